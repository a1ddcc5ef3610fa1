//! Method powerpic: the Power Particle-in-Cell method (Qu, Li, de Goes, Jiang, "The Power
//! Particle-in-Cell Method", ACM TOG 41(4), art. 118, 2022), with a free surface.
//!
//! Every particle has a volume-constrained density kernel: its row of the entropic transport
//! plan `T` between the particles and a transportation grid finer than the simulation grid
//! ([`crate::solvers::sinkhorn`], which derives the updates). Per step (alg. flip with these
//! hooks):
//!
//! 1. the air baseline `b_j` of every transport cell from this step's markings ([`air`]), then
//!    the plan for the particles' positions by Sinkhorn iterations, warm-started from the
//!    previous step's plan (each particle's row scaling carried with it, the cells' column
//!    scalings where they were reached; our choice), until both marginals hold to `delta`;
//! 2. particles to grid with the power (GIMP) weights `w_pi = sum_j T_pj N_i(x_j) / V_p`: each
//!    transport cell gathers the mass `sum_p T_pj` and momentum `sum_p T_pj v_p` of its
//!    column, and splats them with the tent functions `N_i` of the faces;
//! 3. forces and the projection as in flip;
//! 4. grid to particles with the same weights (the FLIP/PIC blend of flip, `u` and `u - u_old`
//!    averaged over the kernel), and each particle moved to its kernel's barycentre
//!    `sum_j T_pj x_j / V_p`;
//! 5. advection from there, as in flip.
//!
//! **The free surface** (`air`, [`AirForm`]): a transport cell need not be full,
//! `sum_p T_pj + a_j = V_j` with an air slack `a_j >= 0`.
//!
//! - `baseline` (the default): the objective gets `eta eps sum_j KL(a_j | b_j)`, which pulls
//!   the slack towards the air baseline `b_j = V_j (1 - V_c)`, `V_c` the fluid volume of the
//!   simulation cell around `j` by Levi's own measure (eq. volume: 1 in deep cells,
//!   `min(1, |gamma_c| / mu)` in the surface layer, 0 outside). Deep cells must be full, so
//!   particles that drift apart inside the liquid are pulled back together; at `eta = 1` the
//!   column update is closed-form, `v_j = V_j / (C_j + b_j)`.
//! - `capacity`: the slack is free, each cell holds at most its volume (the form this
//!   project used first; kept so that the report can show both).
//!
//! Solids: transport cells in solid cells have no capacity, so no kernel reaches into a solid
//! (no clipping, no ghost particles).
//!
//! **Sources.** Parameters ([`PowerPicSettings`]; defaults from Levi, sec. Evaluation):
//! transport grid 2x finer per axis, `eps = 0.1`, `eta = 1`, `tau = 1 / (2 mu^(1/d))`,
//! `delta = 0.1`. What follows a public source: the entropic transport to a finer grid, the
//! GIMP-style power weights, the barycentre move and Sinkhorn's row and column scalings (Qu et
//! al.'s abstract and published summaries, and the open Taichi code g1n0st/power-pic, which is
//! 2D with a closed domain and no free surface), `eps`, `delta` and the transport grid's
//! refinement (Levi and the Taichi code), and that the free surface uses "an estimate of the
//! surface ... as an air occupancy baseline for slack air variables" (Levi, sec. related
//! work). Qu et al.'s text is not available to this project, so the rest is **our
//! reconstruction**:
//!
//! - the air term `eta eps KL(a | b)` and its column update (any penalty of the slack towards
//!   `b` fits Levi's sentence; this one keeps every update closed-form at Levi's `eta = 1`);
//! - the baseline from the markings (Levi's volume measure) rather than from boxes of side
//!   `2 tau` around the particles: the boxes follow the particles, so where they drift apart
//!   the boxes leave gaps, the gaps count as air, and nothing pulls the particles back (on
//!   dam-2d, 8 s: 98.7 .. 122.3 % of V* with boxes, 97.9 .. 102.3 % with the markings);
//! - `tau` as half a particle's rest spacing, setting its volume `V_p = (2 tau)^d` (`1 / mu` at
//!   Levi's value, the volume per particle of the markings' measure);
//! - `eta` as the weight of the air term (the capacity form does not use it).
//!
//! Where the text leaves a choice: `eps` is in simulation cells squared (the Taichi code's
//! `2 dx_T^2` is 0.125 of them, close to Levi's 0.1); the kernel is cut at `1e-12` of its peak
//! (Levi cut nothing; the Taichi code cuts at 6 transport cells); the barycentre move is
//! clamped like any particle move (into the domain, never into a solid); the liquid cells of
//! the pressure solve are those holding particles, as in every method here, and advection is
//! flip's forward Euler from the barycentre (the Taichi code moves to
//! `barycentre + dt sum_j T_pj u(x_j) / V_p`).

