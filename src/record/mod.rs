//! Rerun recordings: the only module that imports `rerun`.
//!
//! [`Recorder`] writes a run: its identity (application `cellflip`, a recording name and
//! properties), its default layout ([`layout`]), its legend ([`legend`]) and, step by step, what
//! the [`Canvas`] draws. Entity paths are listed in docs/recordings.md.
//!
//! Methods log their own reports through the drawing vocabulary's [`Log`] trait
//! ([`crate::draw`]), which the [`Canvas`] implements.

mod canvas;
mod file;
pub mod layout;

pub use canvas::{Canvas, Plane};
pub use file::RrdFile;

use crate::draw::legend::{self, speed_color, NEW_SOLID_COLOR, OBSTACLE_COLOR};
use crate::draw::{Layer, Log};
use crate::grid::Vector;
use crate::methods::ccp::BandMode;
use crate::metrics::Stage;
use crate::particles::Region;
use crate::scene::Scene;
use crate::sim::markings::MarkingClass;
use crate::simulation::{Simulation, StepReport};
use anyhow::{anyhow, Result};
use canvas::PointLook;
use layout::RunFacts;
use rerun::blueprint::{Blueprint, Tabs, TimeSeriesView, Vertical};
use rerun::RecordingStream;
use std::cell::{Cell, RefCell};
use std::path::Path;
use std::time::{Duration, Instant};

/// How the correction's moves are drawn (`--moves`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Moves {
    /// From `x_hat` (after advection) to `x` (after the correction): the exact displacement,
    /// often a small fraction of a cell (the moved particles are highlighted).
    #[default]
    Arrows,
    /// From the centre of the cell the particle was advected into to the centre of the cell
    /// the correction put it in: every move at least one cell long.
    Hops,
}

/// How the command line asks a recording to draw.
#[derive(Clone, Copy, Debug, Default)]
pub struct Drawing {
    pub moves: Moves,
    /// 3D: the slice's axis (0, 1, 2) and position as a fraction of the tank along it.
    pub slice: (usize, f64),
}

/// Writes one run to an `.rrd` file.
pub struct Recorder {
    rec: RecordingStream,
    file: RrdFile,
    dims: Vec<usize>,
    max_speed: f64,
    drawing: Drawing,
    last_flush: Cell<Instant>,
    /// Every obstacle's centres so far (world coordinates), for its trail.
    trails: RefCell<Vec<Vec<[f32; 3]>>>,
}

impl Recorder {
    /// Opens `path` for writing ([`RrdFile`]) with the run's identity, layout and scene; fails
    /// (naming the path) before anything is simulated. `cross_check` is `--cross-check`.
    pub fn create(path: &Path, scene: &Scene, cross_check: bool, drawing: Drawing) -> Result<Self> {
        let file = RrdFile::create(path)?;
        let sink: Box<dyn rerun::sink::LogSink> = Box::new(file.clone());
        let cannot = |e| anyhow!("cannot write recording '{}': {e}", path.display());
        let rec = rerun::RecordingStreamBuilder::new("cellflip")
            .recording_name(recording_name(scene))
            .enabled(true)
            .set_sinks(vec![sink])
            .map_err(cannot)?;
        rec.set_log_time_enabled(false);
        let facts = RunFacts {
            dims: scene.dims.clone(),
            method: scene.method.kind.info(),
            band: scene.method.band() != BandMode::None,
            cross_check,
            obstacles: scene.file.obstacle.iter().map(|o| o.name.clone()).collect(),
            slice_axis: drawing.slice.0,
        };
        layout::send(&rec, &layout::layout(&facts)).map_err(cannot)?;
        rec.send_property("run", &run_properties(scene))
            .map_err(cannot)?;
        rec.log_static(
            "scene",
            &rerun::TextDocument::from_markdown(scene_markdown(scene)),
        )
        .map_err(cannot)?;
        let max_speed = scene.file.simulation.max_speed;
        let legend = legend::markdown(max_speed, facts.shows("world/grid/depth"));
        rec.log_static("legend", &rerun::TextDocument::from_markdown(legend))
            .map_err(cannot)?;
        Ok(Self {
            rec,
            file,
            dims: scene.dims.clone(),
            max_speed: max_speed / scene.cell_size_m,
            drawing,
            last_flush: Cell::new(Instant::now()),
            trails: RefCell::new(vec![]),
        })
    }

