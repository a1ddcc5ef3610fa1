//! Rerun recordings: the only module that imports `rerun`.
//!
//! World units are cells. In 2D the world is drawn as an image (x right, rows down), so
//! positions are logged as `(x, ny - y)`: gravity points down the screen and each particle lies
//! over its cell of the `world/grid/markings` image. In 3D, y is up (`RIGHT_HAND_Y_UP`).
//! Entity paths are listed in the README and in [`ENTITY_PATHS`].

use crate::grid::Vector;
use crate::metrics::Stage;
use crate::particles::Region;
use crate::scene::Scene;
use crate::sim::correct::band::BandCorrection;
use crate::sim::markings::{DepthLevel, MarkingClass, Markings};
use crate::sim::{Simulation, StepReport};
use anyhow::{anyhow, Result};
use rerun::blueprint::{
    Blueprint, Horizontal, Spatial2DView, Spatial3DView, TextDocumentView, TextLogView,
    TimeSeriesView, Vertical,
};
use rerun::RecordingStream;
use std::cell::{Cell, RefCell};
use std::path::Path;
use std::time::{Duration, Instant};

/// Every entity a run logs (the ones under `metrics/` with their leaves).
pub const ENTITY_PATHS: &[&str] = &[
    "scene",
    "world",
    "world/domain",
    "world/particles",
    "world/grid/markings",
    "metrics/volume_percent",
    "metrics/particles",
    "metrics/dt",
    "metrics/max_speed",
    "metrics/pcg/iterations",
    "metrics/pcg/residual",
    "metrics/time/<stage>",
    "log",
];

/// What method `ccp` logs besides [`ENTITY_PATHS`].
pub const CORRECTION_ENTITY_PATHS: &[&str] = &[
    "world/corrector/moves",
    "metrics/correction/objective",
    "metrics/correction/moved",
    "metrics/correction/overfull_before",
    "metrics/correction/solver_ms",
    "metrics/correction/augmentations",
];

/// What the band method (`--band`) logs besides the above.
pub const BAND_ENTITY_PATHS: &[&str] = &[
    "world/grid/depth",
    "world/corrector/paths",
    "metrics/band/n_in",
    "metrics/band/n_out",
    "metrics/band/s_in",
    "metrics/band/s_out",
    "metrics/band/n_move",
    "metrics/band/paths",
    "metrics/band/find_calls",
    "metrics/band/path_ms",
    "metrics/band/n_deep",
    "metrics/band/band_particles",
    "metrics/band/removed",
    "metrics/band/added",
    "metrics/band/objective/<variant>",
];

/// What scenes with obstacles (sec. 7) log besides the above.
pub const OBSTACLE_ENTITY_PATHS: &[&str] = &[
    "world/obstacles/<name>",
    "world/obstacles/<name>/trail",
    "world/obstacles/new_solid",
    "metrics/obstacle/<name>/height",
    "metrics/obstacle/<name>/speed",
    "metrics/obstacle/<name>/blocked",
];

/// Writes one run to an `.rrd` file.
pub struct Recorder {
    rec: RecordingStream,
    dims: Vec<usize>,
    max_speed: f64,
    last_flush: Cell<Instant>,
    /// Every obstacle's centres so far (world coordinates), for its trail.
    trails: RefCell<Vec<Vec<[f32; 3]>>>,
}

fn blueprint(dim: usize) -> Blueprint {
    let world: rerun::blueprint::ContainerLike = if dim == 2 {
        Spatial2DView::new("world").with_origin("world").into()
    } else {
        Spatial3DView::new("world").with_origin("world").into()
    };
    Blueprint::new(
        Horizontal::new([
            world,
            Vertical::new([
                TimeSeriesView::new("volume %")
                    .with_origin("metrics/volume_percent")
                    .into(),
                TimeSeriesView::new("stage times (ms)")
                    .with_origin("metrics/time")
                    .into(),
                TimeSeriesView::new("pressure solve")
                    .with_origin("metrics/pcg")
                    .into(),
                TimeSeriesView::new("correction")
                    .with_origin("metrics/correction")
                    .into(),
                TimeSeriesView::new("band")
                    .with_origin("metrics/band")
                    .into(),
                TextLogView::new("log").with_origin("log").into(),
                TextDocumentView::new("scene").with_origin("scene").into(),
            ])
            .into(),
        ])
        .with_column_shares([2.0, 1.0]),
    )
}

