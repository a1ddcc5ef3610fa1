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
        // ns per unit and per cell, [2D, 3D]: the 2026-12-03 fit of tools/cost-fit.py on both
        // pages as made that day; at rest, the still zero-bc tank's step time over that of the
        // falling obstacle it is otherwise (docs/cluster.md, "The cost model", says on which
        // runs and how close).
        StepCost::of(dim, [(192.0, 12.0), (148.0, 22.0)]).at_rest(0.49)
    }
}

impl<const D: usize> FluidMethod<D> for Flip {}

impl<const D: usize> MethodRecording<D> for Flip {}
