//! Method ccp: cell-constrained particles (Z. Levi), FLIP plus the paper's correction step
//! (sec. 4-5, alg. flip line 6), with the band method of sec. band_method (alg. band) and the
//! coupling with moving obstacles of sec. 7.
//!
//! The correction internals live in [`crate::sim::correct`]: eq. problem3 built as data
//! ([`crate::sim::correct::problem`]), the band variants ([`crate::sim::correct::band`]) and
//! the deep's bookkeeping ([`crate::sim::correct::deep`]). The band's geometry (levels,
//! velocity combination, advection of the grid velocity) is [`crate::sim::band`].

use super::{
    FluidMethod, Known, MethodInfo, MethodOption, MethodReport, MethodSettings, MethodType,
};
use crate::grid::{MacField, Vector};
use crate::metrics::{self, median, InvariantViolation};
use crate::record::layout::{LayerView, Needs, Panel};
use crate::record::{depth_level_classes, Layer, Log, Style};
use crate::sim::band::Band;
use crate::sim::correct::band::{BandContext, BandCorrection, BandVariant};
use crate::sim::correct::deep::{exchange_with_deep, DeepExchange};
use crate::sim::correct::{self, CorrectionReport, CorrectionSettings};
use crate::sim::markings::{DepthLevel, Markings};
use crate::sim::solids::ObstacleMode;
use crate::sim::{transfer, State};
use anyhow::Context;
use std::any::Any;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The paper's method, as registered.
pub struct Ccp;

/// The paper's method in a running simulation.
pub struct CcpSim<const D: usize> {
    correction: CorrectionSettings,
    /// The band and the variant that keeps its count, with the band method.
    band: Option<(Band, BandVariant)>,
    /// `n_deep`: the deep's imaginary particles.
    n_deep: usize,
    /// `x_bar`: the positions before advection.
    x_bar: Vec<Vector<D>>,
    /// Write this step's correction problem as MPS to this path.
    export_lp: Option<(u64, PathBuf)>,
    /// This step's report, filled by the hooks.
    step: CcpReport<D>,
    totals: Totals,
    /// The last correction's prices, the next one's warm start.
    prices: correct::PriceMemory,
}

/// The correction's and the band's panels: counts, objectives, penalties and times apart.
const PANELS: &[Panel] = &[
    Panel {
        title: "correction: particles moved",
        series: &["metrics/correction/moved"],
        needs: Needs::Always,
    },
    Panel {
        title: "correction: over-full cells before",
        series: &["metrics/correction/overfull_before"],
        needs: Needs::Always,
    },
    Panel {
        title: "correction: objective (cells²)",
        series: &["metrics/correction/objective"],
        needs: Needs::Always,
    },
    Panel {
        title: "correction: solid penalty",
        series: &["metrics/correction/penalty"],
        needs: Needs::Obstacles,
    },
    Panel {
        title: "correction: augmenting paths",
        series: &["metrics/correction/augmentations"],
        needs: Needs::Always,
    },
    Panel {
        title: "correction: solver time (ms)",
        series: &["metrics/correction/solver_ms"],
        needs: Needs::Always,
    },
    Panel {
        title: "correction: cross-check difference",
        series: &["metrics/correction/cross_check"],
        needs: Needs::CrossCheck,
    },
    Panel {
        title: "band: particles held",
        series: &["metrics/band/band_particles"],
        needs: Needs::Band,
    },
    Panel {
        title: "band: deep's imaginary particles",
        series: &["metrics/band/n_deep"],
        needs: Needs::Band,
    },
    Panel {
        title: "band: exchange with the deep",
        series: &["metrics/band/removed", "metrics/band/added"],
        needs: Needs::Band,
    },
    Panel {
        title: "band: moves across the interface",
        series: &[
            "metrics/band/n_in",
            "metrics/band/n_out",
            "metrics/band/n_move",
            "metrics/band/paths",
        ],
        needs: Needs::Band,
    },
    Panel {
        title: "band: spaces s_in, s_out",
        series: &["metrics/band/s_in", "metrics/band/s_out"],
        needs: Needs::Band,
    },
    Panel {
        title: "band: objective",
        series: &["metrics/band/objective/**"],
        needs: Needs::Band,
    },
    Panel {
        title: "band: alg. find calls",
        series: &["metrics/band/find_calls"],
        needs: Needs::Band,
    },
    Panel {
        title: "band: path step time (ms)",
        series: &["metrics/band/path_ms"],
        needs: Needs::Band,
    },
];