/// Colour ramp for speeds: dark blue at rest, through cyan, to white at the speed bound.
fn speed_color(speed: f64, max: f64) -> [u8; 3] {
    let s = (speed / max).clamp(0.0, 1.0);
    let lerp = |a: f64, b: f64, t: f64| (a + (b - a) * t) as u8;
    if s < 0.5 {
        let t = s * 2.0;
        [
            lerp(20.0, 40.0, t),
            lerp(60.0, 200.0, t),
            lerp(160.0, 255.0, t),
        ]
    } else {
        let t = (s - 0.5) * 2.0;
        [lerp(40.0, 255.0, t), lerp(200.0, 255.0, t), 255]
    }
}

fn class_color(c: MarkingClass) -> rerun::Rgba32 {
    match c {
        MarkingClass::Empty => rerun::Rgba32::from_unmultiplied_rgba(0, 0, 0, 0),
        MarkingClass::Surface => rerun::Rgba32::from_unmultiplied_rgba(60, 180, 75, 140),
        MarkingClass::Inner => rerun::Rgba32::from_unmultiplied_rgba(30, 70, 160, 110),
        MarkingClass::Bubble => rerun::Rgba32::from_unmultiplied_rgba(230, 50, 50, 160),
        MarkingClass::Solid => rerun::Rgba32::from_unmultiplied_rgba(128, 128, 128, 255),
    }
}

/// The band level of a cell (not fluid for empty and solid cells).
fn level_of(m: &Markings, c: usize, r: u32) -> DepthLevel {
    if m.is_fluid(c) {
        m.level(c, r)
    } else {
        DepthLevel::NotFluid
    }
}

