//! One time step of the fluid methods, generic over the dimension (paper alg. flip, and
//! alg. band for the band method).
//!
//! [`Simulation::step`] is the algorithm box as a list of named stages; each stage is a
//! function in the file of its step, and the places where methods differ are the hooks of
//! [`crate::methods::FluidMethod`].

pub mod advect;
pub mod band;
pub mod correct;
pub mod emit;
pub mod forces;
pub mod levelset;
pub mod markings;
pub mod pressure;
pub mod solids;
pub mod timestep;
pub mod transfer;

use crate::grid::{Grid, MacField, Vector};
use crate::methods::{FluidMethod, MethodReport, MethodSettings, NoReport};
use crate::metrics::{self, InvariantViolation, Stage, StageTimes};
use crate::particles::{self, Particles, Region};
use crate::solvers::pcg::PcgStats;
use emit::Emitter;
use markings::Markings;
use rand::rngs::StdRng;
use rand::SeedableRng;
use solids::{Obstacle, ObstacleMode, Solids};

/// Everything a simulation needs, in grid units (cells, seconds, cells per second).
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig<const D: usize> {
    pub dims: [usize; D],
    /// Cell size in metres (only to report results in SI).
    pub cell_size_m: f64,
    /// The fluid method and its settings.
    pub method: MethodSettings,
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
#[derive(Debug)]
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
    /// Per obstacle: whether it had to stay this step.
    pub blocked: Vec<bool>,
    /// The cells obstacles wanted this step (`C_new_solid`) with their clearing distance.
    pub new_solid: Vec<(usize, u32)>,
    /// What the method did.
    pub method: Box<dyn MethodReport<D>>,
}

impl<const D: usize> StepReport<D> {
    fn new() -> Self {
        Self {
            dt_secs: 0.0,
            dt_shortened: false,
            times: StageTimes::default(),
            pcg: PcgStats::default(),
            max_speed: 0.0,
            emitted: 0,
            volume_percent: 0.0,
            blocked: vec![],
            new_solid: vec![],
            method: Box::new(NoReport),
        }
    }

    /// The method's report as its own type, e.g. `rep.method_report::<CcpReport<2>>()`.
    pub fn method_report<T: 'static>(&self) -> Option<&T> {
        self.method.as_any().downcast_ref()
    }
}

/// The state every method reads and writes.
pub struct State<const D: usize> {
    pub config: SimConfig<D>,
    pub grid: Grid<D>,
    pub particles: Particles<D>,
    /// Grid velocity the next step starts from, cells per second.
    pub velocity: MacField<D>,
    /// Static solids and obstacles.
    pub solids: Solids<D>,
    pub markings: Markings,
    pub time_secs: f64,
    pub steps: u64,
    /// Particles seeded at the start plus all emitted since.
    pub total_particles: usize,
    /// `V*`: initial volume plus emitted volume, in cells.
    pub target_volume: f64,
    pub rng: StdRng,
}

impl<const D: usize> State<D> {
    /// The volume measure of eq. volume as a percentage of `V*`.
    pub fn volume_percent(&self) -> f64 {
        if self.target_volume == 0.0 {
            return 100.0;
        }
        100.0 * metrics::volume_cells(&self.markings, self.config.mu()) / self.target_volume
    }

    /// New markings from the particles; cells flagged in `keep` stay fluid without particles.
    /// Returns the markings they replace.
    pub fn remark(&mut self, keep: Option<&[bool]>) -> Markings {
        let new = Markings::compute_keeping(
            &self.grid,
            &self.particles.pos,
            &self.solids.solid,
            keep,
            self.solids.moving_mask(),
        );
        std::mem::replace(&mut self.markings, new)
    }
}

/// A running simulation: the state and the method that steps it.
pub struct Simulation<const D: usize> {
    pub state: State<D>,
    pub method: Box<dyn FluidMethod<D>>,
    /// Grid-to-particle's `u(x_p)` for the advection, its allocation kept between steps.
    u_at_particles: Vec<Vector<D>>,
}

impl<const D: usize> Simulation<D> {
    pub fn new(config: SimConfig<D>) -> Self {
        let grid = Grid::new(config.dims);
        let solids = Solids::new(
            &grid,
            &config.solids,
            &config.obstacles,
            config.obstacle_mode,
        );
        let mut rng = StdRng::seed_from_u64(config.seed);
        let particles = particles::seed(
            &grid,
            &config.fluid,
            &solids.solid,
            config.per_axis,
            config.jitter,
            &mut rng,
        );
        let markings = Markings::compute_keeping(
            &grid,
            &particles.pos,
            &solids.solid,
            None,
            solids.moving_mask(),
        );
        let total = particles.len();
        let mut method = config.method.kind.build::<D>(&config.method);
        let mut state = State {
            target_volume: total as f64 / config.mu() as f64,
            velocity: MacField::zeros(&grid),
            markings,
            time_secs: 0.0,
            steps: 0,
            total_particles: total,
            grid,
            particles,
            solids,
            config,
            rng,
        };
        method.start(&mut state);
        Self {
            state,
            method,
            u_at_particles: vec![],
        }
    }

