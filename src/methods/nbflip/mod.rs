//! Method nbflip: narrow-band FLIP (Ferstl, Ando, Wojtan, Westermann, Thuerey, "Narrow Band
//! FLIP for Liquid Simulations", CGF 35(2), 2016), as MantaFlow's reference scene
//! `scenes/flip05_nbflip.py` runs it.
//!
//! The liquid is a level set ([`levelset`]); particles live only in a band of `R`
//! cells below its surface, and the grid velocity, advected semi-Lagrangian, carries the
//! interior. Per step, in this code's order (alg. flip with the band's hooks):
//!
//! 1. particles to grid, then the velocity combination: faces with particle weight and
//!    `phi >= -r` (`r = R - 1`, the combine band) take the particles' velocity, all others the
//!    advected grid velocity;
//! 2. forces, projection and the FLIP update as in flip;
//! 3. particles advected; the level set advected with the same velocity, the grid velocity
//!    advected by itself;
//! 4. the level set rebuilt: the advected one shrunk by a cell and united with the particles'
//!    spheres, then re-marched `R + 2` layers in and 3 out;
//! 5. resampling against it: particles outside the liquid or deeper than `R` are deleted, and
//!    crowded cells thinned; band cells below the surface layer short of `mu` particles get
//!    new ones, with the grid's velocity;
//! 6. markings: the level set's inside is fluid, with or without particles.
//!
//! Both read a level set built from the particles where they are, but MantaFlow resamples at
//! the end of its step, after the pressure solve and the FLIP update, and seeds with the
//! projected velocity; here resampling follows the rebuild at once, so the next transfer to the
//! grid and pressure solve see the resampled band, and new particles take the advected grid
//! velocity. The pressure solve and the advection are
//! those of the other methods (first-order free surface, forward Euler), so that the band is
//! the only difference to flip; MantaFlow's scene uses a ghost-fluid surface, RK4 for the
//! particles and MacCormack for the grid velocity.

pub mod levelset;
mod physics;
mod record;
pub mod region;
mod settings;

pub use levelset::level;
pub use physics::{combine, Resampling};
pub use record::NbflipReport;
pub use settings::NbflipSettings;

use super::cost::{Footprint, StepCost, Unit};
use super::options::{Flag, FlagValue};
use super::seam::{
    FluidMethod, MethodInfo, MethodSummary, MethodType, SettingContext, SettingError,
};
use crate::stages::band::check_band_r;
use crate::stages::solids::ObstacleMode;
use physics::NbflipSim;
use record::{Totals, LAYER_VIEWS, PANELS};

/// Narrow-band FLIP, as registered.
pub struct Nbflip;

impl MethodType for Nbflip {
    const INFO: MethodInfo = MethodInfo {
        name: "nbflip",
        about: "narrow-band FLIP: particles only in a band below a level set surface (Ferstl et al. 2016)",
        obstacle_modes: &[ObstacleMode::Naive, ObstacleMode::Ignore],
        panels: PANELS,
        layer_views: LAYER_VIEWS,
        figures: &["nbflip_seeded", "nbflip_deleted", "nbflip_carved"],
    };

    type Settings = NbflipSettings;
    const FLAGS: &'static [Flag<NbflipSettings>] = &[Flag {
        name: "band-r",
        help: "Depth R in cells of the band of particles kept below the level set's zero.",
        value: FlagValue::number::<u32>(),
        set: |s, v| v.try_into().map(|x| s.band_r = x),
    }];

    fn check(s: &NbflipSettings, _ctx: SettingContext) -> Result<(), SettingError> {
        check_band_r(s.band_r).map_err(|why| SettingError::range("band_r", why.to_string()))
    }

    fn build<const D: usize>(s: &NbflipSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(NbflipSim::<D>::new(s.band_r, s.narrow))
    }

    fn summary<const D: usize>(s: &NbflipSettings) -> Box<dyn MethodSummary<D>> {
        Box::new(Totals::new(s.band_r))
    }

    /// Measured peak memory over a run ([`Footprint`]; docs/benchmarks/memory.md): a fit to
    /// whole runs of the particles it may hold (the band seeded or settled), the liquid's cells
    /// and the grid's (5% above each run's peak, the spread of repeated runs), and the peak
    /// while it starts, holding every particle seeded and resampling them all (a chunk at a
    /// time). In 3D the particles the settled band counts beyond the seeded one weigh more:
    /// on the dam the band outgrows the settled count (the column spreads into a sheet, and
    /// the resampling tops up FLIP's volume gain). In 2D the band holds so few particles
    /// beside the cells that the fit gives them no more than their own 32 bytes.
    fn footprint(s: &NbflipSettings, dim: usize) -> Footprint {
        // It deletes the particles below `phi = -R` (`Resampling`): about the top `R` layers of
        // cells keep theirs, one fewer than ccp's band.
        Footprint::band(
            dim,
            s.band_r,
            [
                ([174.0, 184.0, 32.0, 0.0], (38.0, 53.0)),
                ([179.0, 255.0, 217.0, 291.0], (59.0, 57.0)),
            ],
        )
    }

    fn step_cost(_settings: &NbflipSettings, dim: usize) -> StepCost {
        // ns per unit and per cell, [2D, 3D]: the 2026-12-03 fit of tools/cost-fit.py on both
        // pages as made that day; at rest, the still zero-bc tank's step time over that of the
        // falling obstacle it is otherwise (docs/cluster.md, "The cost model", says on which
        // runs and how close).
        StepCost::of(dim, [(590.0, 66.0), (478.0, 125.0)])
            .per_driven(Unit::LiquidCell)
            .at_rest(0.45)
    }
}
