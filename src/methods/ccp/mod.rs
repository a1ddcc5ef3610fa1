//! Method ccp: cell-constrained particles (Z. Levi), FLIP plus the paper's correction step
//! (sec. 4-5, alg. flip line 6), with the band method of sec. band_method (alg. band) and the
//! coupling with moving obstacles of sec. 7.
//!
//! Its parts, each in a file of this folder: the correction ([`correct`]: eq. problem3 built as
//! data in [`correct::problem`], the band variants in [`correct::band`], the guarantees checked
//! after each correction in [`correct::guarantees`]), the deep's bookkeeping ([`deep`]), its
//! settings (`settings.rs`) and what it records and sums up (`record.rs`). The band's geometry
//! (levels, velocity combination, advection of the grid velocity), which narrow-band FLIP
//! shares, is [`crate::stages::band`].

pub mod correct;
pub mod deep;
mod physics;
mod record;
mod settings;

pub use record::CcpReport;
pub use settings::{BandMode, CcpSettings, Directions, Solver};

use super::cost::{Footprint, StepCost, Unit};
use super::options::Flag;
use super::seam::{
    BandChoice, FluidMethod, MethodInfo, MethodSummary, MethodType, SettingContext, SettingError,
    StepFile,
};
use crate::draw::{LayerView, Needs};
use crate::solvers::min_cost_flow::HALVING;
use crate::stages::solids::ObstacleMode;
use physics::CcpSim;
use record::{Totals, PANELS};

/// The paper's method, as registered.
pub struct Ccp;

impl MethodType for Ccp {
    const INFO: MethodInfo = MethodInfo {
        name: "ccp",
        about: "cell-constrained particles: FLIP plus the paper's correction (sec. 4-7)",
        obstacle_modes: &[ObstacleMode::Couple],
        panels: PANELS,
        layer_views: &[LayerView {
            title: "band levels",
            origin: "world",
            layers: &["world/grid/depth"],
            marks: &["world/corrector/paths"],
            needs: Needs::Band,
        }],
        figures: &[
            "ccp_augmentations",
            "ccp_moved",
            "ccp_solver_ms",
            "ccp_band_ms",
        ],
    };

    type Settings = CcpSettings;
    const FLAGS: &'static [Flag<CcpSettings>] = settings::FLAGS;

    fn check(s: &CcpSettings, _ctx: SettingContext) -> Result<(), SettingError> {
        s.check()
    }

    fn band(s: &CcpSettings) -> Option<BandChoice> {
        let variant = s.band.variant()?;
        Some(BandChoice {
            variant: variant.name(),
            r: s.band_r,
        })
    }

    fn cross_checks(s: &CcpSettings) -> bool {
        s.cross_check
    }

    fn files(s: &mut CcpSettings, stem: &std::path::Path) -> Vec<StepFile> {
        s.files(stem)
    }

    fn build<const D: usize>(s: &CcpSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(CcpSim::<D>::new(s))
    }

    fn summary<const D: usize>(s: &CcpSettings) -> Box<dyn MethodSummary<D>> {
        Box::new(Totals::new(s))
    }

    /// Measured peak memory over a run ([`Footprint`]; docs/benchmarks/memory.md). With the
    /// band: a fit to whole runs of the particles it may hold (the band seeded or settled), the
    /// liquid's cells and the grid's (5% above each run's peak, the spread of repeated runs),
    /// and the peak while it starts holding every particle seeded (in 2D the band holds so few
    /// particles beside the cells that the fit gives them no more than their own 32 bytes). In
    /// 3D the grid's fields follow the active cells once they outgrow the allocator's heap
    /// (`per_active_cell`, `per_heap_cell`): fitted on whole runs from 64^3 to 300^3 (refitted
    /// 2026-11-28 on the peak of a whole second at 300^3, 3,531 MiB).
    /// Without: a fit to whole runs of the grid's cells and the particles (5% above each peak),
    /// with the particles of a problem the flow solver halves counted again for its copies.
    fn footprint(s: &CcpSettings, dim: usize) -> Footprint {
        match s.band {
            // Every particle is an item of the flow, and from `HALVING.min_items` up the solver
            // copies them into its two halves.
            BandMode::None => Footprint::of(dim, [(93.0, 296.0), (186.0, 306.0)]).with_large(
                dim,
                HALVING.min_items,
                [150.0, 149.0],
            ),
            // The surface, the band and its interface (`beta` from 0 to `-R`): the interface's
            // particles are the band's boundary (sec. 5).
            _ => Footprint::band(
                dim,
                s.band_r + 1,
                [
                    ([139.0, 221.0, 32.0, 0.0], (35.0, 26.0)),
                    ([54.0, 0.0, 537.0, 0.0], (55.0, 33.0)),
                ],
            )
            .with_active(dim, [(0.0, 0.0), (139.0, 53.0)]),
        }
    }

    fn step_cost(_settings: &CcpSettings, dim: usize) -> StepCost {
        // ns per band particle and per cell, [2D, 3D]: the 2026-12-03 fit of tools/cost-fit.py
        // on both pages as made that day; at rest half, from hydrostatic-2d, where its
        // correction has nothing to move. It clears a solid that enters the liquid of
        // particles, so the still zero-bc tank is not at rest to it (docs/cluster.md, "The
        // cost model", says on which runs and how close).
        StepCost::of(dim, [(610.0, 69.0), (492.0, 272.0)])
            .per_driven(Unit::Particle)
            .at_rest(0.5)
            .clearing_solids()
    }
}