    /// Advances the simulation by one step (alg. flip; alg. band with the band).
    pub fn step(&mut self) -> anyhow::Result<StepReport<D>> {
        let Simulation {
            state: s,
            method: m,
            u_at_particles,
        } = self;
        let mut rep = StepReport::new();
        let mut dt = timestep::planned(s);
        rep.emitted = rep.times.time(Stage::Emit, || emit::emit(s, m.as_ref()));
        if rep.emitted > 0 {
            // New fluid changes the depths the correction reads.
            refresh_markings(s, m.as_mut());
        }
        // Line 1: particles to grid.
        let mut u = rep.times.time(Stage::ParticlesToGrid, || {
            let (mut u, mut known) = m.particles_to_grid(s)?;
            transfer::extrapolate(&s.grid, &mut u, &mut known, 2);
            anyhow::Ok(u)
        })?;
        let u_old = u.clone();
        // Lines 2-3: forces and the pressure projection.
        rep.times
            .time(Stage::Forces, || forces::apply(s, &mut u, dt));
        rep.pcg = rep
            .times
            .time(Stage::Pressure, || pressure::project_stage(s, &mut u));
        m.after_projection(s, &mut u);
        rep.max_speed = timestep::finite_speed(&u, &rep.pcg)?;
        (dt, rep.dt_shortened) = timestep::shortened(dt, rep.max_speed, s.config.cfl);
        // Line 4: grid to particles.
        let have_at = rep.times.time(Stage::GridToParticles, || {
            m.grid_to_particles(s, &u, &u_old, u_at_particles)
        });
        metrics::check_speed_bound(&s.particles.vel, s.config.max_speed)?;
        // Line 5: advection (and, with the band, of the grid velocity).
        m.before_advection(s);
        rep.times.time(Stage::Advect, || {
            let (grid, pos) = (&s.grid, &mut s.particles.pos);
            let at = have_at.then_some(u_at_particles.as_slice());
            advect::advect_particles(grid, &u, at, &s.solids.solid, dt, pos);
            s.velocity = m.next_grid_velocity(s, u, dt);
        });
        // Line 6: the correction, with the cells obstacles want this step (sec. 7).
        let plan = s.solids.plan(&s.grid, dt);
        rep.times.time(Stage::Correct, || {
            m.correct_positions(s, plan.penalty.as_deref())
        })?;
        rep.blocked = s.solids.advance(
            &s.grid,
            &plan,
            &s.particles.pos,
            &s.markings,
            &s.config.gravity,
            dt,
        );
        rep.new_solid = plan.new_solid;
        // Line 7: new markings (alg. band line 9 in the method's hook).
        rep.times
            .time(Stage::Markings, || refresh_markings(s, m.as_mut()));
        s.time_secs += dt;
        s.steps += 1;
        rep.dt_secs = dt;
        rep.volume_percent = s.volume_percent();
        self.check_invariants()?;
        rep.method = self.method.finish_step(&self.state);
        Ok(rep)
    }

    /// The invariants every method keeps, checked after every step (O(particles)): particles
    /// held plus those the method holds no longer account for every particle seeded or emitted,
    /// all state is finite, every particle is inside the domain and outside solids; then the
    /// method's own.
    pub fn check_invariants(&self) -> Result<(), InvariantViolation> {
        let s = &self.state;
        let not_held = self.method.particles_not_held();
        let expected = s
            .total_particles
            .checked_add_signed(-not_held)
            .ok_or_else(|| {
                InvariantViolation(format!(
                    "{not_held} particles not held exceed the {} ever seeded or emitted",
                    s.total_particles
                ))
            })?;
        let p = &s.particles;
        metrics::check_particles(&s.grid, &p.pos, &p.vel, s.solids.particle_free(), expected)?;
        self.method.check_invariants(s)
    }
}

/// New markings from the current positions; the method may keep cells fluid without
/// particles, and acts on the new markings (the band's exchange with the deep).
fn refresh_markings<const D: usize>(s: &mut State<D>, m: &mut dyn FluidMethod<D>) {
    let keep = m.before_markings(s);
    let previous = s.remark(keep.as_deref());
    m.after_markings(s, &previous);
}
