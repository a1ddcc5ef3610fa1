//! What method powerpic records and sums up: its panels and fluid-fraction view, its step
//! report's scalars and image, and the run's Sinkhorn totals.

use crate::draw::{Image, LayerView, Log, Needs, Panel};
use crate::methods::seam::{MethodReport, MethodSummary};
use crate::stages::State;
use std::any::Any;

/// What Power PIC did in one step.
#[derive(Clone, Debug, Default)]
pub struct PowerPicReport {
    /// Whether a transport was solved this step (the other fields are zero otherwise).
    pub solved: bool,
    /// Sinkhorn's row updates.
    pub iterations: u32,
    /// The largest relative column error when it stopped.
    pub marginal_error: f64,
    /// Whether it met `delta` (otherwise it stopped at its cap, or out of range).
    pub converged: bool,
    /// Whether it stopped before its scalings left their range: marginals it cannot meet
    /// (`crate::solvers::sinkhorn::Transport::out_of_range`).
    pub out_of_range: bool,
    /// Empty volume of the transport cells in the liquid's cells, cells.
    pub air_volume: f64,
    /// The transport grid's fluid fraction (2D; the mid slice in 3D).
    pub fraction: Image,
}

pub(super) const PANELS: &[Panel] = &[
    Panel {
        title: "powerpic: Sinkhorn iterations",
        series: &["metrics/powerpic/iterations"],
        needs: Needs::Always,
    },
    Panel {
        title: "powerpic: marginal error",
        series: &["metrics/powerpic/marginal_error"],
        needs: Needs::Always,
    },
    Panel {
        title: "powerpic: air in liquid cells",
        series: &["metrics/powerpic/air_volume"],
        needs: Needs::Always,
    },
];

pub(super) const LAYER_VIEWS: &[LayerView] = &[LayerView {
    title: "transport grid: fluid fraction",
    origin: "powerpic",
    layers: &["powerpic/fluid_fraction"],
    marks: &[],
    needs: Needs::Always,
}];

impl<const D: usize> MethodReport<D> for PowerPicReport {
    fn record(&self, _s: &State<D>, log: &mut dyn Log<D>, full: bool) {
        log.scalar("metrics/powerpic/iterations", self.iterations as f64);
        log.scalar("metrics/powerpic/marginal_error", self.marginal_error);
        log.scalar("metrics/powerpic/air_volume", self.air_volume);
        if self.out_of_range {
            log.warn(&format!(
                "powerpic: Sinkhorn stopped at iteration {} with marginal error {:.3e}, its \
                 scalings running out of range: marginals it cannot meet",
                self.iterations, self.marginal_error
            ));
        } else if !self.converged {
            log.warn(&format!(
                "powerpic: Sinkhorn stopped at its cap of {} iterations with marginal error \
                 {:.3e}",
                self.iterations, self.marginal_error
            ));
        }
        if full {
            log.image("powerpic/fluid_fraction", &self.fraction, [0.0, 1.0]);
        }
    }

    fn figures(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("powerpic_iterations", self.iterations as f64),
            ("powerpic_marginal_error", self.marginal_error),
            ("powerpic_air_volume", self.air_volume),
        ]
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// What the summary reports: Sinkhorn's iterations over the steps that solved a transport.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Totals {
    /// `simulation.powerpic.max_iterations`, named when it was reached.
    max_iterations: u32,
    steps: u64,
    iterations: u64,
    most_iterations: u32,
    at_cap: u64,
    out_of_range: u64,
}

impl Totals {
    pub(super) fn new(max_iterations: u32) -> Self {
        Self {
            max_iterations,
            ..Self::default()
        }
    }
}

impl<const D: usize> MethodSummary<D> for Totals {
    fn add(&mut self, report: &dyn MethodReport<D>, _s: &State<D>) {
        let rep = report.as_any().downcast_ref::<PowerPicReport>();
        let rep = rep.expect("a powerpic report");
        if !rep.solved {
            return;
        }
        self.steps += 1;
        self.iterations += rep.iterations as u64;
        self.most_iterations = self.most_iterations.max(rep.iterations);
        self.at_cap += u64::from(!rep.converged && !rep.out_of_range);
        self.out_of_range += u64::from(rep.out_of_range);
    }

    fn lines(&self) -> Vec<String> {
        let t = self;
        if t.steps == 0 {
            return vec![];
        }
        let mut lines = vec![format!(
            "Sinkhorn: {:.1} iterations per step on average, {} at most",
            t.iterations as f64 / t.steps as f64,
            t.most_iterations
        )];
        if t.at_cap > 0 {
            lines.push(format!(
                "Sinkhorn reached its cap of {} iterations in {} of {} steps \
                 (simulation.powerpic.max_iterations)",
                t.max_iterations, t.at_cap, t.steps
            ));
        }
        if t.out_of_range > 0 {
            lines.push(format!(
                "Sinkhorn stopped short of its cap in {} of {} steps, its scalings running out of \
                 range (marginals it cannot meet; their error is in the marginal error)",
                t.out_of_range, t.steps
            ));
        }
        lines
    }
}
