//! Method ccp's step: the hooks it implements (see the module doc of `super`).

use super::correct::band::{BandContext, BandVariant};
use super::correct::{self, CorrectionSettings};
use super::deep::{exchange_with_deep, DeepExchange};
use super::record::CcpReport;
use super::settings::CcpSettings;
use crate::draw::{depth_level_classes, Log};
use crate::grid::{MacField, NearCells, Vector};
use crate::methods::seam::{FluidMethod, MethodRecording, MethodReport};
use crate::snapshot::{check_elements, not_finite, Reader, SnapshotError, Writer};
use crate::stages::band::Band;
use crate::stages::invariants::InvariantViolation;
use crate::stages::markings::{DepthLevel, Markings};
use crate::stages::transfer::{self, Known};
use crate::stages::{ParticlesMut, State, StepError};
use std::path::{Path, PathBuf};

/// The paper's method in a running simulation.
pub struct CcpSim<const D: usize> {
    correction: CorrectionSettings,
    /// The band and the variant that keeps its count, with the band method.
    band: Option<(Band, BandVariant)>,
    /// `n_deep`: the deep's imaginary particles.
    n_deep: usize,
    /// `x_bar`: the positions before advection.
    x_bar: Vec<Vector<D>>,
    /// Export this step's correction problem as MPS, to this path.
    export_lp: Option<(u64, PathBuf)>,
    /// This step's report, filled by the hooks.
    step: CcpReport<D>,
    /// The last correction's prices, the next one's warm start.
    prices: correct::PriceMemory,
}

impl<const D: usize> CcpSim<D> {
    pub fn new(s: &CcpSettings) -> Self {
        CcpSim {
            correction: CorrectionSettings {
                solver: s.solver,
                directions: s.directions,
                cross_check: s.cross_check,
            },
            band: s.band.variant().map(|v| (Band { r: s.band_r }, v)),
            n_deep: 0,
            x_bar: vec![],
            export_lp: s.export_lp.zip(s.export_path.clone()),
            step: CcpReport::default(),
            prices: Default::default(),
        }
    }

    fn band(&self) -> Option<Band> {
        self.band.map(|(b, _)| b)
    }

    /// Alg. band line 9: the exchange with the deep after new markings.
    fn exchange(&mut self, s: &mut State<D>, previous: Option<&Markings>) -> Option<DeepExchange> {
        let band = self.band()?;
        Some(exchange_with_deep(
            &s.grid,
            &s.active,
            &mut s.particles,
            &mut s.markings,
            previous,
            band,
            s.config.mu(),
            &mut self.n_deep,
            &s.velocity,
            &mut s.rng,
        ))
    }
}

impl<const D: usize> FluidMethod<D> for CcpSim<D> {
    fn start(&mut self, s: &mut State<D>) {
        self.exchange(s, None);
    }

    fn emitter_count(&self, s: &State<D>, c: usize) -> u32 {
        match self.band() {
            Some(b) => b.emitter_count(&s.markings, s.config.mu(), c),
            None => s.markings.count[c],
        }
    }

    fn particles_not_held(&self) -> isize {
        self.n_deep as isize
    }

