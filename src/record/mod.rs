//! Rerun recordings: the only module that imports `rerun`.
//!
//! World units are cells. In 2D the world is drawn as an image (x right, rows down), so
//! positions are logged as `(x, ny - y)`: gravity points down the screen and each particle lies
//! over its cell of the `world/grid/markings` image. That conversion happens in one place,
//! [`Canvas::world`]; every drawing goes through the canvas's point, box, arrow, strip and
//! class-layer helpers, which pick the 2D or 3D archetype. In 3D, y is up
//! (`RIGHT_HAND_Y_UP`). Entity paths are listed in the README.
//!
//! Methods log their own reports through the [`Log`] trait, which names no rerun type.

mod file;

pub use file::RrdFile;

use crate::grid::Vector;
use crate::methods::MethodInfo;
use crate::metrics::Stage;
use crate::particles::Region;
use crate::scene::Scene;
use crate::sim::markings::{DepthLevel, MarkingClass};
use crate::sim::{Simulation, StepReport};
use anyhow::{anyhow, Result};
use rerun::blueprint::{
    Blueprint, Horizontal, Spatial2DView, Spatial3DView, Tabs, TextDocumentView, TextLogView,
    TimeSeriesView, Vertical,
};
use rerun::RecordingStream;
use std::cell::{Cell, RefCell};
use std::path::Path;
use std::time::{Duration, Instant};