impl MethodType for Ccp {
    const INFO: MethodInfo = MethodInfo {
        name: "ccp",
        about: "cell-constrained particles: FLIP plus the paper's correction (sec. 4-7)",
        options: &[
            MethodOption::Band,
            MethodOption::BandR,
            MethodOption::Solver,
            MethodOption::Directions,
            MethodOption::CrossCheck,
            MethodOption::ExportLp,
        ],
        obstacle_modes: &[ObstacleMode::Couple],
        panels: PANELS,
        layer_views: &[LayerView {
            title: "band levels",
            origin: "world",
            layers: &["world/grid/depth"],
            marks: &["world/corrector/paths"],
            needs: Needs::Band,
        }],
        figures: &["ccp_augmentations", "ccp_moved", "ccp_solver_ms"],
    };

    fn build<const D: usize>(s: &MethodSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(CcpSim::<D> {
            correction: CorrectionSettings {
                solver: s.solver,
                directions: s.directions,
                cross_check: s.cross_check,
            },
            band: s.band.variant().map(|v| (Band { r: s.band_r }, v)),
            n_deep: 0,
            x_bar: vec![],
            export_lp: s.export_lp.clone(),
            step: CcpReport::default(),
            totals: Totals::default(),
            prices: Default::default(),
        })
    }
}

impl<const D: usize> CcpSim<D> {
    fn band(&self) -> Option<Band> {
        self.band.map(|(b, _)| b)
    }

