//! One time step of the fluid methods, generic over the dimension (paper alg. flip).
//!
//! Step order: emit -> particles to grid (+ extrapolation) -> gravity and solid boundary ->
//! pressure projection -> extrapolation and speed limit -> time step check -> grid to particles
//! (FLIP/PIC blend) -> advection -> correction (method-specific) -> markings and volume.
//!
//! Method `ccp` with a band (alg. band) adds: particle velocities only in the band, combined
//! with the grid velocity elsewhere; semi-Lagrangian advection of the grid velocity; the band
//! correction; and the exchange of particles with the deep after the markings.

pub mod advect;
pub mod band;
pub mod correct;
pub mod emit;
pub mod markings;
pub mod pressure;
pub mod solids;
pub mod transfer;

use crate::grid::{Grid, MacField, Vector};
use crate::metrics::{self, InvariantViolation, Stage, StageTimes};
use crate::particles::{self, Particles, Region};
use crate::solvers::pcg::{PcgSettings, PcgStats};
use band::{BandSettings, DeepExchange};
use correct::band::BandContext;
use correct::{CorrectionReport, CorrectionSettings};
use emit::Emitter;
use markings::{DepthLevel, Markings};
use rand::rngs::StdRng;
use rand::SeedableRng;
use solids::{Obstacle, ObstacleMode};

/// The fluid methods a scene can run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// PIC/FLIP with no position correction (Zhu and Bridson 2005).
    Flip,
    /// Cell-constrained particles: FLIP plus the paper's correction step (sec. 4-5).
    Ccp,
}

impl Method {
    pub const ALL: [Method; 2] = [Method::Flip, Method::Ccp];

    pub fn name(self) -> &'static str {
        match self {
            Method::Flip => "flip",
            Method::Ccp => "ccp",
        }
    }
}

/// Everything a simulation needs, in grid units (cells, seconds, cells per second).
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig<const D: usize> {
    pub dims: [usize; D],
    /// Cell size in metres (only to report results in SI).
    pub cell_size_m: f64,
    pub method: Method,
    /// Particles per cell along each axis, `k`; `mu = k^D`.
    pub per_axis: usize,
    /// Seeding jitter as a fraction of the sub-cell spacing, in [0, 0.5).
    pub jitter: f64,
    /// Gravity, cells per second squared.
    pub gravity: Vector<D>,
    /// Weight of the FLIP update in the FLIP/PIC blend (1 = pure FLIP, 0 = PIC).
    pub flip_ratio: f64,
    /// Largest motion per step, in cells (at most 1, sec. grid_move).
    pub cfl: f64,
    pub max_dt_secs: f64,
    /// Bound on each face velocity component, cells per second.
    pub max_speed: f64,
    /// Relative max-norm tolerance of the pressure solve.
    pub pressure_tolerance: f64,
    pub seed: u64,
    pub fluid: Vec<Region<D>>,
    pub solids: Vec<Region<D>>,
    pub emitters: Vec<Emitter<D>>,
    /// Solver and directions of the correction step (method `ccp`).
    pub correction: CorrectionSettings,
    /// The band method (method `ccp` only; ignored by the others).
    pub band: Option<BandSettings>,
    /// Moving obstacles (sec. 7) and how the method lets them through particles.
    pub obstacles: Vec<Obstacle<D>>,
    pub obstacle_mode: ObstacleMode,
}

impl<const D: usize> SimConfig<D> {
    pub fn mu(&self) -> u32 {
        self.per_axis.pow(D as u32) as u32
    }
}

/// What one step did.
#[derive(Clone, Debug, Default)]
pub struct StepReport<const D: usize> {
    pub dt_secs: f64,
    /// The step had to be shortened after the projection to keep motion within `cfl` cells.
    pub dt_shortened: bool,
    pub times: StageTimes,
    pub pcg: PcgStats,
    /// Largest face velocity component after the projection, cells per second.
    pub max_speed: f64,
    pub emitted: usize,
    pub volume_percent: f64,
    /// The correction step, for methods that have one.
    pub correction: Option<CorrectionReport<D>>,
    /// The exchange with the deep, with the band method.
    pub deep: Option<DeepExchange>,
    /// Per obstacle: whether it had to stay this step.
    pub blocked: Vec<bool>,
    /// The cells obstacles wanted this step (`C_new_solid`) with their clearing distance.
    pub new_solid: Vec<(usize, u32)>,
}