/// What a method may log and draw, in grid units; implemented by the recorder's [`Canvas`].
pub trait Log<const D: usize> {
    /// A scalar time series, every step.
    fn scalar(&mut self, path: &str, value: f64);
    /// A warning in the log, prefixed with the step.
    fn warn(&mut self, message: &str);
    /// Class ids with their labels and colours (RGBA) for `path` and below, logged once.
    fn classes(&mut self, path: &str, classes: &[(u16, &'static str, [u8; 4])]);
    /// One class id per cell: in 2D an image over the grid, in 3D points at the centres of the
    /// cells whose class is not in `hidden_3d`.
    fn cell_classes(
        &mut self,
        path: &str,
        class: &dyn Fn(usize) -> u8,
        hidden_3d: &[u8],
        layer: Layer,
    );
    /// A `[width, height]` image of values in `range`, row 0 at the bottom (grid order), drawn
    /// with a colour map in its own 2D view ([`crate::methods::MethodInfo::images`]).
    fn image(&mut self, path: &str, size: [usize; 2], values: &[f32], range: [f32; 2]);
    /// Arrows from the first point to the second of each pair (an empty batch clears).
    fn arrows(&mut self, path: &str, from_to: &[(Vector<D>, Vector<D>)], style: Style);
    /// Line strips through points, each with its colour and label (an empty batch clears).
    fn strips(
        &mut self,
        path: &str,
        strips: &[Vec<Vector<D>>],
        colors: &[[u8; 3]],
        labels: Vec<String>,
        style: Style,
    );
}

/// How a drawing looks: its colour, radius (cells) and, in 2D, its draw order.
#[derive(Clone, Copy, Debug)]
pub struct Style {
    pub color: [u8; 3],
    pub radius: f32,
    pub order: f32,
}

/// How a layer of cells is drawn: its draw order in 2D, its points' radius in 3D (cells).
#[derive(Clone, Copy, Debug)]
pub struct Layer {
    pub order: f32,
    pub radius_3d: f32,
}

/// The band levels (sec. band_method) as classes: label and colour of each [`DepthLevel`].
pub fn depth_level_classes() -> Vec<(u16, &'static str, [u8; 4])> {
    DepthLevel::ALL
        .iter()
        .map(|l| {
            let rgba = match l {
                DepthLevel::NotFluid => [0, 0, 0, 0],
                DepthLevel::Surface => [60, 180, 75, 120],
                DepthLevel::Band => [120, 190, 240, 110],
                DepthLevel::Interface => [240, 200, 40, 170],
                DepthLevel::Deep => [20, 40, 120, 140],
            };
            (*l as u16, l.label(), rgba)
        })
        .collect()
}

fn class_color(c: MarkingClass) -> [u8; 4] {
    match c {
        MarkingClass::Empty => [0, 0, 0, 0],
        MarkingClass::Surface => [60, 180, 75, 140],
        MarkingClass::Inner => [30, 70, 160, 110],
        MarkingClass::Bubble => [230, 50, 50, 160],
        MarkingClass::Solid => [128, 128, 128, 255],
    }
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

fn rgba(c: [u8; 4]) -> rerun::Rgba32 {
    rerun::Rgba32::from_unmultiplied_rgba(c[0], c[1], c[2], c[3])
}

/// The world view on the left; on the right the volume, stage times, the pressure solve, the
/// method's own panels, the log and the scene.
fn blueprint(dim: usize, info: &MethodInfo) -> Blueprint {
    let mut world: rerun::blueprint::ContainerLike = if dim == 2 {
        Spatial2DView::new("world").with_origin("world").into()
    } else {
        Spatial3DView::new("world").with_origin("world").into()
    };
    if !info.images.is_empty() {
        let mut left = vec![world];
        left.extend(info.images.iter().map(|&(name, origin)| {
            rerun::blueprint::ContainerLike::from(Spatial2DView::new(name).with_origin(origin))
        }));
        let mut shares = vec![2.0];
        shares.extend(info.images.iter().map(|_| 1.0));
        world = Vertical::new(left).with_row_shares(shares).into();
    }
    let method_panels = info.panels;
    let series = |name: &str, origin: &str| TimeSeriesView::new(name).with_origin(origin).into();
    let mut right: Vec<rerun::blueprint::ContainerLike> = vec![
        series("volume %", "metrics/volume_percent"),
        series("stage times (ms)", "metrics/time"),
        series("pressure solve", "metrics/pcg"),
    ];
    right.extend(
        method_panels
            .iter()
            .map(|(name, origin)| series(name, origin)),
    );
    right.push(TextLogView::new("log").with_origin("log").into());
    right.push(TextDocumentView::new("scene").with_origin("scene").into());
    Blueprint::new(
        Horizontal::new([world, Vertical::new(right).into()]).with_column_shares([2.0, 1.0]),
    )
}

/// Writes one run to an `.rrd` file.
pub struct Recorder {
    rec: RecordingStream,
    file: RrdFile,
    dims: Vec<usize>,
    max_speed: f64,
    last_flush: Cell<Instant>,
    /// Every obstacle's centres so far (world coordinates), for its trail.
    trails: RefCell<Vec<Vec<[f32; 3]>>>,
}

impl Recorder {
    /// Opens `path` for writing ([`RrdFile`]); fails (naming the path) before anything is
    /// simulated.
    pub fn create(path: &Path, scene: &Scene) -> Result<Self> {
        let file = RrdFile::create(path)?;
        let sink: Box<dyn rerun::sink::LogSink> = Box::new(file.clone());
        let rec = rerun::RecordingStreamBuilder::new("cellflip")
            .recording_name(scene.name())
            .enabled(true)
            .send_properties(false)
            .with_blueprint(blueprint(scene.dim(), scene.method.kind.info()))
            .set_sinks(vec![sink])
            .map_err(|e| anyhow!("cannot write recording '{}': {e}", path.display()))?;
        rec.set_log_time_enabled(false);
        let header = format!(
            "# {}\n\n{}\n\n- source: {}\n- method: {}\n- seed: {}\n- program: cellflip {}\n\n```toml\n{}```\n",
            scene.name(),
            scene.file.description,
            scene.source,
            scene.method.kind.name(),
            scene.file.simulation.seed,
            env!("CARGO_PKG_VERSION"),
            scene.resolved_toml()
        );
        rec.log_static("scene", &rerun::TextDocument::from_markdown(header))?;
        Ok(Self {
            rec,
            file,
            dims: scene.dims.clone(),
            max_speed: scene.file.simulation.max_speed / scene.cell_size_m,
            last_flush: Cell::new(Instant::now()),
            trails: RefCell::new(vec![]),
        })
    }

    fn canvas<const D: usize>(&self, sim: &Simulation<D>) -> Canvas<'_, D> {
        self.rec.set_time_sequence("step", sim.state.steps as i64);
        self.rec.set_duration_secs("sim_time", sim.state.time_secs);
        Canvas {
            rec: &self.rec,
            ny: self.dims[1] as f32,
            dims: std::array::from_fn(|k| self.dims[k]),
            step: sim.state.steps,
            result: Ok(()),
        }
    }

    /// Static data: the class colours, the domain, the view coordinates, the method's layers.
    pub fn log_setup<const D: usize>(&self, sim: &Simulation<D>) {
        let mut c = self.canvas(sim);
        let classes: Vec<(u16, &str, [u8; 4])> = MarkingClass::ALL
            .iter()
            .map(|k| (*k as u16, k.label(), class_color(*k)))
            .collect();
        c.classes("world", &classes);
        if D == 3 {
            let r = self
                .rec
                .log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Y_UP());
            c.keep(r);
        }
        let d = sim.state.grid.dims;
        c.boxes(
            "world/domain",
            &Vector::<D>::zeros(),
            &Vector::<D>::from_fn(|k, _| d[k] as f64),
            [200, 200, 200],
            true,
        );
        let s = &sim.state;
        let msg = format!(
            "{} particles on {:?} cells, mu = {}",
            s.particles.len(),
            d,
            s.config.mu()
        );
        let r = self.rec.log_static(
            "log",
            &rerun::TextLog::new(msg).with_level(rerun::TextLogLevel::INFO),
        );
        c.keep(r);
        sim.method.record_setup(&mut c);
        self.report(c.result);
    }

    /// The state after a step: particles, markings and obstacles when `full`, metrics when
    /// `rep` is given.
    ///
    /// Fails when the file cannot be written (checked every step, flushed every two seconds);
    /// the first step recorded gives the file its name.
    pub fn log_step<const D: usize>(
        &self,
        sim: &Simulation<D>,
        rep: Option<&StepReport<D>>,
        full: bool,
    ) -> Result<()> {
        let mut c = self.canvas(sim);
        let s = &sim.state;
        if full {
            let colors = s
                .particles
                .vel
                .iter()
                .map(|v| speed_color(v.norm(), self.max_speed))
                .collect();
            let look = PointLook {
                radius: if D == 2 { 0.12 } else { 0.15 },
                order: 10.0,
                labels: None,
            };
            c.points("world/particles", &s.particles.pos, colors, look);
            let mu = s.config.mu();
            let hidden = [MarkingClass::Empty as u8, MarkingClass::Inner as u8];
            c.cell_classes(
                "world/grid/markings",
                &|cell| s.markings.class(cell, mu) as u8,
                &hidden,
                Layer {
                    order: 0.0,
                    radius_3d: 0.3,
                },
            );
            self.log_obstacles(&mut c, sim);
        }
        if let Some(rep) = rep {
            log_metrics(&mut c, sim, rep);
            if full && !s.solids.obstacles.is_empty() {
                log_new_solid(&mut c, sim, &rep.new_solid);
            }
            rep.method.record(s, &mut c, full);
        }
        self.report(c.result);
        self.flush_now_and_then();
        if rep.is_some() {
            self.file.commit()?;
        }
        self.file.check()
    }

    /// Each obstacle's shape where it is now, and its trail (its centre over the steps).
    fn log_obstacles<const D: usize>(&self, c: &mut Canvas<'_, D>, sim: &Simulation<D>) {
        let mut trails = self.trails.borrow_mut();
        let obstacles = &sim.state.solids.obstacles;
        trails.resize(obstacles.len(), vec![]);
        let color = [230u8, 90, 40];
        for (o, trail) in obstacles.iter().zip(trails.iter_mut()) {
            let path = format!("world/obstacles/{}", o.name);
            let r = o.region_at(&o.offset);
            match &r {
                Region::Ball { center, radius } => {
                    let look = PointLook {
                        radius: *radius as f32,
                        order: 25.0,
                        labels: None,
                    };
                    c.points(&path, &[*center], vec![color], look)
                }
                _ => {
                    let (lo, hi) = r.bounds();
                    c.boxes(&path, &lo, &hi, color, false)
                }
            }
            trail.push(c.world(&r.center()));
            c.strip_world(&format!("{path}/trail"), trail, color);
        }
    }

    pub fn warn<const D: usize>(&self, sim: &Simulation<D>, msg: &str) {
        self.text(sim, rerun::TextLogLevel::WARN, msg);
    }

    pub fn error<const D: usize>(&self, sim: &Simulation<D>, msg: &str) {
        self.text(sim, rerun::TextLogLevel::ERROR, msg);
    }

    fn text<const D: usize>(&self, sim: &Simulation<D>, level: &'static str, msg: &str) {
        let mut c = self.canvas(sim);
        c.text(msg, level);
        self.report(c.result);
    }

    /// A failed log call is not worth stopping a simulation for; say so on stderr.
    fn report(&self, r: rerun::RecordingStreamResult<()>) {
        if let Err(e) = r {
            eprintln!("warning: recording: {e}");
        }
    }

    /// Bounds what a crash can lose: everything logged more than two seconds ago is on disk.
    /// A failed write shows in the file's [`RrdFile::check`].
    fn flush_now_and_then(&self) {
        if self.last_flush.get().elapsed() > Duration::from_secs(2) {
            let _ = self.rec.flush_blocking();
            self.last_flush.set(Instant::now());
        }
    }

    /// Flushes everything and writes the file's footer; the file takes its name even if no
    /// step was recorded (an interrupted run).
    pub fn finish(self) -> Result<()> {
        let _ = self.rec.flush_blocking();
        self.file.commit()?;
        self.file.finish()
    }

    /// After a run that failed (the run's error says why; a failure to finish adds nothing):
    /// the recording is finished as far as it goes, or removed if it never took its name (no
    /// step was recorded).
    pub fn abandon(self) {
        let _ = self.rec.flush_blocking();
        let _ = self.file.finish();
        self.file.discard();
    }

    /// A closure that finishes the recording from another thread with what was logged so far
    /// (the signal watchdog: a step that does not end in time is not waited for).
    pub fn finisher(&self) -> impl FnOnce() -> Result<()> + Send + 'static {
        let (rec, file) = (self.rec.clone(), self.file.clone());
        move || {
            let _ = rec.flush_blocking();
            file.commit()?;
            file.finish()
        }
    }
}

/// The scalars every method has, and each obstacle's.
fn log_metrics<const D: usize>(c: &mut Canvas<'_, D>, sim: &Simulation<D>, rep: &StepReport<D>) {
    let s = &sim.state;
    let h = s.config.cell_size_m;
    c.scalar("metrics/volume_percent", rep.volume_percent);
    c.scalar("metrics/particles", s.particles.len() as f64);
    c.scalar("metrics/dt", rep.dt_secs);
    c.scalar("metrics/max_speed", rep.max_speed * h);
    c.scalar("metrics/pcg/iterations", rep.pcg.iterations as f64);
    c.scalar("metrics/pcg/residual", rep.pcg.residual);
    for st in Stage::ALL {
        let ms = rep.times.get(st).as_secs_f64() * 1e3;
        c.scalar(&format!("metrics/time/{}", st.name()), ms);
    }
    for (o, &blocked) in s.solids.obstacles.iter().zip(&rep.blocked) {
        let m = format!("metrics/obstacle/{}", o.name);
        c.scalar(&format!("{m}/height"), o.bottom() * h);
        c.scalar(&format!("{m}/speed"), o.velocity.norm() * h);
        c.scalar(&format!("{m}/blocked"), blocked as u8 as f64);
    }
    if rep.dt_shortened {
        let msg = format!(
            "step {}: time step shortened to {:.3e} s after the projection (max speed {:.3} m/s)",
            s.steps,
            rep.dt_secs,
            rep.max_speed * h
        );
        c.text(&msg, rerun::TextLogLevel::DEBUG);
    }
}

/// The cells obstacles wanted this step (`C_new_solid`), labelled with their clearing
/// distance (an empty batch clears the previous step's).
fn log_new_solid<const D: usize>(
    c: &mut Canvas<'_, D>,
    sim: &Simulation<D>,
    cells: &[(usize, u32)],
) {
    let g = &sim.state.grid;
    let centres: Vec<Vector<D>> = cells
        .iter()
        .map(|(k, _)| g.center(g.cell_coords(*k)))
        .collect();
    let labels = cells.iter().map(|(_, d)| d.to_string()).collect();
    let look = PointLook {
        radius: 0.3,
        order: 26.0,
        labels: Some(labels),
    };
    c.points(
        "world/obstacles/new_solid",
        &centres,
        vec![[255, 200, 0]],
        look,
    );
}

/// How points look: radius (cells), draw order in 2D, labels.
struct PointLook {
    radius: f32,
    order: f32,
    labels: Option<Vec<String>>,
}

/// Draws on the recording at one step, in 2D or 3D; keeps the first error.
pub struct Canvas<'a, const D: usize> {
    rec: &'a RecordingStream,
    dims: [usize; D],
    ny: f32,
    step: u64,
    result: rerun::RecordingStreamResult<()>,
}

