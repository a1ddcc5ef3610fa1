//! Method powerpic: the Power Particle-in-Cell method (Qu, Li, de Goes, Jiang, "The Power
//! Particle-in-Cell Method", ACM TOG 41(4), art. 118, 2022), with a free surface.
//!
//! Every particle has a volume-constrained density kernel: its row of the entropic transport
//! plan `T` between the particles and a transportation grid finer than the simulation grid
//! ([`crate::solvers::sinkhorn`]). Per step (alg. flip with these hooks):
//!
//! 1. the plan for the particles' positions, by Sinkhorn iterations in the log domain from
//!    zero scalings, until both marginals hold to `delta`;
//! 2. particles to grid with the power (GIMP) weights `w_pi = sum_j T_pj N_i(x_j) / V_p`: each
//!    transport cell gathers the mass `sum_p T_pj` and momentum `sum_p T_pj v_p` of its
//!    column, and splats them with the tent functions `N_i` of the faces;
//! 3. forces and the projection as in flip;
//! 4. grid to particles with the same weights (the FLIP/PIC blend of flip, `u` and `u - u_old`
//!    averaged over the kernel), and each particle moved to its kernel's barycentre
//!    `sum_j T_pj x_j / V_p`;
//! 5. advection from there, as in flip.
//!
//! The free surface: a transport cell need not be full, `sum_p T_pj + a_j = V_j` with an
//! air slack `a_j >= 0`, so kernels fill the liquid's cells and keep their Gaussian shape
//! where there is air. Solids: transport cells in solid cells have no capacity, so no kernel
//! reaches into a solid (no clipping, no ghost particles).
//!
//! Parameters ([`PowerPicSettings`]; defaults from Levi, sec. Evaluation): transport grid 2x
//! finer per axis, `eps = 0.1`, `eta = 1`, `tau = 1 / (2 mu^(1/d))`, `delta = 0.1`. Qu et al.'s
//! text is not available to this project (its public summary and the open Taichi code,
//! g1n0st/power-pic, which has no free surface, are), and Levi gives only the values, so the
//! meaning of `eta` and `tau` is our reading, chosen to match their formulas:
//!
//! - `tau` is a length in cells: half a particle's spacing at rest, the half-width `l_p` of
//!   its GIMP domain (Bardenhagen and Kober 2004), so `(2 tau)^d` is its rest volume;
//! - `eta` scales that volume: every particle carries `V_p = eta (2 tau)^d` cells. With a free
//!   surface the fluid's volume is not the domain's, so it must be given; `eta = 1` is the
//!   volume the particles were seeded with ("precise volume control" of Qu et al.'s abstract).
//!
//! Where the text leaves a choice: `eps` is in simulation cells squared (the Taichi code's
//! `2 dx_T^2` is 0.125 of them, close to Levi's 0.1); the kernel is cut at `1e-12` of its peak
//! (Levi cut nothing; the Taichi code cuts at 6 transport cells); each step starts from zero
//! scalings (as the Taichi code does), so iteration counts measure the step's own problem; the
//! barycentre move is clamped like any particle move (into the domain, never into a solid);
//! the liquid cells of the pressure solve are those holding particles, as in every method
//! here, and advection is flip's forward Euler from the barycentre (the Taichi code moves to
//! `barycentre + dt sum_j T_pj u(x_j) / V_p`).

mod physics;
mod record;
mod settings;

pub use physics::{FractionImage, PowerPicReport};
pub use settings::PowerPicSettings;

use super::seam::{
    FluidMethod, MethodInfo, MethodOption, MethodSummary, MethodType, SettingContext, SettingError,
};
use crate::sim::solids::ObstacleMode;
use physics::PowerPicSim;
use record::{Totals, LAYER_VIEWS, PANELS};

/// Power PIC, as registered.
pub struct Powerpic;

impl MethodType for Powerpic {
    const INFO: MethodInfo = MethodInfo {
        name: "powerpic",
        about: "Power PIC (Qu et al. 2022): transfers through volume-constrained kernels, an \
                entropic transport to a finer grid solved by Sinkhorn, with air slack at the \
                free surface",
        options: &[MethodOption::PowerPic],
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

    fn check(s: &PowerPicSettings, ctx: SettingContext) -> Result<(), SettingError> {
        s.check(ctx)
    }

    fn build<const D: usize>(s: &PowerPicSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(PowerPicSim::<D>::new(*s))
    }

    fn summary<const D: usize>(s: &PowerPicSettings) -> Box<dyn MethodSummary<D>> {
        Box::new(Totals::new(s.max_iterations))
    }
}
