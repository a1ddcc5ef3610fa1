//! One run drawn in a recording: its particles, cells, obstacles, metrics and what its
//! method reports, at the paths of docs/recordings.md (under a prefix in a comparison,
//! [`Stream`]).

use super::canvas::PointLook;
use super::{Canvas, Drawing, Moves, Plane, Stream};
use crate::draw::legend::{self, speed_color, MarkingClass, NEW_SOLID_COLOR, OBSTACLE_COLOR};
use crate::draw::{Layer, Log};
use crate::frames::{Frame, FrameNeeds, FrameSink};
use crate::grid::Vector;
use crate::metrics::Stage;
use crate::particles::Region;
use crate::scene::Scene;
use crate::step::{Simulation, StepReport};
use std::cell::RefCell;

/// Draws one run, step by step.
pub struct RunLog {
    out: Stream,
    dims: Vec<usize>,
    max_speed: f64,
    drawing: Drawing,
    /// One of several runs in a comparison: no `step` timeline (the runs' steps differ;
    /// `sim_time` is the one timeline) and no 3D slice (the comparison shows worlds only).
    compared: bool,
    /// Every obstacle's centres so far (world coordinates), for its trail.
    trails: RefCell<Vec<Vec<[f32; 3]>>>,
}

impl RunLog {
    pub fn new(out: Stream, scene: &Scene, drawing: Drawing, compared: bool) -> Self {
        Self {
            out,
            dims: scene.dims.clone(),
            max_speed: scene.file.simulation.max_speed / scene.cell_size_m,
            drawing,
            compared,
            trails: RefCell::new(vec![]),
        }
    }

    /// Every obstacle's trail so far (a checkpoint keeps them).
    pub fn trails(&self) -> Vec<Vec<[f32; 3]>> {
        self.trails.borrow().clone()
    }

    /// The trails of a run resumed from a checkpoint.
    pub fn set_trails(&self, trails: Vec<Vec<[f32; 3]>>) {
        *self.trails.borrow_mut() = trails;
    }

    pub(super) fn canvas<const D: usize>(&self, sim: &Simulation<D>) -> Canvas<'_, D> {
        stamp(
            &self.out,
            self.compared,
            sim.state.steps,
            sim.state.time_secs,
        );
        let (axis, at) = self.drawing.slice;
        let slice = (D == 3 && !self.compared).then(|| {
            let layer = ((at * self.dims[axis] as f64) as usize).min(self.dims[axis] - 1);
            Plane::slice(&self.dims, axis, layer)
        });
        Canvas {
            rec: &self.out,
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
                .out
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
        let r = self.out.log_static(
            "log",
            &rerun::TextLog::new(msg).with_level(rerun::TextLogLevel::INFO),
        );
        c.keep(r);
        sim.method.record_setup(&mut c);
        self.report(c.result);
    }

    /// The state after a step (or at the start, step 0, without `rep`): particles, markings
    /// and obstacles when `full`; the metrics (at the start those it has). A failed log call
    /// is reported on stderr; the file's own failures are the [`super::Output`]'s to report.
    pub fn log_step<const D: usize>(
        &self,
        sim: &Simulation<D>,
        rep: Option<&StepReport<D>>,
        full: bool,
    ) {
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
            false => MarkingClass::of(&s.markings, cell, mu) as u8,
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

    /// 3D with the surface drawn: the sink that draws each frame's surface, `world/surface`,
    /// at the frame's step and time, from the frame worker's thread ([`crate::frames`]).
    pub fn surface_sink(&self) -> Option<(FrameSink, FrameNeeds)> {
        if self.dims.len() != 3 || !self.drawing.surface {
            return None;
        }
        let (out, compared) = (self.out.clone(), self.compared);
        let sink = move |f: &Frame| {
            let Some(mesh) = &f.surface else {
                return Ok(());
            };
            stamp(&out, compared, f.step, f.time_secs);
            warn_on_failure(out.log("world/surface", &surface_mesh(mesh)));
            Ok(())
        };
        let needs = FrameNeeds {
            surface: true,
            particles: false,
        };
        Some((Box::new(sink), needs))
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

    /// See [`warn_on_failure`].
    pub(super) fn report(&self, r: rerun::RecordingStreamResult<()>) {
        warn_on_failure(r);
    }
}

/// A failed log call is not worth stopping a simulation for; say so on stderr.
fn warn_on_failure(r: rerun::RecordingStreamResult<()>) {
    if let Err(e) = r {
        eprintln!("warning: recording: {e}");
    }
}

/// Sets the calling thread's times on `out` for what it logs next: `sim_time`, and `step`
/// unless the run is one of a comparison (whose runs' steps differ).
fn stamp(out: &Stream, compared: bool, step: u64, time_secs: f64) {
    if !compared {
        out.rec.set_time_sequence("step", step as i64);
    }
    out.rec.set_duration_secs("sim_time", time_secs);
}

/// A surface mesh in the liquid's colour (grid coordinates are world coordinates in 3D).
fn surface_mesh(mesh: &crate::surface::SurfaceMesh) -> rerun::Mesh3D {
    let [r, g, b] = legend::SURFACE_COLOR;
    rerun::Mesh3D::new(mesh.vertices.iter().copied())
        .with_triangle_indices(mesh.triangles.iter().copied())
        .with_vertex_normals(mesh.normals.iter().copied())
        .with_albedo_factor(rerun::Rgba32::from_unmultiplied_rgba(r, g, b, 255))
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
