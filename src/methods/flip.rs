//! PIC/FLIP (Zhu and Bridson 2005) on a MAC grid, as the paper's alg. flip runs it without the
//! correction (line 6): the baseline every other method extends. Every hook of
//! [`FluidMethod`] keeps its default.

use super::{FluidMethod, MethodInfo, MethodSettings, MethodType};
use crate::sim::solids::ObstacleMode;

/// Plain FLIP.
pub struct Flip;

impl MethodType for Flip {
    const INFO: MethodInfo = MethodInfo {
        name: "flip",
        about: "PIC/FLIP with no position correction (Zhu and Bridson 2005)",
        options: &[],
        obstacle_modes: &[ObstacleMode::Naive, ObstacleMode::Ignore],
        panels: &[],
        layer_views: &[],
        figures: &[],
    };

    fn build<const D: usize>(_settings: &MethodSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(Flip)
    }
}

impl<const D: usize> FluidMethod<D> for Flip {}
