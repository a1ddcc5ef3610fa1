//! What method nbflip records and sums up: its panels and band-level view, its step report's
//! scalars and the band levels by the level set, and the run's totals.

use super::levelset::{level, LevelSet};
use crate::draw::{Image, Layer, LayerView, Log, Needs, Panel};
use crate::methods::seam::{MethodReport, MethodSummary};
use crate::metrics::median;
use crate::stages::markings::DepthLevel;
use crate::stages::State;
use std::any::Any;
use std::sync::Arc;

/// What nbflip did in one step: its resampling, the particles it holds, and the band levels
/// of every cell by the level set.
#[derive(Clone, Debug, Default)]
pub struct NbflipReport {
    pub seeded: usize,
    /// Particles deleted inside a solid (an `ignore` obstacle moved over them).
    pub covered: usize,
    /// Particles deleted outside the liquid (`phi > 0`).
    pub outside: usize,
    /// Particles deleted below the band (`phi < -R`).
    pub below: usize,
    /// Particles deleted beyond `2 mu` in a cell away from the surface.
    pub crowded: usize,
    /// Particles held after the step.
    pub particles: usize,
    /// Cells of liquid the obstacles newly covered in the step (`ignore`: liquid lost).
    pub carved: usize,
    /// Cells the level set was last rebuilt on (all cells with the dense level set).
    pub cells_worked: usize,
    /// `R` and the level set after the step.
    pub band_r: u32,
    pub phi: Arc<LevelSet>,
}

impl NbflipReport {
    pub fn deleted(&self) -> usize {
        self.covered + self.outside + self.below + self.crowded
    }

    /// Adds another resampling of the same step (after emission and at the end).
    pub(super) fn add(&mut self, other: &NbflipReport) {
        self.seeded += other.seeded;
        self.covered += other.covered;
        self.outside += other.outside;
        self.below += other.below;
        self.crowded += other.crowded;
    }
}

pub(super) const PANELS: &[Panel] = &[
    Panel {
        title: "narrow band: particles held",
        series: &["metrics/nbflip/particles"],
        needs: Needs::Always,
    },
    Panel {
        title: "narrow band: resampling",
        series: &["metrics/nbflip/seeded", "metrics/nbflip/deleted"],
        needs: Needs::Always,
    },
    Panel {
        title: "narrow band: liquid obstacles covered (cells)",
        series: &["metrics/nbflip/carved"],
        needs: Needs::Obstacles,
    },
];

pub(super) const LAYER_VIEWS: &[LayerView] = &[
    LayerView {
        title: "band levels",
        origin: "world",
        layers: &["world/grid/depth"],
        marks: &[],
        needs: Needs::Always,
    },
    LayerView {
        title: "level set phi (cells)",
        origin: "nbflip",
        layers: &["nbflip/level_set"],
        marks: &[],
        needs: Needs::Always,
    },
];

/// The level set's values drawn: from `R + 1` cells inside (below the band's interface at
/// `-R`) to 3 cells outside (the outward re-march reaches 3); beyond, the colour map's ends.
fn level_set_range(band_r: u32) -> [f32; 2] {
    [-(band_r as f32 + 1.0), 3.0]
}

impl<const D: usize> MethodReport<D> for NbflipReport {
    fn record(&self, s: &State<D>, log: &mut dyn Log<D>, full: bool) {
        log.scalar("metrics/nbflip/particles", self.particles as f64);
        log.scalar("metrics/nbflip/seeded", self.seeded as f64);
        log.scalar("metrics/nbflip/deleted", self.deleted() as f64);
        if !s.solids.obstacles.is_empty() {
            log.scalar("metrics/nbflip/carved", self.carved as f64);
        }
        if full {
            let layer = Layer {
                order: 1.0,
                radius_3d: 0.2,
            };
            let hidden = [DepthLevel::NotFluid as u8, DepthLevel::Deep as u8];
            let (phi, solid, r) = (&self.phi, &s.solids.solid, self.band_r as f64);
            let class = |c| level::<D>(phi, solid, r, c) as u8;
            log.cell_classes("world/grid/depth", &class, &hidden, layer);
            let image = Image::of_cells(s.grid.dims, |c| phi.phi[c] as f32);
            log.image("nbflip/level_set", &image, level_set_range(self.band_r));
        }
    }

    fn figures(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("nbflip_seeded", self.seeded as f64),
            ("nbflip_deleted", self.deleted() as f64),
            ("nbflip_carved", self.carved as f64),
        ]
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// What nbflip did over a run: each step's report without its level set.
#[derive(Debug)]
pub(super) struct Totals {
    band_r: u32,
    steps: Vec<NbflipReport>,
}

impl Totals {
    pub(super) fn new(band_r: u32) -> Self {
        Self {
            band_r,
            steps: vec![],
        }
    }
}

impl<const D: usize> MethodSummary<D> for Totals {
    fn add(&mut self, report: &dyn MethodReport<D>, _s: &State<D>) {
        let rep = report.as_any().downcast_ref::<NbflipReport>();
        let rep = rep.expect("an nbflip report");
        self.steps.push(NbflipReport {
            phi: Default::default(),
            ..rep.clone()
        });
    }

    fn lines(&self) -> Vec<String> {
        let (lo, hi) = self.steps.iter().fold((usize::MAX, 0), |(lo, hi), r| {
            (lo.min(r.particles), hi.max(r.particles))
        });
        let sum = |f: fn(&NbflipReport) -> usize| self.steps.iter().map(f).sum::<usize>();
        let seeded: Vec<usize> = self.steps.iter().map(|r| r.seeded).collect();
        let worked: Vec<usize> = self.steps.iter().map(|r| r.cells_worked).collect();
        let mut lines = vec![format!(
            "narrow band (R = {}): {lo} .. {hi} particles after a step; level set worked on {} cells (median a step); resampling seeded {} (median {} a step) and deleted {} outside the liquid, {} below the band, {} in crowded cells",
            self.band_r,
            median(&worked).unwrap_or(0),
            sum(|r| r.seeded),
            median(&seeded).unwrap_or(0),
            sum(|r| r.outside),
            sum(|r| r.below),
            sum(|r| r.crowded),
        )];
        let (carved, covered) = (sum(|r| r.carved), sum(|r| r.covered));
        if carved + covered > 0 {
            lines.push(format!(
                "obstacles covered {carved} cells of liquid (lost) and {covered} particles (deleted)"
            ));
        }
        lines
    }
}