fn level_color(l: DepthLevel) -> rerun::Rgba32 {
    match l {
        DepthLevel::NotFluid => rerun::Rgba32::from_unmultiplied_rgba(0, 0, 0, 0),
        DepthLevel::Surface => rerun::Rgba32::from_unmultiplied_rgba(60, 180, 75, 120),
        DepthLevel::Band => rerun::Rgba32::from_unmultiplied_rgba(120, 190, 240, 110),
        DepthLevel::Interface => rerun::Rgba32::from_unmultiplied_rgba(240, 200, 40, 170),
        DepthLevel::Deep => rerun::Rgba32::from_unmultiplied_rgba(20, 40, 120, 140),
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

impl Recorder {
    /// Opens `path` for writing; fails (naming the path) before anything is simulated.
    pub fn create(path: &Path, scene: &Scene) -> Result<Self> {
        let rec = rerun::RecordingStreamBuilder::new("cellflip")
            .recording_name(scene.name())
            .enabled(true)
            .send_properties(false)
            .with_blueprint(blueprint(scene.dim()))
            .save(path)
            .map_err(|e| anyhow!("cannot write recording '{}': {e}", path.display()))?;
        rec.set_log_time_enabled(false);
        let header = format!(
            "# {}\n\n{}\n\n- source: {}\n- method: {}\n- seed: {}\n- program: cellflip {}\n\n```toml\n{}```\n",
            scene.name(),
            scene.file.description,
            scene.source,
            scene.method.name(),
            scene.file.simulation.seed,
            env!("CARGO_PKG_VERSION"),
            scene.resolved_toml()
        );
        rec.log_static("scene", &rerun::TextDocument::from_markdown(header))?;
        Ok(Self {
            rec,
            dims: scene.dims.clone(),
            max_speed: scene.file.simulation.max_speed / scene.cell_size_m,
            last_flush: Cell::new(Instant::now()),
            trails: RefCell::new(vec![]),
        })
    }

    /// Static data: the class colours, the domain, the view coordinates.
    pub fn log_setup<const D: usize>(&self, sim: &Simulation<D>) {
        let classes: Vec<(u16, &str, rerun::Rgba32)> = MarkingClass::ALL
            .iter()
            .map(|c| (*c as u16, c.label(), class_color(*c)))
            .collect();
        let d = &self.dims;
        let result = (|| -> rerun::RecordingStreamResult<()> {
            self.rec
                .log_static("world", &rerun::AnnotationContext::new(classes))?;
            if sim.band().is_some() {
                let levels: Vec<(u16, &str, rerun::Rgba32)> = DepthLevel::ALL
                    .iter()
                    .map(|l| (*l as u16, l.label(), level_color(*l)))
                    .collect();
                self.rec
                    .log_static("world/grid/depth", &rerun::AnnotationContext::new(levels))?;
            }
            if D == 2 {
                self.rec.log_static(
                    "world/domain",
                    &rerun::Boxes2D::from_mins_and_sizes(
                        [(0.0f32, 0.0)],
                        [(d[0] as f32, d[1] as f32)],
                    )
                    .with_colors([[200u8, 200, 200]]),
                )?;
            } else {
                self.rec
                    .log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Y_UP())?;
                let half = (d[0] as f32 / 2.0, d[1] as f32 / 2.0, d[2] as f32 / 2.0);
                self.rec.log_static(
                    "world/domain",
                    &rerun::Boxes3D::from_centers_and_half_sizes([half], [half])
                        .with_colors([[200u8, 200, 200]])
                        .with_fill_mode(rerun::FillMode::MajorWireframe),
                )?;
            }
            self.rec.log_static(
                "log",
                &rerun::TextLog::new(format!(
                    "{} particles on {:?} cells, mu = {}",
                    sim.particles.len(),
                    sim.grid.dims,
                    sim.config.mu()
                ))
                .with_level(rerun::TextLogLevel::INFO),
            )
        })();
        self.report(result);
    }

    fn set_time<const D: usize>(&self, sim: &Simulation<D>) {
        self.rec.set_time_sequence("step", sim.steps as i64);
        self.rec.set_duration_secs("sim_time", sim.time_secs);
    }

    /// The state after a step: particles and markings when `full`, metrics when `rep` is given.
    pub fn log_step<const D: usize>(
        &self,
        sim: &Simulation<D>,
        rep: Option<&StepReport<D>>,
        full: bool,
    ) {
        self.set_time(sim);
        let mu = sim.config.mu();
        let result = (|| -> rerun::RecordingStreamResult<()> {
            if full {
                let colors: Vec<[u8; 3]> = sim
                    .particles
                    .vel
                    .iter()
                    .map(|v| speed_color(v.norm(), self.max_speed))
                    .collect();
                let marks = &sim.markings;
                if D == 2 {
                    let ny = self.dims[1] as f32;
                    let pos: Vec<[f32; 2]> = sim
                        .particles
                        .pos
                        .iter()
                        .map(|x| [x[0] as f32, ny - x[1] as f32])
                        .collect();
                    self.rec.log(
                        "world/particles",
                        &rerun::Points2D::new(pos)
                            .with_colors(colors)
                            .with_radii([0.12f32])
                            .with_draw_order(10.0),
                    )?;
                    self.log_class_image("world/grid/markings", 0.0, |c| marks.class(c, mu) as u8)?;
                    if let Some(b) = sim.band() {
                        self.log_class_image("world/grid/depth", 1.0, |c| {
                            level_of(marks, c, b.r) as u8
                        })?;
                    }
                } else {
                    let pos: Vec<[f32; 3]> = sim
                        .particles
                        .pos
                        .iter()
                        .map(|x| [x[0] as f32, x[1] as f32, x[2] as f32])
                        .collect();
                    self.rec.log(
                        "world/particles",
                        &rerun::Points3D::new(pos)
                            .with_colors(colors)
                            .with_radii([0.15f32]),
                    )?;
                    let cells: Vec<(usize, MarkingClass)> = (0..marks.kind.len())
                        .map(|c| (c, marks.class(c, mu)))
                        .filter(|(_, k)| *k != MarkingClass::Empty && *k != MarkingClass::Inner)
                        .collect();
                    let centers: Vec<[f32; 3]> = cells
                        .iter()
                        .map(|(c, _)| {
                            let x = sim.grid.center(sim.grid.cell_coords(*c));
                            [x[0] as f32, x[1] as f32, x[2] as f32]
                        })
                        .collect();
                    let ids: Vec<rerun::components::ClassId> = cells
                        .iter()
                        .map(|(_, k)| rerun::components::ClassId::from(*k as u16))
                        .collect();
                    self.rec.log(
                        "world/grid/markings",
                        &rerun::Points3D::new(centers)
                            .with_class_ids(ids)
                            .with_radii([0.3f32]),
                    )?;
                    if let Some(b) = sim.band() {
                        let (centers, ids): (Vec<[f32; 3]>, Vec<rerun::components::ClassId>) =
                            (0..marks.kind.len())
                                .filter(|&c| marks.is_fluid(c))
                                .map(|c| {
                                    let x = sim.grid.center(sim.grid.cell_coords(c));
                                    (
                                        [x[0] as f32, x[1] as f32, x[2] as f32],
                                        rerun::components::ClassId::from(
                                            level_of(marks, c, b.r) as u16
                                        ),
                                    )
                                })
                                .unzip();
                        self.rec.log(
                            "world/grid/depth",
                            &rerun::Points3D::new(centers)
                                .with_class_ids(ids)
                                .with_radii([0.2f32]),
                        )?;
                    }
                }
            }
            if full {
                self.log_obstacles(sim)?;
            }
            if let Some(rep) = rep {
                let h = sim.config.cell_size_m;
                let scalar = |path: &str, v: f64| self.rec.log(path, &rerun::Scalars::single(v));
                scalar("metrics/volume_percent", rep.volume_percent)?;
                scalar("metrics/particles", sim.particles.len() as f64)?;
                scalar("metrics/dt", rep.dt_secs)?;
                scalar("metrics/max_speed", rep.max_speed * h)?;
                scalar("metrics/pcg/iterations", rep.pcg.iterations as f64)?;
                scalar("metrics/pcg/residual", rep.pcg.residual)?;
                for s in Stage::ALL {
                    scalar(
                        &format!("metrics/time/{}", s.name()),
                        rep.times.get(s).as_secs_f64() * 1e3,
                    )?;
                }
                if let Some(c) = &rep.correction {
                    scalar("metrics/correction/objective", c.objective)?;
                    scalar("metrics/correction/moved", c.moves.len() as f64)?;
                    scalar(
                        "metrics/correction/overfull_before",
                        c.overfull_before as f64,
                    )?;
                    scalar(
                        "metrics/correction/solver_ms",
                        c.solver_time.as_secs_f64() * 1e3,
                    )?;
                    scalar("metrics/correction/augmentations", c.augmentations as f64)?;
                    match &c.cross_check {
                        Some(Ok(d)) => scalar("metrics/correction/cross_check", *d)?,
                        Some(Err(e)) => self.rec.log(
                            "log",
                            &rerun::TextLog::new(format!(
                                "step {}: cross-check solver failed: {e}",
                                sim.steps
                            ))
                            .with_level(rerun::TextLogLevel::WARN),
                        )?,
                        None => {}
                    }
                    if let Some(f) = &c.fallback {
                        self.rec.log(
                            "log",
                            &rerun::TextLog::new(format!("step {}: {f}", sim.steps))
                                .with_level(rerun::TextLogLevel::WARN),
                        )?;
                    }
                    if full {
                        self.log_moves(&c.moves)?;
                    }
                    if let Some(b) = &c.band {
                        self.log_band(sim, b, full)?;
                    }
                }
                for (o, &blocked) in sim.obstacles.iter().zip(&rep.blocked) {
                    let m = format!("metrics/obstacle/{}", o.name);
                    scalar(&format!("{m}/height"), o.bottom() * h)?;
                    scalar(&format!("{m}/speed"), o.velocity.norm() * h)?;
                    scalar(&format!("{m}/blocked"), blocked as u8 as f64)?;
                }
                if full && !sim.obstacles.is_empty() {
                    self.log_new_solid(sim, &rep.new_solid)?;
                }
                if let Some(x) = &rep.deep {
                    scalar("metrics/band/n_deep", sim.n_deep as f64)?;
                    scalar("metrics/band/band_particles", sim.particles.len() as f64)?;
                    scalar("metrics/band/removed", x.removed as f64)?;
                    scalar("metrics/band/added", x.added as f64)?;
                    if x.unplaced > 0 {
                        self.rec.log(
                            "log",
                            &rerun::TextLog::new(format!(
                                "step {}: the band interface had no room for {} of the deep's excess particles (kept in n_deep)",
                                sim.steps, x.unplaced
                            ))
                            .with_level(rerun::TextLogLevel::WARN),
                        )?;
                    }
                }
                if rep.dt_shortened {
                    self.rec.log(
                        "log",
                        &rerun::TextLog::new(format!(
                            "step {}: time step shortened to {:.3e} s after the projection (max speed {:.3} m/s)",
                            sim.steps,
                            rep.dt_secs,
                            rep.max_speed * h
                        ))
                        .with_level(rerun::TextLogLevel::DEBUG),
                    )?;
                }
            }
            Ok(())
        })();
        self.report(result);
        self.flush_now_and_then();
    }

    /// A 2D `SegmentationImage` of one class id per cell (rows down: row 0 is the top).
    fn log_class_image(
        &self,
        path: &str,
        draw_order: f32,
        class: impl Fn(usize) -> u8,
    ) -> rerun::RecordingStreamResult<()> {
        let (w, h) = (self.dims[0], self.dims[1]);
        let mut img = vec![0u8; w * h];
        for c in 0..w * h {
            // Cell index c = x + w y (axis 0 fastest).
            let (x, y) = (c % w, c / w);
            img[(h - 1 - y) * w + x] = class(c);
        }
        self.rec.log(
            path,
            &rerun::SegmentationImage::new(
                img,
                rerun::ImageFormat::segmentation([w as u32, h as u32], rerun::ChannelDatatype::U8),
            )
            .with_draw_order(draw_order),
        )
    }

    /// World coordinates of a point in cells (2D: rows down).
    fn world(&self, x: &[f64]) -> [f32; 3] {
        if x.len() == 2 {
            [x[0] as f32, self.dims[1] as f32 - x[1] as f32, 0.0]
        } else {
            [x[0] as f32, x[1] as f32, x[2] as f32]
        }
    }

    /// Each obstacle's shape where it is now, and its trail (its centre over the steps).
    fn log_obstacles<const D: usize>(
        &self,
        sim: &Simulation<D>,
    ) -> rerun::RecordingStreamResult<()> {
        let mut trails = self.trails.borrow_mut();
        trails.resize(sim.obstacles.len(), vec![]);
        let color = [[230u8, 90, 40]];
        for (o, trail) in sim.obstacles.iter().zip(trails.iter_mut()) {
            let path = format!("world/obstacles/{}", o.name);
            let r = o.region_at(&o.offset);
            let (lo, hi) = r.bounds();
            let (a, b) = (self.world(lo.as_slice()), self.world(hi.as_slice()));
            let centre = self.world(r.center().as_slice());
            trail.push(centre);
            let half: [f32; 3] = std::array::from_fn(|k| (b[k] - a[k]).abs() / 2.0);
            // Balls as a point of their radius; boxes (obstacles are boxes or balls) as boxes.
            match (&r, D) {
                (Region::Ball { radius, .. }, 2) => self.rec.log(
                    path.as_str(),
                    &rerun::Points2D::new([(centre[0], centre[1])])
                        .with_radii([*radius as f32])
                        .with_colors(color)
                        .with_draw_order(25.0),
                )?,
                (Region::Ball { radius, .. }, _) => self.rec.log(
                    path.as_str(),
                    &rerun::Points3D::new([centre])
                        .with_radii([*radius as f32])
                        .with_colors(color),
                )?,
                (_, 2) => self.rec.log(
                    path.as_str(),
                    &rerun::Boxes2D::from_centers_and_half_sizes(
                        [(centre[0], centre[1])],
                        [(half[0], half[1])],
                    )
                    .with_colors(color)
                    .with_draw_order(25.0),
                )?,
                _ => self.rec.log(
                    path.as_str(),
                    &rerun::Boxes3D::from_centers_and_half_sizes([centre], [half])
                        .with_colors(color),
                )?,
            }
            let trail_path = format!("{path}/trail");
            if D == 2 {
                let strip: Vec<[f32; 2]> = trail.iter().map(|p| [p[0], p[1]]).collect();
                self.rec.log(
                    trail_path.as_str(),
                    &rerun::LineStrips2D::new([strip])
                        .with_colors(color)
                        .with_draw_order(24.0),
                )?;
            } else {
                self.rec.log(
                    trail_path.as_str(),
                    &rerun::LineStrips3D::new([trail.clone()]).with_colors(color),
                )?;
            }
        }
        Ok(())
    }

    /// The cells obstacles wanted this step (`C_new_solid`), labelled with their clearing
    /// distance (an empty batch clears the previous step's).
    fn log_new_solid<const D: usize>(
        &self,
        sim: &Simulation<D>,
        cells: &[(usize, u32)],
    ) -> rerun::RecordingStreamResult<()> {
        let centres: Vec<[f32; 3]> = cells
            .iter()
            .map(|(c, _)| self.world(sim.grid.center(sim.grid.cell_coords(*c)).as_slice()))
            .collect();
        let labels: Vec<String> = cells.iter().map(|(_, d)| d.to_string()).collect();
        let color = [[255u8, 200, 0]];
        if D == 2 {
            let pts: Vec<[f32; 2]> = centres.iter().map(|p| [p[0], p[1]]).collect();
            self.rec.log(
                "world/obstacles/new_solid",
                &rerun::Points2D::new(pts)
                    .with_labels(labels)
                    .with_radii([0.3f32])
                    .with_colors(color)
                    .with_draw_order(26.0),
            )
        } else {
            self.rec.log(
                "world/obstacles/new_solid",
                &rerun::Points3D::new(centres)
                    .with_labels(labels)
                    .with_radii([0.3f32])
                    .with_colors(color),
            )
        }
    }

    /// The band correction's scalars and, when `full`, its paths as line strips through cell
    /// centres, coloured by cost (an empty batch clears the previous step's paths).
    fn log_band<const D: usize>(
        &self,
        sim: &Simulation<D>,
        b: &BandCorrection<D>,
        full: bool,
    ) -> rerun::RecordingStreamResult<()> {
        let scalar = |path: &str, v: f64| self.rec.log(path, &rerun::Scalars::single(v));
        scalar("metrics/band/n_in", b.n_in as f64)?;
        scalar("metrics/band/n_out", b.n_out as f64)?;
        scalar("metrics/band/s_in", b.s_in as f64)?;
        scalar("metrics/band/s_out", b.s_out as f64)?;
        scalar("metrics/band/n_move", b.n_move as f64)?;
        scalar("metrics/band/paths", b.paths_applied as f64)?;
        scalar("metrics/band/find_calls", b.find_calls as f64)?;
        scalar("metrics/band/path_ms", b.second_time.as_secs_f64() * 1e3)?;
        scalar(
            &format!("metrics/band/objective/{}", b.variant.name()),
            b.objective,
        )?;
        for (v, o) in &b.other_objectives {
            match o {
                Ok(o) => scalar(&format!("metrics/band/objective/{}", v.name()), *o)?,
                Err(e) => self.rec.log(
                    "log",
                    &rerun::TextLog::new(format!(
                        "step {}: band variant {} failed on this step's problem: {e}",
                        sim.steps,
                        v.name()
                    ))
                    .with_level(rerun::TextLogLevel::WARN),
                )?,
            }
        }
        if let Some(f) = &b.failure {
            self.rec.log(
                "log",
                &rerun::TextLog::new(format!(
                    "step {}: band {}: {f}",
                    sim.steps,
                    b.variant.name()
                ))
                .with_level(rerun::TextLogLevel::WARN),
            )?;
        }
        if !full {
            return Ok(());
        }
        let scale = b.paths.iter().map(|p| p.cost.abs()).fold(0.0, f64::max);
        let colors: Vec<[u8; 3]> = b.paths.iter().map(|p| cost_color(p.cost, scale)).collect();
        let labels: Vec<String> = b.paths.iter().map(|p| format!("{:.3}", p.cost)).collect();
        if D == 2 {
            let ny = self.dims[1] as f32;
            let strips: Vec<Vec<[f32; 2]>> = b
                .paths
                .iter()
                .map(|p| {
                    p.cells
                        .iter()
                        .map(|x| [x[0] as f32, ny - x[1] as f32])
                        .collect()
                })
                .collect();
            self.rec.log(
                "world/corrector/paths",
                &rerun::LineStrips2D::new(strips)
                    .with_colors(colors)
                    .with_labels(labels)
                    .with_radii([0.08f32])
                    .with_draw_order(30.0),
            )
        } else {
            let strips: Vec<Vec<[f32; 3]>> = b
                .paths
                .iter()
                .map(|p| {
                    p.cells
                        .iter()
                        .map(|x| [x[0] as f32, x[1] as f32, x[2] as f32])
                        .collect()
                })
                .collect();
            self.rec.log(
                "world/corrector/paths",
                &rerun::LineStrips3D::new(strips)
                    .with_colors(colors)
                    .with_labels(labels)
                    .with_radii([0.08f32]),
            )
        }
    }

    /// Arrows from `x_hat` to `x` for the particles the correction sent to another cell (an
    /// empty batch clears the previous step's arrows).
    fn log_moves<const D: usize>(
        &self,
        moves: &[(Vector<D>, Vector<D>)],
    ) -> rerun::RecordingStreamResult<()> {
        let color = [[255u8, 80, 200]];
        if D == 2 {
            let ny = self.dims[1] as f32;
            let origins: Vec<[f32; 2]> = moves
                .iter()
                .map(|(a, _)| [a[0] as f32, ny - a[1] as f32])
                .collect();
            let vectors: Vec<[f32; 2]> = moves
                .iter()
                .map(|(a, b)| [(b[0] - a[0]) as f32, (a[1] - b[1]) as f32])
                .collect();
            self.rec.log(
                "world/corrector/moves",
                &rerun::Arrows2D::from_vectors(vectors)
                    .with_origins(origins)
                    .with_colors(color)
                    .with_radii([0.04f32])
                    .with_draw_order(20.0),
            )
        } else {
            let f = |v: &Vector<D>| [v[0] as f32, v[1] as f32, v[2] as f32];
            let origins: Vec<[f32; 3]> = moves.iter().map(|(a, _)| f(a)).collect();
            let vectors: Vec<[f32; 3]> = moves.iter().map(|(a, b)| f(&(b - a))).collect();
            self.rec.log(
                "world/corrector/moves",
                &rerun::Arrows3D::from_vectors(vectors)
                    .with_origins(origins)
                    .with_colors(color)
                    .with_radii([0.05f32]),
            )
        }
    }

    fn text<const D: usize>(&self, sim: &Simulation<D>, level: &'static str, msg: &str) {
        self.set_time(sim);
        let r = self
            .rec
            .log("log", &rerun::TextLog::new(msg).with_level(level));
        self.report(r);
    }

    pub fn warn<const D: usize>(&self, sim: &Simulation<D>, msg: &str) {
        self.text(sim, rerun::TextLogLevel::WARN, msg);
    }

    pub fn error<const D: usize>(&self, sim: &Simulation<D>, msg: &str) {
        self.text(sim, rerun::TextLogLevel::ERROR, msg);
    }

    /// A failed log call is not worth stopping a simulation for; say so once on stderr.
    fn report(&self, r: rerun::RecordingStreamResult<()>) {
        if let Err(e) = r {
            eprintln!("warning: recording: {e}");
        }
    }

    /// Bounds what a crash can lose: everything logged more than two seconds ago is on disk.
    fn flush_now_and_then(&self) {
        if self.last_flush.get().elapsed() > Duration::from_secs(2) {
            if let Err(e) = self.rec.flush_blocking() {
                eprintln!("warning: recording: {e}");
            }
            self.last_flush.set(Instant::now());
        }
    }

    /// Flushes everything and writes the file's footer.
    pub fn finish(self) -> Result<()> {
        self.rec.flush_blocking().map_err(|e| anyhow!("{e}"))?;
        drop(self.rec);
        Ok(())
    }
}
