//! What method idp records and sums up: its panels and density-error view, its step report's
//! scalars and drawings, and the run's totals.

use crate::draw::{Layer, LayerView, Log, Needs, Panel, Style};
use crate::grid::Vector;
use crate::methods::seam::{MethodReport, MethodSummary};
use crate::metrics::median;
use crate::solvers::pcg::PcgStats;
use crate::stages::State;
use std::any::Any;

/// What one projection did.
#[derive(Clone, Debug, Default)]
pub struct IdpReport<const D: usize> {
    pub pcg: PcgStats,
    /// Each cell's [`ErrorClass`], for recordings.
    pub class: Vec<u8>,
    /// `(before, after)` of every k-th particle, at most `MAX_ARROWS`.
    pub moves: Vec<(Vector<D>, Vector<D>)>,
    /// The largest particle displacement, cells.
    pub max_displacement: f64,
    /// Fluid cells more than one particle over the rest density (`s < -1/mu`).
    pub overdense: usize,
    /// Cells whose density error was clamped.
    pub clamped: usize,
    /// Under-dense surface cells that left the solve.
    pub surface: usize,
    /// Particles pushed out of solids.
    pub pushed: usize,
    /// Cells resampled.
    pub resampled: usize,
}

/// The density error of a cell, in classes for recordings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum ErrorClass {
    NotFluid = 0,
    /// Under-dense at the surface: left the solve.
    Surface = 1,
    /// `s <= -0.5` (clamped, or resampled).
    OverClamped = 2,
    /// `-0.5 < s < -0.05`.
    Over = 3,
    /// `|s| <= 0.05`.
    Rest = 4,
    /// `0.05 < s < 0.5`.
    Under = 5,
    /// `s >= 0.5`.
    UnderClamped = 6,
}

impl ErrorClass {
    /// Labels and colours: over-dense red, under-dense blue, at rest faint grey.
    pub(super) fn table() -> [(u16, &'static str, [u8; 4]); 7] {
        [
            (0, "not fluid", [0, 0, 0, 0]),
            (
                1,
                "surface, under-dense (left the solve)",
                [60, 180, 75, 110],
            ),
            (2, "over-dense, clamped (s <= -0.5)", [200, 20, 20, 200]),
            (3, "over-dense (-0.5 < s < -0.05)", [240, 120, 100, 160]),
            (4, "at rest (|s| <= 0.05)", [128, 128, 128, 40]),
            (5, "under-dense (0.05 < s < 0.5)", [110, 150, 240, 160]),
            (6, "under-dense, clamped (s >= 0.5)", [30, 60, 200, 200]),
        ]
    }
}

pub(super) const PANELS: &[Panel] = &[
    Panel {
        title: "idp: PCG iterations",
        series: &["metrics/idp/iterations"],
        needs: Needs::Always,
    },
    Panel {
        title: "idp: PCG residual",
        series: &["metrics/idp/residual"],
        needs: Needs::Always,
    },
    Panel {
        title: "idp: largest move (cells)",
        series: &["metrics/idp/max_displacement"],
        needs: Needs::Always,
    },
    Panel {
        title: "idp: cells",
        series: &[
            "metrics/idp/overdense_cells",
            "metrics/idp/clamped_cells",
            "metrics/idp/resampled",
        ],
        needs: Needs::Always,
    },
    Panel {
        title: "idp: particles pushed out of solids",
        series: &["metrics/idp/pushed"],
        needs: Needs::Always,
    },
];

pub(super) const LAYER_VIEWS: &[LayerView] = &[LayerView {
    title: "density error",
    origin: "world",
    layers: &["world/idp/density_error"],
    marks: &["world/idp/displacement"],
    needs: Needs::Always,
}];

impl<const D: usize> MethodReport<D> for IdpReport<D> {
    fn record(&self, _s: &State<D>, log: &mut dyn Log<D>, full: bool) {
        log.scalar("metrics/idp/iterations", self.pcg.iterations as f64);
        log.scalar("metrics/idp/residual", self.pcg.residual);
        log.scalar("metrics/idp/max_displacement", self.max_displacement);
        log.scalar("metrics/idp/overdense_cells", self.overdense as f64);
        log.scalar("metrics/idp/clamped_cells", self.clamped as f64);
        log.scalar("metrics/idp/pushed", self.pushed as f64);
        log.scalar("metrics/idp/resampled", self.resampled as f64);
        if !self.pcg.converged {
            log.warn(&format!(
                "idp: the second solve did not converge ({:?})",
                self.pcg
            ));
        }
        if full {
            let class = |c: usize| self.class[c];
            let hidden = [ErrorClass::NotFluid as u8, ErrorClass::Rest as u8];
            let layer = Layer {
                order: 1.0,
                radius_3d: 0.25,
            };
            log.cell_classes("world/idp/density_error", &class, &hidden, layer);
            let style = Style {
                color: [255, 170, 0],
                radius: 0.04,
                order: 20.0,
            };
            log.arrows("world/idp/displacement", &self.moves, style);
        }
    }

    fn figures(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("idp_iterations", self.pcg.iterations as f64),
            ("idp_max_displacement", self.max_displacement),
        ]
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// What idp did over a run.
#[derive(Clone, Debug, Default)]
pub(super) struct Totals {
    iterations: Vec<usize>,
    not_converged: u64,
    max_displacement: f64,
    overdense_max: usize,
    clamped_max: usize,
    pushed: u64,
    resampled: u64,
}

impl<const D: usize> MethodSummary<D> for Totals {
    fn add(&mut self, report: &dyn MethodReport<D>, _s: &State<D>) {
        let r = report.as_any().downcast_ref::<IdpReport<D>>();
        self.add_report(r.expect("an idp report"));
    }

    fn lines(&self) -> Vec<String> {
        self.summary_lines()
    }
}

impl Totals {
    fn add_report<const D: usize>(&mut self, r: &IdpReport<D>) {
        self.iterations.push(r.pcg.iterations);
        self.not_converged += !r.pcg.converged as u64;
        self.max_displacement = self.max_displacement.max(r.max_displacement);
        self.overdense_max = self.overdense_max.max(r.overdense);
        self.clamped_max = self.clamped_max.max(r.clamped);
        self.pushed += r.pushed as u64;
        self.resampled += r.resampled as u64;
    }

    fn summary_lines(&self) -> Vec<String> {
        let mut out = vec![format!(
            "idp: second solve median {} PCG iterations (max {}), did not converge on {} steps; largest particle displacement {:.3} cells; up to {} over-dense and {} clamped cells in a step",
            median(&self.iterations).unwrap_or(0),
            self.iterations.iter().max().unwrap_or(&0),
            self.not_converged,
            self.max_displacement,
            self.overdense_max,
            self.clamped_max
        )];
        if self.pushed > 0 || self.resampled > 0 {
            out.push(format!(
                "  {} particles pushed out of solids, {} cells resampled in all",
                self.pushed, self.resampled
            ));
        }
        out
    }
}