pub mod air;
mod physics;
mod record;
mod settings;

pub use record::PowerPicReport;
pub use settings::{AirForm, PowerPicSettings};

use super::cost::{Footprint, StepCost, Unit};
use super::options::{Flag, FlagValue};
use super::seam::{
    FluidMethod, MethodInfo, MethodSummary, MethodType, SettingContext, SettingError,
};
use crate::stages::solids::ObstacleMode;
use physics::PowerPicSim;
use record::{Totals, LAYER_VIEWS, PANELS};

/// Power PIC, as registered.
pub struct Powerpic;

impl MethodType for Powerpic {
    const INFO: MethodInfo = MethodInfo {
        name: "powerpic",
        about: "Power PIC (Qu et al. 2022): transfers through volume-constrained kernels, an \
                entropic transport to a finer grid solved by Sinkhorn, with air slack pulled \
                towards an air baseline at the free surface",
        obstacle_modes: &[ObstacleMode::Naive, ObstacleMode::Ignore],
        panels: PANELS,
        layer_views: LAYER_VIEWS,
        figures: &[
            "powerpic_iterations",
            "powerpic_marginal_error",
            "powerpic_air_volume",
        ],
    };

    type Settings = PowerPicSettings;
    const FLAGS: &'static [Flag<PowerPicSettings>] = &[Flag {
        name: "air",
        help: "How the free surface's air is costed (overrides `simulation.powerpic.air`): \
               baseline (pulled towards the air baseline estimated from the markings) or \
               capacity (free).",
        value: FlagValue::choice::<AirForm>(),
        set: |s, v| v.try_into().map(|x| s.air = x),
    }];

    fn check(s: &PowerPicSettings, ctx: SettingContext) -> Result<(), SettingError> {
        s.check(ctx)
    }

    fn build<const D: usize>(s: &PowerPicSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(PowerPicSim::<D>::new(*s))
    }

    fn summary<const D: usize>(s: &PowerPicSettings) -> Box<dyn MethodSummary<D>> {
        Box::new(Totals::new(s.max_iterations))
    }

    /// Measured peak memory over a run ([`Footprint`]; docs/benchmarks/memory.md): in 2D the
    /// pair fitted when the kernel rows were kept factored, less the 4 bytes a kernel factor
    /// saves in single precision; in 3D bytes per cell and per particle that put no run of
    /// bbfac50 above its estimate, near the least at drop-3d 300^3 of those that do, with 2%
    /// to spare on the two tightest (dam-3d 48^3, falling-obstacle-3d 40^3): whole runs of
    /// dam-3d (48^3, 64^3), deep-pool-3d (40^3, 48^3), drop-3d 64^3, falling-obstacle-3d
    /// 40^3 and large-obstacle-3d, and the first steps of drop-3d at 100^3 and 128^3
    /// (2026-12-01, issue 73; (400, 860) before the transfers held less).
    fn footprint(_settings: &PowerPicSettings, dim: usize) -> Footprint {
        Footprint::of(dim, [(160.0, 778.0), (350.0, 710.0)])
    }

    fn step_cost(_settings: &PowerPicSettings, dim: usize) -> StepCost {
        // ns per unit and per cell, [2D, 3D]: the 2026-12-03 fit of tools/cost-fit.py on both
        // pages as made that day; at rest, the still zero-bc tank's step time over that of the
        // falling obstacle it is otherwise (docs/cluster.md, "The cost model", says on which
        // runs and how close).
        StepCost::of(dim, [(562.0, 190.0), (651.0, 1065.0)])
            .per_driven(Unit::Particle)
            .at_rest(0.55)
    }
}