impl<const D: usize> Canvas<'_, D> {
    fn keep(&mut self, r: rerun::RecordingStreamResult<()>) {
        if self.result.is_ok() {
            self.result = r;
        }
    }

    /// World coordinates of a point in cells: in 2D rows down, `(x, ny - y, 0)`.
    fn world(&self, x: &Vector<D>) -> [f32; 3] {
        if D == 2 {
            [x[0] as f32, self.ny - x[1] as f32, 0.0]
        } else {
            [x[0] as f32, x[1] as f32, x[2] as f32]
        }
    }

    fn world_all(&self, xs: &[Vector<D>]) -> Vec<[f32; 3]> {
        xs.iter().map(|x| self.world(x)).collect()
    }

    fn text(&mut self, msg: &str, level: &'static str) {
        let r = self
            .rec
            .log("log", &rerun::TextLog::new(msg).with_level(level));
        self.keep(r);
    }

    /// Points with one colour each (or one for all), one radius, and labels if given.
    fn points(&mut self, path: &str, xs: &[Vector<D>], colors: Vec<[u8; 3]>, look: PointLook) {
        let p = self.world_all(xs);
        let r = if D == 2 {
            let p2 = p.iter().map(|p| [p[0], p[1]]);
            let mut pts = rerun::Points2D::new(p2)
                .with_colors(colors)
                .with_radii([look.radius])
                .with_draw_order(look.order);
            if let Some(l) = look.labels {
                pts = pts.with_labels(l);
            }
            self.rec.log(path, &pts)
        } else {
            let mut pts = rerun::Points3D::new(p)
                .with_colors(colors)
                .with_radii([look.radius]);
            if let Some(l) = look.labels {
                pts = pts.with_labels(l);
            }
            self.rec.log(path, &pts)
        };
        self.keep(r);
    }

    /// An axis-aligned box from `lo` to `hi` (cells): the tank (`domain`: static, 3D as a
    /// wireframe, under everything in 2D) or an obstacle (per step, over the particles).
    fn boxes(&mut self, path: &str, lo: &Vector<D>, hi: &Vector<D>, color: [u8; 3], domain: bool) {
        let (a, b) = (self.world(lo), self.world(hi));
        let centre: [f32; 3] = std::array::from_fn(|k| (a[k] + b[k]) / 2.0);
        let half: [f32; 3] = std::array::from_fn(|k| (b[k] - a[k]).abs() / 2.0);
        let r = match (D, domain) {
            (2, _) => {
                let b = rerun::Boxes2D::from_centers_and_half_sizes(
                    [(centre[0], centre[1])],
                    [(half[0], half[1])],
                )
                .with_colors([color]);
                if domain {
                    self.rec.log_static(path, &b)
                } else {
                    self.rec.log(path, &b.with_draw_order(25.0))
                }
            }
            (_, true) => {
                let b = rerun::Boxes3D::from_centers_and_half_sizes([centre], [half])
                    .with_colors([color])
                    .with_fill_mode(rerun::FillMode::MajorWireframe);
                self.rec.log_static(path, &b)
            }
            _ => {
                let b = rerun::Boxes3D::from_centers_and_half_sizes([centre], [half]);
                self.rec.log(path, &b.with_colors([color]))
            }
        };
        self.keep(r);
    }

    /// One line strip through world points.
    fn strip_world(&mut self, path: &str, pts: &[[f32; 3]], color: [u8; 3]) {
        let r = if D == 2 {
            let strip: Vec<[f32; 2]> = pts.iter().map(|p| [p[0], p[1]]).collect();
            let s = rerun::LineStrips2D::new([strip]).with_colors([color]);
            self.rec.log(path, &s.with_draw_order(24.0))
        } else {
            let s = rerun::LineStrips3D::new([pts.to_vec()]).with_colors([color]);
            self.rec.log(path, &s)
        };
        self.keep(r);
    }
}