    /// The deep's count and the last correction's prices (the next one's warm start, which
    /// may pick another of several optimal assignments).
    fn save_state<'a>(&'a self, w: &mut Writer<'a>) {
        w.scalar("ccp.n_deep", self.n_deep as u64);
        w.slice("ccp.cell_prices", self.prices.cell_prices());
    }

    fn restore_state(&mut self, s: &State<D>, r: &Reader) -> Result<(), SnapshotError> {
        let n_deep = r.scalar::<u64>("ccp.n_deep")?;
        if n_deep > s.total_particles as u64 {
            return Err(SnapshotError::Array {
                name: "ccp.n_deep".into(),
                reason: format!(
                    "{n_deep} particles in the deep, more than the {} seeded or emitted",
                    s.total_particles
                ),
            });
        }
        self.n_deep = n_deep as usize;
        let prices = r.slice("ccp.cell_prices", None)?;
        check_elements("ccp.cell_prices", &prices, not_finite)?;
        self.prices = correct::PriceMemory::from_cell_prices(prices);
        Ok(())
    }

    fn particles_to_grid(&mut self, s: &State<D>) -> Result<(MacField<D>, Known<D>), StepError> {
        let (mut u, mut known) =
            transfer::particles_to_grid(&s.grid, &s.particles.pos, &s.particles.vel);
        if let Some(b) = self.band() {
            let (m, active) = (&s.markings, &s.active);
            b.combine_with_grid(&s.grid, &mut u, &mut known, &s.velocity, m, active);
        }
        Ok((u, known))
    }

    fn before_advection(&mut self, s: &State<D>) {
        self.x_bar.clone_from(&s.particles.pos);
    }

    fn next_grid_velocity(&mut self, s: &State<D>, u: MacField<D>, dt: f64) -> MacField<D> {
        match self.band() {
            Some(_) => Band::advect_grid_velocity(&s.grid, &u, dt, &s.markings, &s.active),
            None => u,
        }
    }

    fn correct_positions(
        &mut self,
        s: ParticlesMut<'_, D>,
        penalty: Option<&[f64]>,
    ) -> Result<(), StepError> {
        let export = self.export_lp.as_ref().filter(|(n, _)| *n == s.steps + 1);
        let mu = s.config.mu();
        let ctx = self.band.map(|(b, variant)| BandContext {
            r: b.r,
            n_deep: self.n_deep,
            variant,
        });
        let solid = &s.solids.solid;
        let pos = &mut s.particles.pos;
        let rep = correct::correct(
            s.grid,
            &self.x_bar,
            pos,
            s.markings,
            solid,
            mu,
            &self.correction,
            ctx,
            penalty,
            export.is_some(),
            &mut self.prices,
        )
        .map_err(|e| InvariantViolation(format!("correction problem: {e}")))?;
        correct::guarantees::check_cell_counts(
            s.grid,
            pos,
            s.markings,
            solid,
            mu,
            ctx.map(|b| b.r),
            s.active,
        )?;
        // The problems go out with the report; the run's observer writes them.
        if let (Some(_), Some((step, path))) = (&rep.mps, export) {
            self.step.export = Some((*step, path.clone()));
        }
        if let (Some(_), Some((_, path))) = (&rep.second_mps, export) {
            self.step.export_second = Some(second_step_path(path));
        }
        self.step.correction = rep;
        Ok(())
    }

    fn before_markings(&mut self, s: ParticlesMut<'_, D>) -> Option<NearCells> {
        self.band()
            .map(|_| Band::kept_cells(s.grid, s.markings, s.active))
    }

    fn after_markings(&mut self, s: &mut State<D>, previous: &Markings) {
        if let Some(x) = self.exchange(s, Some(previous)) {
            self.step.deep = Some(x.merged(self.step.deep));
        }
    }

    /// With the band: every cell holds at most `mu` after the exchange, and no real particle
    /// is left in the deep. (The correction's own guarantees are checked right after it.)
    fn check_invariants(&self, s: &State<D>) -> Result<(), InvariantViolation> {
        let Some(band) = self.band() else {
            return Ok(());
        };
        let mu = s.config.mu();
        if let Some(c) = s.active.each_cell().find(|&c| s.markings.count[c] > mu) {
            return Err(InvariantViolation(format!(
                "cell {:?} holds {} particles after the exchange with the deep (mu = {mu})",
                s.grid.cell_coords(c),
                s.markings.count[c]
            )));
        }
        match band.particle_in_deep(&s.grid, &s.markings, &s.particles.pos) {
            Some(x) => Err(InvariantViolation(format!(
                "a particle at {:?} is in the deep after the exchange",
                x.as_slice()
            ))),
            None => Ok(()),
        }
    }

    fn finish_step(&mut self, _s: &State<D>) -> Box<dyn MethodReport<D>> {
        let mut rep = std::mem::take(&mut self.step);
        rep.band = self.band();
        rep.n_deep = self.n_deep;
        Box::new(rep)
    }
}

impl<const D: usize> MethodRecording<D> for CcpSim<D> {
    fn record_setup(&self, log: &mut dyn Log<D>) {
        if self.band.is_some() {
            log.classes("world/grid/depth", &depth_level_classes());
        }
    }

    fn is_deep(&self, s: &State<D>, c: usize) -> bool {
        self.band
            .is_some_and(|(b, _)| b.level(&s.markings, c) == DepthLevel::Deep)
    }
}

/// Where `exact-paths` writes its second-step problem: next to the exported problem,
/// `...-step3.mps` -> `...-step3-second.mps`.
fn second_step_path(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(Default::default, |s| s.to_string_lossy());
    path.with_file_name(format!("{stem}-second.mps"))
}
