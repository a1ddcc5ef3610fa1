//! Method idp: implicit density projection (Kugelstadt, Longva, Thuerey, Bender, "Implicit
//! Density Projection for Volume Conserving Liquids", IEEE TVCG 27(4), 2021), after its
//! official implementation (thunil/mantaflow, `source/plugin/implicitdensityprojection.cpp`,
//! "the reference" below; `scenes/idp_apic0{1,2}*.py`). FLIP, plus after the particle
//! advection (where the reference scenes and Levi's driver run it, the slot of alg. flip
//! line 6) a second Poisson solve whose right-hand side is the density error, and a
//! position-only correction that moves particles out of over-dense cells. Velocities are not
//! changed (except for resampled particles).
//!
//! Each step ([`project_density`]), in grid units (unit cells, rest density 1 per cell):
//!
//! 1. **Fluid cells**: non-solid cells holding a particle after advection.
//! 2. **Push-out** of particles inside solid cells (only an obstacle under `ignore` can cover
//!    particles; static solids never hold any): the displacement that takes the particle out of
//!    the solid by the nearest exit, [`PUSH_MARGIN`] beyond it, at most one cell per step
//!    ([`push_out`]); written onto the solid cell's two faces on that axis, the largest magnitude
//!    winning (reference: `markFluidAndBoundaryCells`).
//! 3. **Density error** of each fluid cell, `s = 1 - sum_p w_c(x_p) / mu` with the tent weight
//!    `w_c` at the cell centre (particle mass `1/mu`, rest density 1: reference `knMapLinear`,
//!    `knComputeDensity`); minus what the wall and solid neighbours would contribute if they
//!    were sampled like the fluid ([`SolidShare`]); plus the divergence of the push-out field.
//! 4. **Surface rule**: a fluid cell with a face neighbour that is empty (neither fluid nor
//!    solid) and `s > 0` (under-dense) leaves the solve as a Dirichlet cell, `s = 0`.
//! 5. **Clamp** `s` to `[-CLAMP, CLAMP]` ([`CLAMP`] = 0.5: at most half a cell of correction
//!    per step).
//! 6. **Second solve** `A phi = s` with the projection's matrix and solver
//!    ([`crate::stages::pressure::Poisson`]: PCG with the scene's pressure preconditioner and
//!    tolerance).
//! 7. **Displacement**: on faces between two non-solid cells `D_f = phi_R - phi_L`, on faces
//!    touching a solid or the walls the push-out value (or 0); each particle moves by `D`
//!    interpolated at its position, clamped into the domain and never into a solid
//!    ([`crate::stages::advect::displace`]).
//!
//! Over-dense cells (`s < 0`) get a local minimum of `phi`, so `D` points away from them, and
//! `div D = -s`: the linearised correction of the density. The reference divides `s` by `dt`
//! and moves particles by `dt * grad(lambda)`, which cancels; we solve for `phi = dt lambda`
//! directly.
//!
//! Where we depart from the reference's code (each a place where it departs from its own
//! stated intent; the notes of the team list them):
//! - The wall and solid contribution is the exact share of a regularly sampled neighbour for
//!   any `mu`, in 2D and 3D ([`SolidShare`]). The reference adds it in 3D only, assumes 8 ppc,
//!   counts empty neighbours as full too, and its face/edge test reads the cell's z index
//!   where the loop variable was meant, so x and y faces get half their share.
//! - Weights of cells outside the domain are dropped, not clamped onto the wall cells, so the
//!   wall share is counted once.
//! - The push-out goes `PUSH_MARGIN` beyond the surface (the reference stops 0.01 inside it:
//!   `-(dist + 0.01) grad phi`), along the nearest face exit of the rasterised solid (we have
//!   no obstacle level set); it is a displacement, not scaled by `dt` (the reference multiplies
//!   it by `dt` in the move but not in the density, consistent only at `dt = 1`).
//! - A fluid region with no free surface has a singular system: the mean of `s` over it is
//!   removed (its particle count cannot change; the reference's CG runs to its iteration cap).
//!
//! Optional resampling of degenerate cells (`simulation.idp_resample`, default off as in the
//! reference's 3D scene and Levi's driver; its 2D scene turns it on): cells with `s <`
//! [`RESAMPLE_BELOW`] (more than twice the rest density) get their particles spread over a
//! `q^D` sub-grid (`q = ceil(n^(1/D))`, distinct sub-cells in seeded random order), with the
//! grid velocity, and keep `s = RESAMPLE_BELOW` instead of the clamp (reference
//! `resampeOverfullCells`).

mod physics;
mod record;
mod settings;

pub use physics::{
    density_errors, project_density, push_out, Inputs, Resample, SolidShare, CLAMP, PUSH_MARGIN,
    RESAMPLE_BELOW,
};
pub use record::{ErrorClass, IdpReport};
pub use settings::IdpSettings;

use super::cost::{Footprint, StepCost};
use super::seam::{FluidMethod, MethodInfo, MethodSummary, MethodType};
use crate::stages::solids::ObstacleMode;
use physics::IdpSim;
use record::{Totals, LAYER_VIEWS, PANELS};

/// Implicit density projection, as registered.
pub struct Idp;

impl MethodType for Idp {
    const INFO: MethodInfo = MethodInfo {
        name: "idp",
        about: "FLIP plus implicit density projection: a second Poisson solve moves particles out of over-dense cells (Kugelstadt et al. 2021)",
        obstacle_modes: &[ObstacleMode::Naive, ObstacleMode::Ignore],
        panels: PANELS,
        layer_views: LAYER_VIEWS,
        figures: &["idp_iterations", "idp_max_displacement"],
    };

    type Settings = IdpSettings;

    fn build<const D: usize>(s: &IdpSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(IdpSim::<D>::new(s.resample))
    }

    fn summary<const D: usize>(_s: &IdpSettings) -> Box<dyn MethodSummary<D>> {
        Box::new(Totals::default())
    }

    /// Measured peak memory over a run ([`Footprint`]; docs/benchmarks/memory.md).
    fn footprint(_settings: &IdpSettings, dim: usize) -> Footprint {
        Footprint::of(dim, [(145.0, 115.0), (195.0, 150.0)])
    }

    fn step_cost(_settings: &IdpSettings, dim: usize) -> StepCost {
        // ns per unit and per cell, [2D, 3D]: the 2026-12-03 fit of tools/cost-fit.py on both
        // pages as made that day; at rest, the still zero-bc tank's step time over that of the
        // falling obstacle it is otherwise (docs/cluster.md, "The cost model", says on which
        // runs and how close).
        StepCost::of(dim, [(405.0, 0.0), (272.0, 104.0)]).at_rest(0.71)
    }
}