    fn canvas<const D: usize>(&self, sim: &Simulation<D>) -> Canvas<'_, D> {
        self.rec.set_time_sequence("step", sim.state.steps as i64);
        self.rec.set_duration_secs("sim_time", sim.state.time_secs);
        let (axis, at) = self.drawing.slice;
        let slice = (D == 3).then(|| {
            let layer = ((at * self.dims[axis] as f64) as usize).min(self.dims[axis] - 1);
            Plane::slice(&self.dims, axis, layer)
        });
        Canvas {
            rec: &self.rec,
            dims: std::array::from_fn(|k| self.dims[k]),
            step: sim.state.steps,
            hops: self.drawing.moves == Moves::Hops,
            slice,
            result: Ok(()),
        }
    }

    /// Static data: the class colours, the domain, the view coordinates, the method's layers.
    pub fn log_setup<const D: usize>(&self, sim: &Simulation<D>) {
        let mut c = self.canvas(sim);
        c.classes("world", &legend::marking_classes());
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

    /// The state after a step (or at the start, step 0, without `rep`): particles, markings
    /// and obstacles when `full`; the metrics (at the start those it has).
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
            self.log_particles_and_cells(&mut c, sim);
            self.log_obstacles(&mut c, sim);
        }
        log_state_metrics(&mut c, sim);
        if let Some(rep) = rep {
            log_step_metrics(&mut c, sim, rep);
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

    /// The particles coloured by speed and the cell markings (the band methods' deep as its
    /// own class).
    fn log_particles_and_cells<const D: usize>(&self, c: &mut Canvas<'_, D>, sim: &Simulation<D>) {
        let s = &sim.state;
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
        let class = |cell| match sim.method.is_deep(s, cell) {
            true => legend::DEEP as u8,
            false => s.markings.class(cell, mu) as u8,
        };
        let hidden = [
            MarkingClass::Empty as u8,
            MarkingClass::Inner as u8,
            legend::DEEP as u8,
        ];
        let layer = Layer {
            order: 0.0,
            radius_3d: 0.2,
        };
        c.cell_classes("world/grid/markings", &class, &hidden, layer);
    }

    /// Each obstacle's shape where it is now, and its trail (its centre over the steps).
    fn log_obstacles<const D: usize>(&self, c: &mut Canvas<'_, D>, sim: &Simulation<D>) {
        let mut trails = self.trails.borrow_mut();
        let obstacles = &sim.state.solids.obstacles;
        trails.resize(obstacles.len(), vec![]);
        let color = OBSTACLE_COLOR;
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

/// The scalars the state gives, also at the start (step 0): the volume, the particles, the
/// fastest particle before the first step (after it: the fastest face, from the step's
/// report), and each obstacle's lowest point and speed.
fn log_state_metrics<const D: usize>(c: &mut Canvas<'_, D>, sim: &Simulation<D>) {
    let s = &sim.state;
    let h = s.config.cell_size_m;
    c.scalar("metrics/volume_percent", s.volume_percent());
    c.scalar("metrics/particles", s.particles.len() as f64);
    if s.steps == 0 {
        let fastest = s.particles.vel.iter().map(|v| v.norm()).fold(0.0, f64::max);
        c.scalar("metrics/max_speed", fastest * h);
    }
    for o in &s.solids.obstacles {
        let m = format!("metrics/obstacle/{}", o.name);
        c.scalar(&format!("{m}/height"), o.bottom() * h);
        c.scalar(&format!("{m}/speed"), o.velocity.norm() * h);
    }
}

/// The scalars of a step's report that every method has: the time step, the fastest face,
/// the pressure solve, the stage times, each obstacle's blocked flag.
fn log_step_metrics<const D: usize>(
    c: &mut Canvas<'_, D>,
    sim: &Simulation<D>,
    rep: &StepReport<D>,
) {
    let s = &sim.state;
    let h = s.config.cell_size_m;
    c.scalar("metrics/dt", rep.dt_secs);
    c.scalar("metrics/max_speed", rep.max_speed * h);
    c.scalar("metrics/pcg/iterations", rep.pcg.iterations as f64);
    c.scalar("metrics/pcg/residual", rep.pcg.residual);
    for st in Stage::ALL {
        let ms = rep.times.get(st).as_secs_f64() * 1e3;
        c.scalar(&format!("metrics/time/{}", st.name()), ms);
    }
    for (o, &blocked) in s.solids.obstacles.iter().zip(&rep.blocked) {
        let path = format!("metrics/obstacle/{}/blocked", o.name);
        c.scalar(&path, blocked as u8 as f64);
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
        vec![NEW_SOLID_COLOR],
        look,
    );
}

/// The recording's name in the viewer, [`Scene::run_tags`] (e.g. `dam-3d ccp band-paths r6
/// 50x50x50 ppc8 seed1`), so that runs opened side by side differ.
pub fn recording_name(scene: &Scene) -> String {
    scene.run_tags().join(" ")
}

/// The run's settings as recording properties (`__properties/run`), shown with the
/// recording in the viewer.
fn run_properties(scene: &Scene) -> rerun::AnyValues {
    let cells: Vec<String> = scene.dims.iter().map(usize::to_string).collect();
    let sim = &scene.file.simulation;
    [
        ("scene", scene.name().to_string()),
        ("method", scene.method.kind.name().to_string()),
        ("band", scene.method.band().name().to_string()),
        ("cells", cells.join("x")),
        ("ppc", sim.ppc.to_string()),
        ("seed", sim.seed.to_string()),
        ("version", format!("cellflip {}", env!("CARGO_PKG_VERSION"))),
    ]
    .into_iter()
    .fold(rerun::AnyValues::default(), |v, (key, value)| {
        v.with_component::<rerun::components::Text>(key, [value])
    })
}

/// The `scene` panel: the scene as run.
fn scene_markdown(scene: &Scene) -> String {
    format!(
        "# {}\n\n{}\n\n- source: {}\n- method: {}\n- seed: {}\n- program: cellflip {}\n\n```toml\n{}```\n",
        recording_name(scene),
        scene.file.description,
        scene.source,
        scene.method.kind.name(),
        scene.file.simulation.seed,
        env!("CARGO_PKG_VERSION"),
        scene.resolved_toml()
    )
}

/// One run's time series for the report's comparison recording.
pub struct ComparisonSeries<'a> {
    pub scene: &'a str,
    pub method: &'a str,
    /// The method's line colour (RGB), as in the report's plots.
    pub color: [u8; 3],
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

/// Run `r`'s line colour among `runs`: its method's colour for the coarsest (then lowest-seed)
/// run of that method on its scene, mixed with white up to half way for the others, in order.
fn shade(runs: &[ComparisonSeries<'_>], r: &ComparisonSeries<'_>) -> [u8; 3] {
    let mut same: Vec<(usize, u64)> = (runs.iter())
        .filter(|o| o.scene == r.scene && o.method == r.method)
        .map(|o| (o.res, o.seed))
        .collect();
    same.sort_unstable();
    same.dedup();
    let rank = same.iter().position(|&x| x == (r.res, r.seed)).unwrap_or(0);
    let f = 0.5 * rank as f64 / same.len().saturating_sub(1).max(1) as f64;
    r.color
        .map(|c| (c as f64 + (255.0 - c as f64) * f).round() as u8)
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
            // The method's colour in both panels (the viewer would pick one per path), lighter
            // for each further resolution or seed of the same method and scene.
            let line = rerun::SeriesLines::new().with_colors([shade(runs, r)]);
            rec.log_static(entity.as_str(), &line)?;
            for &(t, v) in series {
                rec.set_duration_secs("sim_time", t);
                rec.log(entity.as_str(), &rerun::Scalars::single(v))?;
            }
        }
    }
    rec.flush_blocking().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A method keeps its colour on every scene; its finer resolutions are lighter, up to half
    /// way to white, and no two runs of one method on one scene share a colour.
    #[test]
    fn comparison_lines_take_their_methods_colour_lighter_per_resolution() {
        let run = |scene, method, res, color| ComparisonSeries {
            scene,
            method,
            color,
            res,
            seed: 1,
            volume: &[],
            ke: &[],
        };
        let (red, blue) = ([200, 20, 40], [30, 110, 180]);
        let runs = [
            run("dam", "ccp", 64, red),
            run("dam", "ccp", 32, red),
            run("dam", "ccp", 16, red),
            run("dam", "flip", 32, blue),
            run("drop", "ccp", 64, red),
        ];
        let c: Vec<[u8; 3]> = runs.iter().map(|r| shade(&runs, r)).collect();
        assert_eq!(c[2], red, "the coarsest run has the method's colour");
        assert_eq!(c[1], [214, 79, 94], "a quarter of the way to white");
        assert_eq!(c[0], [228, 138, 148], "the finest run half way to white");
        assert_eq!(
            (c[3], c[4]),
            (blue, red),
            "alone on its scene: the method's colour"
        );
    }
}