impl<const D: usize> Log<D> for Canvas<'_, D> {
    fn scalar(&mut self, path: &str, value: f64) {
        let r = self.rec.log(path, &rerun::Scalars::single(value));
        self.keep(r);
    }

    fn warn(&mut self, message: &str) {
        let msg = format!("step {}: {message}", self.step);
        self.text(&msg, rerun::TextLogLevel::WARN);
    }

    fn classes(&mut self, path: &str, classes: &[(u16, &'static str, [u8; 4])]) {
        let c: Vec<(u16, &str, rerun::Rgba32)> = classes
            .iter()
            .map(|(id, l, c)| (*id, *l, rgba(*c)))
            .collect();
        let r = self.rec.log_static(path, &rerun::AnnotationContext::new(c));
        self.keep(r);
    }

    fn cell_classes(
        &mut self,
        path: &str,
        class: &dyn Fn(usize) -> u8,
        hidden_3d: &[u8],
        layer: Layer,
    ) {
        let n: usize = self.dims.iter().product();
        let r = if D == 2 {
            // Cell index c = x + w y (axis 0 fastest); image row 0 is the top.
            let (w, h) = (self.dims[0], self.dims[1]);
            let mut img = vec![0u8; n];
            for c in 0..n {
                img[(h - 1 - c / w) * w + c % w] = class(c);
            }
            let format =
                rerun::ImageFormat::segmentation([w as u32, h as u32], rerun::ChannelDatatype::U8);
            let image = rerun::SegmentationImage::new(img, format).with_draw_order(layer.order);
            self.rec.log(path, &image)
        } else {
            let grid = crate::grid::Grid::new(self.dims);
            let (centres, ids): (Vec<[f32; 3]>, Vec<rerun::components::ClassId>) = (0..n)
                .map(|c| (c, class(c)))
                .filter(|(_, k)| !hidden_3d.contains(k))
                .map(|(c, k)| {
                    (
                        self.world(&grid.center(grid.cell_coords(c))),
                        rerun::components::ClassId::from(k as u16),
                    )
                })
                .unzip();
            let pts = rerun::Points3D::new(centres).with_class_ids(ids);
            let pts = pts.with_radii([layer.radius_3d]);
            self.rec.log(path, &pts)
        };
        self.keep(r);
    }

    fn image(&mut self, path: &str, [w, h]: [usize; 2], values: &[f32], range: [f32; 2]) {
        // Image row 0 is the top.
        let mut bytes = Vec::with_capacity(4 * w * h);
        for row in (0..h).rev() {
            for v in &values[row * w..(row + 1) * w] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        let format = rerun::ImageFormat::depth([w as u32, h as u32], rerun::ChannelDatatype::F32);
        let image = rerun::DepthImage::new(bytes, format)
            .with_colormap(rerun::components::Colormap::Viridis)
            .with_depth_range([range[0] as f64, range[1] as f64]);
        let r = self.rec.log(path, &image);
        self.keep(r);
    }

    fn arrows(&mut self, path: &str, from_to: &[(Vector<D>, Vector<D>)], style: Style) {
        let origins: Vec<[f32; 3]> = from_to.iter().map(|(a, _)| self.world(a)).collect();
        let vectors: Vec<[f32; 3]> = from_to
            .iter()
            .zip(&origins)
            .map(|((_, b), o)| {
                let w = self.world(b);
                std::array::from_fn(|k| w[k] - o[k])
            })
            .collect();
        let r = if D == 2 {
            let two = |v: &[[f32; 3]]| v.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>();
            let a = rerun::Arrows2D::from_vectors(two(&vectors)).with_origins(two(&origins));
            let a = a.with_colors([style.color]).with_radii([style.radius]);
            self.rec.log(path, &a.with_draw_order(style.order))
        } else {
            let a = rerun::Arrows3D::from_vectors(vectors).with_origins(origins);
            self.rec.log(
                path,
                &a.with_colors([style.color]).with_radii([style.radius]),
            )
        };
        self.keep(r);
    }

    fn strips(
        &mut self,
        path: &str,
        strips: &[Vec<Vector<D>>],
        colors: &[[u8; 3]],
        labels: Vec<String>,
        style: Style,
    ) {
        let world: Vec<Vec<[f32; 3]>> = strips.iter().map(|s| self.world_all(s)).collect();
        let r = if D == 2 {
            let two: Vec<Vec<[f32; 2]>> = world
                .iter()
                .map(|s| s.iter().map(|p| [p[0], p[1]]).collect())
                .collect();
            let l = rerun::LineStrips2D::new(two)
                .with_colors(colors.to_vec())
                .with_labels(labels);
            self.rec.log(
                path,
                &l.with_radii([style.radius]).with_draw_order(style.order),
            )
        } else {
            let l = rerun::LineStrips3D::new(world)
                .with_colors(colors.to_vec())
                .with_labels(labels);
            self.rec.log(path, &l.with_radii([style.radius]))
        };
        self.keep(r);
    }
}

/// One run's time series for the report's comparison recording.
pub struct ComparisonSeries<'a> {
    pub scene: &'a str,
    pub method: &'a str,
    pub res: usize,
    pub seed: u64,
    /// `(simulated seconds, V/V* %)` and `(simulated seconds, kinetic energy per unit mass)`.
    pub volume: &'a [(f64, f64)],
    pub ke: &'a [(f64, f64)],
}

/// Entity-path part of a scene label.
fn path_part(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `cellflip report`'s recording: every run's volume and kinetic energy on the `sim_time`
/// timeline, under `volume/<scene>/<method>/<cells>` and
/// `kinetic_energy/<scene>/<method>/<cells>` (`_s<seed>` appended when a scene runs with
/// several seeds), with one tab per scene comparing the methods.
pub fn write_comparison(path: &Path, runs: &[ComparisonSeries<'_>]) -> Result<()> {
    let mut scenes: Vec<String> = vec![];
    for r in runs {
        let s = path_part(r.scene);
        if !scenes.contains(&s) {
            scenes.push(s);
        }
    }
    // One tab per scene: its volume above its kinetic energy, every run a line.
    let panel = |what: &str, s: &String| -> rerun::blueprint::ContainerLike {
        TimeSeriesView::new(format!("{s}: {what}"))
            .with_origin(format!("{what}/{s}"))
            .into()
    };
    let tabs = scenes.iter().map(|s| {
        Vertical::new([panel("volume", s), panel("kinetic_energy", s)])
            .with_name(s.clone())
            .into()
    });
    let blueprint = Blueprint::new(Tabs::new(tabs));
    let rec = rerun::RecordingStreamBuilder::new("cellflip")
        .recording_name("cellflip report")
        .send_properties(false)
        .with_blueprint(blueprint)
        .save(path)?;
    rec.set_log_time_enabled(false);
    let several_seeds = |r: &ComparisonSeries<'_>| {
        runs.iter().any(|o| {
            o.scene == r.scene && o.method == r.method && o.res == r.res && o.seed != r.seed
        })
    };
    for r in runs {
        let mut leaf = format!("{}/{}/{}", path_part(r.scene), r.method, r.res);
        if several_seeds(r) {
            leaf += &format!("_s{}", r.seed);
        }
        for (what, series) in [("volume", r.volume), ("kinetic_energy", r.ke)] {
            let entity = format!("{what}/{leaf}");
            for &(t, v) in series {
                rec.set_duration_secs("sim_time", t);
                rec.log(entity.as_str(), &rerun::Scalars::single(v))?;
            }
        }
    }
    rec.flush_blocking().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}