    /// Alg. band line 9: the exchange with the deep after new markings.
    fn exchange(&mut self, s: &mut State<D>, was_low: Option<&[bool]>) -> Option<DeepExchange> {
        let band = self.band()?;
        Some(exchange_with_deep(
            &s.grid,
            &mut s.particles,
            &mut s.markings,
            was_low,
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

    fn emitter_counts(&self, s: &State<D>) -> Option<Vec<u32>> {
        Some(self.band()?.emitter_counts(&s.markings, s.config.mu()))
    }

    fn particles_not_held(&self) -> isize {
        self.n_deep as isize
    }

    fn particles_to_grid(&mut self, s: &State<D>) -> anyhow::Result<(MacField<D>, Known<D>)> {
        let (mut u, mut known) =
            transfer::particles_to_grid(&s.grid, &s.particles.pos, &s.particles.vel);
        if let Some(b) = self.band() {
            b.combine_with_grid(&s.grid, &mut u, &mut known, &s.velocity, &s.markings);
        }
        Ok((u, known))
    }

    fn before_advection(&mut self, s: &State<D>) {
        self.x_bar.clone_from(&s.particles.pos);
    }

    fn next_grid_velocity(&mut self, s: &State<D>, u: MacField<D>, dt: f64) -> MacField<D> {
        match self.band() {
            Some(_) => Band::advect_grid_velocity(&s.grid, &u, dt, &s.markings),
            None => u,
        }
    }

    fn correct_positions(
        &mut self,
        s: &mut State<D>,
        penalty: Option<&[f64]>,
    ) -> anyhow::Result<()> {
        let export = self.export_lp.as_ref().filter(|(n, _)| *n == s.steps + 1);
        let mu = s.config.mu();
        let ctx = self.band.map(|(b, variant)| BandContext {
            r: b.r,
            n_deep: self.n_deep,
            variant,
        });
        let solid = &s.solids.solid;
        let pos = &mut s.particles.pos;
        let mut rep = correct::correct(
            &s.grid,
            &self.x_bar,
            pos,
            &s.markings,
            solid,
            mu,
            &self.correction,
            ctx,
            penalty,
            export.is_some(),
            &mut self.prices,
        )
        .map_err(|e| InvariantViolation(format!("correction problem: {e}")))?;
        metrics::check_cell_counts(&s.grid, pos, &s.markings, solid, mu, ctx.map(|b| b.r))?;
        if let (Some(mps), Some((step, path))) = (rep.mps.take(), export) {
            std::fs::write(path, mps)
                .with_context(|| format!("cannot write '{}'", path.display()))?;
            self.totals.exported = Some((*step, path.clone()));
        }
        if let (Some(mps), Some((_, path))) = (rep.second_mps.take(), export) {
            let second = second_step_path(path);
            std::fs::write(&second, mps)
                .with_context(|| format!("cannot write '{}'", second.display()))?;
            self.totals.exported_second = Some(second);
        }
        self.step.correction = rep;
        Ok(())
    }

    fn before_markings(&mut self, s: &mut State<D>) -> Option<Vec<bool>> {
        self.band().map(|_| Band::kept_cells(&s.markings))
    }

    fn after_markings(&mut self, s: &mut State<D>, previous: &Markings) {
        let Some(band) = self.band() else { return };
        let was_low = band.at_or_below_interface(previous);
        let x = self.exchange(s, Some(&was_low)).expect("a band");
        self.step.deep = Some(x.merged(self.step.deep));
    }

    /// With the band: every cell holds at most `mu` after the exchange, and no real particle
    /// is left in the deep. (The correction's own guarantees are checked right after it.)
    fn check_invariants(&self, s: &State<D>) -> Result<(), InvariantViolation> {
        let Some(band) = self.band() else {
            return Ok(());
        };
        let mu = s.config.mu();
        if let Some(c) = (0..s.grid.num_cells()).find(|&c| s.markings.count[c] > mu) {
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

    fn finish_step(&mut self, s: &State<D>) -> Box<dyn MethodReport<D>> {
        let mut rep = std::mem::take(&mut self.step);
        rep.band = self.band();
        rep.n_deep = self.n_deep;
        self.totals.add(&rep, s.particles.len());
        Box::new(rep)
    }

    fn record_setup(&self, log: &mut dyn Log<D>) {
        if self.band.is_some() {
            log.classes("world/grid/depth", &depth_level_classes());
        }
    }

    fn is_deep(&self, s: &State<D>, c: usize) -> bool {
        self.band
            .is_some_and(|(b, _)| b.level(&s.markings, c) == DepthLevel::Deep)
    }

    fn reset_summary(&mut self) {
        self.totals = Totals::default();
    }

    fn summary(&self) -> Vec<String> {
        let variant = self.band.map(|(b, v)| (v.name(), b.r));
        self.totals.lines(&self.correction, variant, self.n_deep)
    }
}

/// What ccp did in one step.
#[derive(Clone, Debug, Default)]
pub struct CcpReport<const D: usize> {
    /// The correction (with its band part, with the band method).
    pub correction: CorrectionReport<D>,
    /// The exchanges with the deep (after emission and after the markings), with the band.
    pub deep: Option<DeepExchange>,
    /// The band, and `n_deep` after the step.
    pub band: Option<Band>,
    pub n_deep: usize,
}

impl<const D: usize> MethodReport<D> for CcpReport<D> {
    fn record(&self, s: &State<D>, log: &mut dyn Log<D>, full: bool) {
        let c = &self.correction;
        log.scalar("metrics/correction/objective", c.objective);
        if !s.solids.obstacles.is_empty() {
            log.scalar("metrics/correction/penalty", c.penalty);
        }
        log.scalar("metrics/correction/moved", c.moves.len() as f64);
        log.scalar(
            "metrics/correction/overfull_before",
            c.overfull_before as f64,
        );
        log.scalar(
            "metrics/correction/solver_ms",
            c.solver_time.as_secs_f64() * 1e3,
        );
        log.scalar("metrics/correction/augmentations", c.augmentations as f64);
        match &c.cross_check {
            Some(Ok(d)) => log.scalar("metrics/correction/cross_check", *d),
            Some(Err(e)) => log.warn(&format!("cross-check solver failed: {e}")),
            None => {}
        }
        if let Some(f) = &c.fallback {
            log.warn(f);
        }
        if full {
            log.moves(&c.moves);
        }
        if let Some(b) = &c.band {
            record_band_correction(b, log, full);
        }
        if let (Some(x), Some(band)) = (&self.deep, self.band) {
            record_deep(x, band, self.n_deep, s, log, full);
        }
    }

    fn figures(&self) -> Vec<(&'static str, f64)> {
        let c = &self.correction;
        vec![
            ("ccp_augmentations", c.augmentations as f64),
            ("ccp_moved", c.moves.len() as f64),
            ("ccp_solver_ms", c.solver_time.as_secs_f64() * 1e3),
        ]
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// The band correction's scalars and, when `full`, its paths as line strips through cell
/// centres, coloured by cost (an empty batch clears the previous step's paths).
fn record_band_correction<const D: usize>(b: &BandCorrection<D>, log: &mut dyn Log<D>, full: bool) {
    for (name, v) in [
        ("n_in", b.n_in as f64),
        ("n_out", b.n_out as f64),
        ("s_in", b.s_in as f64),
        ("s_out", b.s_out as f64),
        ("n_move", b.n_move as f64),
        ("paths", b.paths_applied as f64),
        ("find_calls", b.find_calls as f64),
        ("path_ms", b.second_time.as_secs_f64() * 1e3),
    ] {
        log.scalar(&format!("metrics/band/{name}"), v);
    }
    log.scalar(
        &format!("metrics/band/objective/{}", b.variant.name()),
        b.cost,
    );
    for (v, o) in &b.other_costs {
        match o {
            Ok(o) => log.scalar(&format!("metrics/band/objective/{}", v.name()), *o),
            Err(e) => log.warn(&format!(
                "band variant {} failed on this step's problem: {e}",
                v.name()
            )),
        }
    }
    if let Some(f) = &b.failure {
        log.warn(&format!("band {}: {f}", b.variant.name()));
    }
    if full {
        let scale = b.paths.iter().map(|p| p.cost.abs()).fold(0.0, f64::max);
        let colors: Vec<[u8; 3]> = b.paths.iter().map(|p| cost_color(p.cost, scale)).collect();
        let labels = b.paths.iter().map(|p| format!("{:.3}", p.cost)).collect();
        let strips: Vec<Vec<Vector<D>>> = b.paths.iter().map(|p| p.cells.clone()).collect();
        let style = Style {
            color: [0, 0, 0],
            radius: 0.08,
            order: 30.0,
        };
        log.strips("world/corrector/paths", &strips, &colors, labels, style);
    }
}

/// The deep: its particles, the exchange, and when `full` the depth levels of every cell.
fn record_deep<const D: usize>(
    x: &DeepExchange,
    band: Band,
    n_deep: usize,
    s: &State<D>,
    log: &mut dyn Log<D>,
    full: bool,
) {
    log.scalar("metrics/band/n_deep", n_deep as f64);
    log.scalar("metrics/band/band_particles", s.particles.len() as f64);
    log.scalar("metrics/band/removed", x.removed as f64);
    log.scalar("metrics/band/added", x.added as f64);
    if x.unplaced > 0 {
        log.warn(&format!(
            "the band interface had no room for {} of the deep's excess particles (kept in n_deep)",
            x.unplaced
        ));
    }
    if full {
        let layer = Layer {
            order: 1.0,
            radius_3d: 0.2,
        };
        let hidden = [DepthLevel::NotFluid as u8];
        let class = |c: usize| band.level(&s.markings, c) as u8;
        log.cell_classes("world/grid/depth", &class, &hidden, layer);
    }
}

/// Path colour by cost: green for paths that lower the objective, red for those that raise it.
fn cost_color(cost: f64, scale: f64) -> [u8; 3] {
    let t = (cost / scale.max(1e-12)).clamp(-1.0, 1.0);
    if t < 0.0 {
        [40, (120.0 - 100.0 * t) as u8, 60]
    } else {
        [(120.0 + 135.0 * t) as u8, 60, 40]
    }
}

/// What ccp did over a run, for the summary.
#[derive(Clone, Debug, Default)]
struct Totals {
    corrections: u64,
    moved: u64,
    overfull_max: usize,
    fallbacks: u64,
    cross_check_max: Option<f64>,
    solver_times: Vec<Duration>,
    cross_check_times: Vec<Duration>,
    /// Band: the fewest and most particles held after a step, paths applied, particles moved
    /// across the interface, failed band corrections, excess without room, the second step's
    /// times, and per other variant (cross-check) the relative objective gaps to the one run.
    band_particles: Option<(usize, usize)>,
    band_paths: u64,
    band_moves: u64,
    band_failures: u64,
    unplaced: u64,
    second_times: Vec<Duration>,
    band_gaps: Vec<(&'static str, Vec<f64>)>,
    exported: Option<(u64, PathBuf)>,
    exported_second: Option<PathBuf>,
}

impl Totals {
    fn add<const D: usize>(&mut self, rep: &CcpReport<D>, particles: usize) {
        let c = &rep.correction;
        self.corrections += 1;
        self.moved += c.moves.len() as u64;
        self.overfull_max = self.overfull_max.max(c.overfull_before);
        self.fallbacks += c.fallback.is_some() as u64;
        self.solver_times.push(c.solver_time);
        if let Some(t) = c.cross_check_time {
            self.cross_check_times.push(t);
        }
        if let Some(Ok(d)) = c.cross_check {
            self.cross_check_max = Some(self.cross_check_max.unwrap_or(0.0).max(d));
        }
        if let Some(b) = &c.band {
            self.add_band(b);
        }
        if let Some(x) = &rep.deep {
            self.unplaced += x.unplaced as u64;
            let (lo, hi) = self.band_particles.unwrap_or((particles, particles));
            self.band_particles = Some((lo.min(particles), hi.max(particles)));
        }
    }

    fn add_band<const D: usize>(&mut self, b: &BandCorrection<D>) {
        self.band_paths += b.paths_applied as u64;
        self.band_moves += b.n_move as u64;
        self.band_failures += b.failure.is_some() as u64;
        self.second_times.push(b.second_time);
        for (v, o) in &b.other_costs {
            let gap = o
                .as_ref()
                .map_or(f64::NAN, |o| (o - b.cost) / b.cost.abs().max(1e-12));
            match self.band_gaps.iter_mut().find(|(n, _)| *n == v.name()) {
                Some((_, g)) => g.push(gap),
                None => self.band_gaps.push((v.name(), vec![gap])),
            }
        }
    }

    fn lines(
        &self,
        s: &CorrectionSettings,
        band: Option<(&str, u32)>,
        n_deep: usize,
    ) -> Vec<String> {
        let ms = |d: Option<Duration>| d.map_or(0.0, |d| d.as_secs_f64() * 1e3);
        let mut out = vec![format!(
            "correction: {} particles sent to another cell in all; up to {} over-full cells before one correction; {} solver fallbacks; {} solver median {:.2} ms",
            self.moved,
            self.overfull_max,
            self.fallbacks,
            s.solver.name(),
            ms(median(&self.solver_times))
        )];
        if let Some(d) = self.cross_check_max {
            let ratios: Vec<f64> = self
                .cross_check_times
                .iter()
                .zip(&self.solver_times)
                .map(|(o, t)| o.as_secs_f64() / t.as_secs_f64().max(1e-9))
                .collect();
            let what = match band {
                Some((v, _)) if v == BandVariant::ExactPaths.name() => {
                    "the simplex on exact-paths' second steps"
                }
                _ => "the other solver",
            };
            out.push(format!(
                "  cross-check: objectives differ by at most {d:.2e} (relative); {what} took median {:.2} ms, {:.0}x the first solve's (min {:.0}x, max {:.0}x)",
                ms(median(&self.cross_check_times)),
                median(&ratios).unwrap_or(f64::NAN),
                ratios.iter().cloned().fold(f64::INFINITY, f64::min),
                ratios.iter().cloned().fold(0.0, f64::max),
            ));
        }
        if let Some((variant, r)) = band {
            out.extend(self.band_lines(variant, r, n_deep));
        }
        if let Some((step, path)) = &self.exported {
            out.push(format!(
                "wrote the correction problem of step {step} to {}",
                path.display()
            ));
        }
        if let Some(path) = &self.exported_second {
            out.push(format!(
                "wrote its exact-paths second step to {}",
                path.display()
            ));
        }
        out
    }

    fn band_lines(&self, variant: &str, r: u32, n_deep: usize) -> Vec<String> {
        let (lo, hi) = self.band_particles.unwrap_or_default();
        let mut out = vec![format!(
            "band ({variant}, R = {r}): {lo} .. {hi} band particles after a step, n_deep = {n_deep} at the end; {} particles moved across the interface along {} paths (second step median {:.2} ms); band correction failed on {} steps; {} excess particles found no room in the interface",
            self.band_moves,
            self.band_paths,
            median(&self.second_times).map_or(0.0, |d| d.as_secs_f64() * 1e3),
            self.band_failures,
            self.unplaced
        )];
        for (v, gaps) in &self.band_gaps {
            let failed = gaps.iter().filter(|x| x.is_nan()).count();
            let mut g: Vec<f64> = gaps.iter().cloned().filter(|x| !x.is_nan()).collect();
            g.sort_by(f64::total_cmp);
            out.push(match (g.first(), g.last()) {
                (Some(lo), Some(hi)) => format!(
                    "  {v} on the same problems: objective {:+.3}% .. {:+.3}% (median {:+.3}%) relative to {variant}; failed on {failed} of {} steps",
                    100.0 * lo,
                    100.0 * hi,
                    100.0 * g[g.len() / 2],
                    gaps.len()
                ),
                _ => format!("  {v} on the same problems: failed on all {failed} steps"),
            });
        }
        out
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