/// The state of a running simulation.
pub struct Simulation<const D: usize> {
    pub config: SimConfig<D>,
    pub grid: Grid<D>,
    pub particles: Particles<D>,
    /// Grid velocity after the last projection, cells per second.
    pub velocity: MacField<D>,
    /// Solid cells: the static solids and the obstacles where they are now.
    pub solid: Vec<bool>,
    /// Velocity of each solid cell (zero for walls and static solids).
    pub solid_vel: Vec<Vector<D>>,
    /// Cells of moving obstacles (their fluid neighbours are surface).
    pub moving: Vec<bool>,
    /// The obstacles, at their current offsets.
    pub obstacles: Vec<Obstacle<D>>,
    static_solid: Vec<bool>,
    pub markings: Markings,
    pub time_secs: f64,
    pub steps: u64,
    /// Write the correction problem of this step as MPS into its report.
    pub export_problem_at_step: Option<u64>,
    /// Particles seeded at the start plus all emitted since.
    pub total_particles: usize,
    /// `V*`: initial volume plus emitted volume, in cells.
    pub target_volume: f64,
    /// `n_deep`: imaginary particles of the band method's deep (0 without the band).
    pub n_deep: usize,
    rng: StdRng,
}

impl<const D: usize> Simulation<D> {
    pub fn new(config: SimConfig<D>) -> Self {
        let grid = Grid::new(config.dims);
        let n = grid.num_cells();
        let mut static_solid = vec![false; n];
        for r in &config.solids {
            r.cells(&grid).for_each(|c| static_solid[c] = true);
        }
        let obstacles = config.obstacles.clone();
        let (solid, solid_vel, moving) = rasterise(&grid, &static_solid, &obstacles);
        let mut rng = StdRng::seed_from_u64(config.seed);
        let particles = particles::seed(
            &grid,
            &config.fluid,
            &solid,
            config.per_axis,
            config.jitter,
            &mut rng,
        );
        let markings = Markings::compute_keeping(
            &grid,
            &particles.pos,
            &solid,
            None,
            (!config.obstacles.is_empty()).then_some(&moving[..]),
        );
        let total = particles.len();
        let mut sim = Self {
            target_volume: total as f64 / config.mu() as f64,
            velocity: MacField::zeros(&grid),
            solid_vel,
            moving,
            obstacles,
            static_solid,
            markings,
            time_secs: 0.0,
            steps: 0,
            export_problem_at_step: None,
            total_particles: total,
            grid,
            particles,
            solid,
            config,
            rng,
            n_deep: 0,
        };
        if let Some(b) = sim.band() {
            band::exchange_with_deep(
                &sim.grid,
                &mut sim.particles,
                &mut sim.markings,
                None,
                b.r,
                sim.config.mu(),
                &mut sim.n_deep,
                &sim.velocity,
                &mut sim.rng,
            );
        }
        sim
    }

    /// The band, when the method uses one.
    pub fn band(&self) -> Option<BandSettings> {
        self.config
            .band
            .filter(|_| self.config.method == Method::Ccp)
    }

    /// Markings of the current positions. With the band, fluid cells below the surface stay
    /// fluid without particles ([`band::kept_cells`]), and then particles are exchanged with
    /// the deep (alg. band, line 9).
    fn refresh_markings(&mut self) -> Option<DeepExchange> {
        let band = self.band();
        let was_low = band.map(|b| band::at_or_below_interface(&self.markings, b.r));
        let keep = band.map(|_| band::kept_cells(&self.markings));
        self.markings = Markings::compute_keeping(
            &self.grid,
            &self.particles.pos,
            &self.solid,
            keep.as_deref(),
            // Without obstacles nothing moves: no need to look at every cell's neighbours.
            (!self.obstacles.is_empty()).then_some(&self.moving[..]),
        );
        band.map(|b| {
            band::exchange_with_deep(
                &self.grid,
                &mut self.particles,
                &mut self.markings,
                was_low.as_deref(),
                b.r,
                self.config.mu(),
                &mut self.n_deep,
                &self.velocity,
                &mut self.rng,
            )
        })
    }

