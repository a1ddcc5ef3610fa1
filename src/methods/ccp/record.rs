//! What method ccp records and sums up: its panels, its step report's scalars and drawings
//! (the correction's moves, the band's paths, the depth levels), and the run's totals.

use super::correct::band::{BandCorrection, BandVariant};
use super::correct::CorrectionReport;
use super::deep::DeepExchange;
use super::settings::{CcpSettings, Solver};
use crate::draw::{Layer, Log, Needs, Panel, Style};
use crate::grid::Vector;
use crate::methods::seam::{Export, MethodReport, MethodSummary};
use crate::metrics::median;
use crate::stages::band::Band;
use crate::stages::markings::DepthLevel;
use crate::stages::State;
use std::any::Any;
use std::path::PathBuf;
use std::time::Duration;

/// The correction's and the band's panels: counts, objectives, penalties and times apart.
pub(super) const PANELS: &[Panel] = &[
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
    /// Where the correction problem of this step goes (`--export-lp`), and its exact-paths
    /// second step: handed over with their text ([`MethodReport::exports`]).
    pub export: Option<(u64, PathBuf)>,
    pub export_second: Option<PathBuf>,
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
            log.warn(&f.to_string());
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
            // The band's second step (alg. find's paths for `paths`); NaN without a band.
            (
                "ccp_band_ms",
                c.band
                    .as_ref()
                    .map_or(f64::NAN, |b| b.second_time.as_secs_f64() * 1e3),
            ),
        ]
    }

    /// The correction problem asked for (`--export-lp`) and its exact-paths second step, as MPS.
    fn exports(&self) -> Vec<Export<'_>> {
        let c = &self.correction;
        let first =
            (self.export.as_ref().zip(c.mps.as_deref())).map(|((step, path), text)| Export {
                path,
                what: format!("the correction problem of step {step}"),
                text,
            });
        let second =
            (self.export_second.as_ref().zip(c.second_mps.as_deref())).map(|(path, text)| Export {
                path,
                what: "its exact-paths second step".into(),
                text,
            });
        first.into_iter().chain(second).collect()
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
pub(super) struct Totals {
    /// The settings it was run with: the solver, and the band's variant and `R`.
    solver: Solver,
    band: Option<(&'static str, u32)>,
    /// `n_deep` after the last step.
    n_deep: usize,
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
}

impl<const D: usize> MethodSummary<D> for Totals {
    fn add(&mut self, report: &dyn MethodReport<D>, s: &State<D>) {
        let rep = report.as_any().downcast_ref::<CcpReport<D>>();
        self.add_report(rep.expect("a ccp report"), s.particles.len());
    }

    fn lines(&self) -> Vec<String> {
        self.summary_lines()
    }
}

impl Totals {
    pub(super) fn new(s: &CcpSettings) -> Self {
        Self {
            solver: s.solver,
            band: s.band.variant().map(|v| (v.name(), s.band_r)),
            ..Self::default()
        }
    }

    fn add_report<const D: usize>(&mut self, rep: &CcpReport<D>, particles: usize) {
        self.n_deep = rep.n_deep;
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

    /// The summary's lines.
    fn summary_lines(&self) -> Vec<String> {
        let ms = |d: Option<Duration>| d.map_or(0.0, |d| d.as_secs_f64() * 1e3);
        let mut out = vec![format!(
            "correction: {} particles sent to another cell in all; up to {} over-full cells before one correction; {} solver fallbacks; {} solver median {:.2} ms",
            self.moved,
            self.overfull_max,
            self.fallbacks,
            self.solver.name(),
            ms(median(&self.solver_times))
        )];
        if let Some(d) = self.cross_check_max {
            let ratios: Vec<f64> = self
                .cross_check_times
                .iter()
                .zip(&self.solver_times)
                .map(|(o, t)| o.as_secs_f64() / t.as_secs_f64().max(1e-9))
                .collect();
            let what = match self.band {
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
        if let Some((variant, r)) = self.band {
            out.extend(self.band_lines(variant, r, self.n_deep));
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
