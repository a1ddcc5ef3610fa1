//! PIC/FLIP (Zhu and Bridson 2005) on a MAC grid, as the paper's alg. flip runs it without the
//! correction (line 6): the baseline every other method extends. Every hook of
//! [`FluidMethod`] and [`MethodRecording`] keeps its default, so the whole method is its
//! registration.

use super::cost::{Footprint, StepCost};
use super::seam::{
    FluidMethod, MethodInfo, MethodRecording, MethodSummary, MethodType, NoSettings, NoSummary,
};
use crate::stages::solids::ObstacleMode;

/// Plain FLIP.
pub struct Flip;

impl MethodType for Flip {
    const INFO: MethodInfo = MethodInfo {
        name: "flip",
        about: "PIC/FLIP with no position correction (Zhu and Bridson 2005)",
        obstacle_modes: &[ObstacleMode::Naive, ObstacleMode::Ignore],
        panels: &[],
        layer_views: &[],
        figures: &[],
    };

    /// Flip has no settings of its own.
    type Settings = NoSettings;

    fn build<const D: usize>(_settings: &NoSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(Flip)
    }

    fn summary<const D: usize>(_settings: &NoSettings) -> Box<dyn MethodSummary<D>> {
        Box::new(NoSummary)
    }

    /// Measured peak memory over a run ([`Footprint`]; docs/benchmarks/memory.md).
    fn footprint(_settings: &NoSettings, dim: usize) -> Footprint {
        Footprint::of(dim, [(111.0, 115.0), (165.0, 100.0)])
    }

    fn step_cost(_settings: &NoSettings, dim: usize) -> StepCost {
        // ns per unit and per cell, [2D, 3D]: the 2026-11-30 fit of tools/cost-fit.py, 3D
        // refitted with the falling obstacle at 200 x 300 x 200 (docs/cluster.md, "The cost
        // model", says on which runs and how close).
        StepCost::of(dim, [(145.0, 8.0), (111.0, 16.0)])
    }
}

impl<const D: usize> FluidMethod<D> for Flip {}

impl<const D: usize> MethodRecording<D> for Flip {}