    /// The volume measure of eq. volume as a percentage of `V*`.
    pub fn volume_percent(&self) -> f64 {
        if self.target_volume == 0.0 {
            return 100.0;
        }
        100.0 * metrics::volume_cells(&self.markings, self.config.mu()) / self.target_volume
    }

    /// The time step for the coming step: at most `max_dt`, and small enough that the current
    /// particle speed plus one step of gravity moves nothing more than `cfl` cells:
    /// `(v + g dt) dt <= cfl`. The projection can still raise the speed; [`Self::step`] then
    /// shortens the step.
    fn planned_dt(&self) -> f64 {
        let c = &self.config;
        let v = self
            .particles
            .vel
            .iter()
            .map(|v| v.amax())
            .fold(0.0f64, f64::max)
            .min(c.max_speed)
            .max(
                self.obstacles
                    .iter()
                    .map(|o| o.velocity.amax())
                    .fold(0.0, f64::max),
            );
        let g = c.gravity.amax();
        let dt = if g > 0.0 {
            (-v + (v * v + 4.0 * g * c.cfl).sqrt()) / (2.0 * g)
        } else if v > 0.0 {
            c.cfl / v
        } else {
            f64::INFINITY
        };
        dt.min(c.max_dt_secs)
    }

    /// Advances the simulation by one step.
    pub fn step(&mut self) -> Result<StepReport<D>, InvariantViolation> {
        let mut rep = StepReport::default();
        let mut dt = self.planned_dt();
        let grid = &self.grid;
        let c = &self.config;

        let band = self.band();
        let emitted = rep.times.time(Stage::Emit, || {
            // The band's deep holds imaginary particles: emitters see its cells as full.
            let occupied: Vec<u32> = match band {
                Some(b) if !c.emitters.is_empty() => (0..grid.num_cells())
                    .map(|i| match self.markings.level(i, b.r) {
                        DepthLevel::Deep if self.markings.is_fluid(i) => c.mu(),
                        _ => self.markings.count[i],
                    })
                    .collect(),
                _ => vec![],
            };
            let count = if occupied.is_empty() {
                &self.markings.count
            } else {
                &occupied
            };
            let mut added = 0;
            for e in &c.emitters {
                added += e.emit(
                    grid,
                    self.time_secs,
                    count,
                    self.n_deep,
                    &self.solid,
                    c.per_axis,
                    c.jitter,
                    &mut self.particles,
                    &mut self.rng,
                );
            }
            added
        });
        // New fluid changes the depths: the deep must hold no real particle when the
        // correction counts its room.
        let mut emit_exchange = None;
        if emitted > 0 {
            let mu = self.config.mu();
            emit_exchange = self.refresh_markings();
            self.total_particles += emitted;
            self.target_volume += emitted as f64 / mu as f64;
        }
        rep.emitted = emitted;

        let grid = &self.grid;
        let c = &self.config;
        let (mut u, mut known) = rep.times.time(Stage::ParticlesToGrid, || {
            let (mut u, mut known) =
                transfer::particles_to_grid(grid, &self.particles.pos, &self.particles.vel);
            if let Some(b) = band {
                transfer::combine_with_grid(
                    grid,
                    &mut u,
                    &mut known,
                    &self.velocity,
                    &self.markings,
                    b.r,
                );
            }
            transfer::extrapolate(grid, &mut u, &mut known, 2);
            (u, known)
        });
        let u_old = u.clone();

        rep.times.time(Stage::Forces, || {
            for a in 0..D {
                let g = c.gravity[a] * dt;
                if g != 0.0 {
                    u.comp[a].iter_mut().for_each(|v| *v += g);
                }
            }
            pressure::apply_solid_boundary(grid, &self.solid, &self.solid_vel, &mut u);
        });

        rep.pcg = rep.times.time(Stage::Pressure, || {
            let settings = PcgSettings {
                tolerance: c.pressure_tolerance,
                ..Default::default()
            };
            let stats = pressure::project(
                grid,
                &self.markings.kind,
                &self.solid,
                &self.solid_vel,
                &mut u,
                &settings,
            );
            known = pressure::known_after_projection(grid, &self.markings.kind, &self.solid);
            transfer::extrapolate(grid, &mut u, &mut known, 2);
            for comp in u.comp.iter_mut() {
                comp.iter_mut()
                    .for_each(|v| *v = v.clamp(-c.max_speed, c.max_speed));
            }
            stats
        });
        rep.max_speed = u.max_abs();
        if !rep.max_speed.is_finite() {
            return Err(InvariantViolation(format!(
                "the grid velocity is not finite after the pressure solve ({:?})",
                rep.pcg
            )));
        }
        if rep.max_speed * dt > c.cfl {
            dt = c.cfl / rep.max_speed;
            rep.dt_shortened = true;
        }

        rep.times.time(Stage::GridToParticles, || {
            transfer::grid_to_particles(
                grid,
                &u,
                &u_old,
                c.flip_ratio,
                &self.particles.pos,
                &mut self.particles.vel,
            );
            for v in self.particles.vel.iter_mut() {
                let s = v.norm();
                if s > c.max_speed {
                    *v *= c.max_speed / s;
                }
            }
        });
        let x_bar = (c.method == Method::Ccp).then(|| self.particles.pos.clone());
        let advected_u = rep.times.time(Stage::Advect, || {
            advect::advect_particles(grid, &u, &self.solid, dt, &mut self.particles.pos);
            band.map(|_| {
                // The next step reads the grid velocity next to the interface and the deep,
                // which lie inside the fluid: advect the faces of fluid cells.
                let needed: Vec<bool> = (0..grid.num_cells())
                    .map(|c| self.markings.is_fluid(c))
                    .collect();
                advect::advect_velocity(grid, &u, dt, &needed)
            })
        });
        // Where each obstacle would be after this step, and the cells it would newly occupy
        // (C_new_solid) with their clearing distance (def. clear_dist).
        // One after the other, each clear of the others where they are and where those
        // before it go.
        let mut targets = Vec::with_capacity(self.obstacles.len());
        if !self.obstacles.is_empty() {
            let mut owner = solids::owners(grid, &self.obstacles);
            for (k, o) in self.obstacles.iter().enumerate() {
                let t = o.target(grid, dt, |c| {
                    self.static_solid[c] || owner[c].is_some_and(|j| j != k)
                });
                o.cells_at(grid, &t)
                    .into_iter()
                    .for_each(|c| owner[c] = Some(k));
                targets.push(t);
            }
        }
        let wanted: Vec<Vec<usize>> = self
            .obstacles
            .iter()
            .zip(&targets)
            .map(|(o, t)| {
                let mut cells = o.cells_at(grid, t);
                cells.retain(|&c| !self.solid[c]);
                cells
            })
            .collect();
        let mut penalty = None;
        if !self.obstacles.is_empty() {
            let mut new_solid = vec![false; grid.num_cells()];
            wanted.iter().flatten().for_each(|&c| new_solid[c] = true);
            let clear = solids::clearing_distance(grid, &new_solid, &self.solid);
            rep.new_solid = (0..grid.num_cells())
                .filter(|&c| new_solid[c])
                .map(|c| (c, clear[c]))
                .collect();
            if c.obstacle_mode == ObstacleMode::Couple && !rep.new_solid.is_empty() {
                penalty = Some(solids::penalties(&clear));
            }
        }
        if let Some(x_bar) = x_bar {
            let want_mps = self.export_problem_at_step == Some(self.steps + 1);
            let report = rep.times.time(Stage::Correct, || {
                correct::correct(
                    grid,
                    &x_bar,
                    &mut self.particles.pos,
                    &self.markings,
                    &self.solid,
                    c.mu(),
                    &c.correction,
                    band.map(|b| BandContext {
                        r: b.r,
                        n_deep: self.n_deep,
                        variant: b.variant,
                    }),
                    penalty.as_deref(),
                    want_mps,
                )
            });
            let report =
                report.map_err(|e| InvariantViolation(format!("correction problem: {e}")))?;
            metrics::check_cell_counts(
                grid,
                &self.particles.pos,
                &self.markings,
                &self.solid,
                c.mu(),
                band.map(|b| b.r),
            )?;
            rep.correction = Some(report);
        }
        // Each obstacle moves unless particles hold cells it wants (couple: after the
        // correction; naive: after advection); with `ignore` it always moves.
        if !self.obstacles.is_empty() {
            let mut occupied = vec![false; grid.num_cells()];
            for x in &self.particles.pos {
                occupied[grid.cell_index_of(x)] = true;
            }
            rep.blocked = wanted
                .iter()
                .map(|cells| {
                    c.obstacle_mode != ObstacleMode::Ignore && cells.iter().any(|&k| occupied[k])
                })
                .collect();
            // In the water: fluid in or next to a cell the obstacle occupies or wants.
            let touches_fluid = |cells: &[usize]| {
                cells.iter().any(|&k| {
                    self.markings.is_fluid(k)
                        || grid
                            .moore_neighbors(grid.cell_coords(k))
                            .any(|m| self.markings.is_fluid(grid.cell_index(m)))
                })
            };
            let in_water: Vec<bool> = self
                .obstacles
                .iter()
                .zip(&wanted)
                .map(|(o, w)| touches_fluid(w) || touches_fluid(&o.cells_at(grid, &o.offset)))
                .collect();
            for (o, (to, blocked)) in self
                .obstacles
                .iter_mut()
                .zip(targets.iter().zip(&rep.blocked))
            {
                if !blocked {
                    o.offset = *to;
                }
            }
            let owner = solids::owners(grid, &self.obstacles);
            for (k, o) in self.obstacles.iter_mut().enumerate() {
                o.accelerate(
                    grid,
                    &c.gravity,
                    dt,
                    in_water[k],
                    |c| self.static_solid[c],
                    |c| owner[c].is_some_and(|j| j != k),
                );
            }
            (self.solid, self.solid_vel, self.moving) =
                rasterise(&self.grid, &self.static_solid, &self.obstacles);
        }
        self.velocity = advected_u.unwrap_or(u);
        rep.deep = rep
            .times
            .time(Stage::Markings, || self.refresh_markings())
            .map(|x| x.merged(emit_exchange));
        self.time_secs += dt;
        self.steps += 1;
        rep.dt_secs = dt;
        rep.volume_percent = self.volume_percent();
        self.check_invariants()?;
        Ok(rep)
    }

