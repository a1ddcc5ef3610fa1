//! A running simulation: the state, the method that steps it, and one time step as a list of
//! named stages (paper alg. flip; alg. band for the band methods).
//!
//! This module sits above the methods: [`Simulation::step`] calls the stages of [`crate::stages`]
//! (the library of the paper's steps, which knows no method) and, where methods differ, the
//! hooks of [`FluidMethod`]. After every step it checks the invariants every method keeps,
//! then the method's own.

use crate::grid::Vector;
use crate::methods::{FluidMethod, MethodReport, MethodSettings, MethodSummary, NoReport};
use crate::metrics::{self, Stage, StageTimes};
use crate::snapshot::{Reader, SnapshotError, Writer};
use crate::solvers::pcg::PcgStats;
use crate::stages::invariants::{self, InvariantViolation};
use crate::stages::{
    advect, emit, forces, pressure, timestep, transfer, SimConfig, State, StepError,
};

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

/// A running simulation: the state, the method that steps it and what the method did so far.
pub struct Simulation<const D: usize> {
    pub state: State<D>,
    pub method: Box<dyn FluidMethod<D>>,
    /// The method's totals since the start or the last [`Simulation::reset_summary`].
    pub summary: Box<dyn MethodSummary<D>>,
    settings: MethodSettings,
    /// Grid-to-particle's `u(x_p)` for the advection, its allocation kept between steps.
    u_at_particles: Vec<Vector<D>>,
}

impl<const D: usize> Simulation<D> {
    /// Seeds the scene's fluid and starts the method of `settings` on it.
    pub fn new(config: SimConfig<D>, settings: &MethodSettings) -> Self {
        let mut state = State::new(config);
        let mut method = settings.kind.build::<D>(settings);
        method.start(&mut state);
        Self {
            state,
            method,
            summary: settings.kind.summary::<D>(settings),
            settings: settings.clone(),
            u_at_particles: vec![],
        }
    }

    /// The simulation a checkpoint holds ([`Simulation::save`]) for the scene's `config` and
    /// method `settings` it was written with: the state restored, the method built and given
    /// back its own state instead of started. The method's totals start afresh.
    pub fn restore(
        config: SimConfig<D>,
        settings: &MethodSettings,
        r: &Reader,
    ) -> Result<Self, SnapshotError> {
        let state = State::restore(config, r)?;
        let mut method = settings.kind.build::<D>(settings);
        method.restore_state(&state, r)?;
        let (total, held) = (state.total_particles, state.particles.len());
        let not_held = method.particles_not_held();
        if particles_held(total, not_held) != Some(held) {
            return Err(SnapshotError::Array {
                name: "total_particles".into(),
                reason: format!(
                    "{total} seeded or emitted, but {held} held and {not_held} not held by the \
                     method"
                ),
            });
        }
        Ok(Self {
            state,
            method,
            summary: settings.kind.summary::<D>(settings),
            settings: settings.clone(),
            u_at_particles: vec![],
        })
    }

    /// Writes what the next step reads: the shared state and the method's own.
    pub fn save<'a>(&'a self, w: &mut Writer<'a>) {
        self.state.save(w);
        self.method.save_state(w);
    }

    /// How the liquid moves, the method's deep included ([`metrics::liquid_motion`]): the same
    /// measure for every method.
    pub fn liquid_motion(&self) -> metrics::LiquidMotion {
        let s = &self.state;
        let deep = |c| self.method.is_deep(s, c);
        let (g, vel, h) = (&s.grid, &s.particles.vel, s.config.cell_size_m);
        metrics::liquid_motion(g, vel, s.config.mu(), &s.active, &s.velocity, deep, h)
    }

    /// Forgets the method's totals so far (after a warm-up).
    pub fn reset_summary(&mut self) {
        self.summary = self.settings.kind.summary::<D>(&self.settings);
    }

    /// Advances the simulation by one step (alg. flip; alg. band with the band).
    pub fn step(&mut self) -> Result<StepReport<D>, StepError> {
        let Simulation {
            state: s,
            method: m,
            u_at_particles,
            ..
        } = self;
        let mut rep = StepReport::new();
        let mut dt = timestep::planned(s);
        rep.emitted = rep
            .times
            .time(Stage::Emit, || emit::emit(s, |s, c| m.emitter_count(s, c)));
        if rep.emitted > 0 {
            // New fluid changes the depths the correction reads.
            refresh_markings(s, m.as_mut());
        }
        // Line 1: particles to grid.
        let mut u = rep.times.time(Stage::ParticlesToGrid, || {
            let (mut u, mut known) = m.particles_to_grid(s)?;
            transfer::extrapolate(&s.grid, &mut u, &mut known, 2, &s.active);
            Ok::<_, StepError>(u)
        })?;
        // `u` is zero off the active faces: the particles and the extrapolation stay inside.
        let u_old = s.active.copy(&u);
        // Lines 2-3: forces and the pressure projection.
        rep.times
            .time(Stage::Forces, || forces::apply(s, &mut u, dt));
        rep.pcg = rep
            .times
            .time(Stage::Pressure, || pressure::project_stage(s, &mut u, dt));
        let air = forces::air_velocity(&s.config, dt);
        rep.max_speed = timestep::finite_speed(&s.grid, &u, &s.active, air, &rep.pcg)?;
        (dt, rep.dt_shortened) = timestep::shortened(dt, rep.max_speed, s.config.cfl);
        // Line 4: grid to particles.
        let have_at = rep.times.time(Stage::GridToParticles, || {
            m.grid_to_particles(s.particles_mut(), &u, &u_old, u_at_particles)
        });
        invariants::check_speed_bound(&s.particles.vel, s.config.max_speed)?;
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
            m.correct_positions(s.particles_mut(), plan.penalty.as_deref())
        })?;
        rep.blocked = s.solids.advance(
            &s.grid,
            &plan,
            &s.particles.pos,
            |c| m.holds_liquid(&s.grid, c),
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
        self.summary.add(rep.method.as_ref(), &self.state);
        Ok(rep)
    }

    /// The invariants every method keeps, checked after every step (O(particles)): particles
    /// held plus those the method holds no longer account for every particle seeded or emitted,
    /// all state is finite, every particle is inside the domain and outside solids; then the
    /// method's own.
    pub fn check_invariants(&self) -> Result<(), InvariantViolation> {
        let s = &self.state;
        let not_held = self.method.particles_not_held();
        let expected = particles_held(s.total_particles, not_held).ok_or_else(|| {
            InvariantViolation(format!(
                "{not_held} particles not held exceed the {} ever seeded or emitted",
                s.total_particles
            ))
        })?;
        let p = &s.particles;
        invariants::check_particles(&s.grid, &p.pos, &p.vel, s.solids.particle_free(), expected)?;
        self.method.check_invariants(s)
    }
}

/// The particles a simulation holds when `total` were seeded or emitted and its method holds
/// `not_held` of them otherwise (a deep, a level set; negative when it seeded more); `None`
/// when no count can be.
fn particles_held(total: usize, not_held: isize) -> Option<usize> {
    not_held
        .checked_neg()
        .and_then(|n| total.checked_add_signed(n))
}

/// New markings from the current positions and their active cells; the method may keep cells
/// fluid without particles, and acts on the new markings (the band's exchange with the deep).
fn refresh_markings<const D: usize>(s: &mut State<D>, m: &mut dyn FluidMethod<D>) {
    let keep = m.before_markings(s.particles_mut());
    let previous = s.remark(keep.as_ref());
    m.after_markings(s, &previous);
}