    /// The invariants every method keeps, checked after every step (O(particles)): with the
    /// band, particles plus `n_deep` account for every particle seeded or emitted, and no cell
    /// holds more than `mu`.
    pub fn check_invariants(&self) -> Result<(), InvariantViolation> {
        // With `ignore`, particles an obstacle covers are lost volume, not a broken invariant.
        let solid = match self.config.obstacle_mode {
            ObstacleMode::Ignore => &self.static_solid,
            _ => &self.solid,
        };
        metrics::check_particles(
            &self.grid,
            &self.particles.pos,
            &self.particles.vel,
            solid,
            self.total_particles
                .checked_sub(self.n_deep)
                .ok_or_else(|| {
                    InvariantViolation(format!(
                        "n_deep = {} exceeds the {} particles ever seeded or emitted",
                        self.n_deep, self.total_particles
                    ))
                })?,
        )?;
        if let Some(b) = self.band() {
            let mu = self.config.mu();
            if let Some(c) = (0..self.grid.num_cells()).find(|&c| self.markings.count[c] > mu) {
                return Err(InvariantViolation(format!(
                    "cell {:?} holds {} particles after the exchange with the deep (mu = {mu})",
                    self.grid.cell_coords(c),
                    self.markings.count[c]
                )));
            }
            if let Some(x) = self.particles.pos.iter().find(|x| {
                let c = self.grid.cell_index_of(x);
                self.markings.is_fluid(c) && self.markings.level(c, b.r) == DepthLevel::Deep
            }) {
                return Err(InvariantViolation(format!(
                    "a particle at {:?} is in the deep after the exchange",
                    x.as_slice()
                )));
            }
        }
        Ok(())
    }
}

/// Solid cells, their velocities and the moving ones: the static solids plus every obstacle
/// at its current offset.
fn rasterise<const D: usize>(
    grid: &Grid<D>,
    static_solid: &[bool],
    obstacles: &[Obstacle<D>],
) -> (Vec<bool>, Vec<Vector<D>>, Vec<bool>) {
    let n = grid.num_cells();
    let mut solid = static_solid.to_vec();
    let mut vel = vec![Vector::zeros(); n];
    let mut moving = vec![false; n];
    for (c, k) in solids::owners(grid, obstacles).into_iter().enumerate() {
        if let Some(k) = k {
            solid[c] = true;
            vel[c] = obstacles[k].boundary_velocity();
            moving[c] = obstacles[k].velocity != Vector::<D>::zeros();
        }
    }
    (solid, vel, moving)
}
