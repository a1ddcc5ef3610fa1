//! The library of the paper's steps, generic over the dimension: the stages of alg. flip and
//! alg. band, one file per step, and the [`State`] they read and write.
//!
//! It knows no method: the step that calls these stages in order, and the methods' hooks
//! between them, sit above it (`crate::step`).

pub mod advect;
pub mod band;
pub mod emit;
pub mod forces;
pub mod invariants;
pub mod markings;
pub mod pressure;
pub mod saved;
pub mod solids;
pub mod timestep;
pub mod transfer;
pub mod volume;

use crate::grid::active::Active;
use crate::grid::{Grid, MacField, NearCells, Vector};
use crate::particles::{self, Particles, Region};
use crate::solvers::pcg::Preconditioner;
use emit::Emitter;
pub use markings::ACTIVE_MARGIN;
use markings::{CellKind, Markings};
use rand::SeedableRng;
use solids::{Obstacle, ObstacleMode, Solids};

/// Everything a simulation needs, in grid units (cells, seconds, cells per second).
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig<const D: usize> {
    pub dims: [usize; D],
    /// Cell size in metres (only to report results in SI).
    pub cell_size_m: f64,
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
    /// CG's preconditioner in the pressure solve (and idp's second solve).
    pub pressure_preconditioner: Preconditioner,
    /// Whether the pressure solve starts from the last step's pressure
    /// ([`pressure::WarmStart`]) rather than from zero.
    pub pressure_warm_start: bool,
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

/// The simulation's random generator: ChaCha12, the algorithm of `rand`'s `StdRng` (and the
/// same stream for the same seed), named so that a checkpoint can save its position.
pub type SimRng = rand_chacha::ChaCha12Rng;

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
    /// Where the step's grid passes work: the cells within [`ACTIVE_MARGIN`] of a fluid cell
    /// or a moving obstacle's cell of the current markings.
    pub active: Active<D>,
    pub time_secs: f64,
    pub steps: u64,
    /// Particles seeded at the start plus all emitted since.
    pub total_particles: usize,
    /// `V*`: initial volume plus emitted volume, in cells.
    pub target_volume: f64,
    pub rng: SimRng,
    /// The last pressure solve's result, where the next one starts
    /// ([`SimConfig::pressure_warm_start`]).
    pub pressure: pressure::WarmStart,
}

/// The cells within [`ACTIVE_MARGIN`] of a fluid cell of `markings` or a moving obstacle's
/// cell, by a pass over the box: for markings read from a checkpoint (new markings come with
/// theirs, [`Markings::compute_keeping`]).
pub(crate) fn active_cells<const D: usize>(
    grid: &Grid<D>,
    markings: &Markings,
    solids: &Solids<D>,
) -> Active<D> {
    let (fluid, moving) = (&markings.kind, solids.moving_mask());
    let seed = |c| fluid[c] == CellKind::Fluid || moving.is_some_and(|m| m[c]);
    Active::around(grid, seed, ACTIVE_MARGIN)
}

/// Why a step failed.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// A guarantee broke: a bug, or a state the method cannot go on from.
    #[error(transparent)]
    Invariant(#[from] invariants::InvariantViolation),
    /// A method's solver failed: the setting that causes it (e.g.
    /// `simulation.powerpic.epsilon`), the solver, and why.
    #[error("{setting}: {solver} failed")]
    Solver {
        setting: &'static str,
        solver: &'static str,
        #[source]
        error: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// The state as a hook that changes only the particles sees it (a method's transfer to the
/// particles, its correction, its resampling before the markings): the particles and the random
/// stream that seeds them may change, the rest is read-only.
pub struct ParticlesMut<'a, const D: usize> {
    pub config: &'a SimConfig<D>,
    pub grid: &'a Grid<D>,
    pub solids: &'a Solids<D>,
    pub markings: &'a Markings,
    /// The active cells of `markings`.
    pub active: &'a Active<D>,
    /// The grid velocity the step started from.
    pub velocity: &'a MacField<D>,
    /// Steps done before this one.
    pub steps: u64,
    pub particles: &'a mut Particles<D>,
    pub rng: &'a mut SimRng,
}

impl<const D: usize> State<D> {
    /// The state for a hook that changes only the particles ([`ParticlesMut`]).
    pub fn particles_mut(&mut self) -> ParticlesMut<'_, D> {
        ParticlesMut {
            config: &self.config,
            grid: &self.grid,
            solids: &self.solids,
            markings: &self.markings,
            active: &self.active,
            velocity: &self.velocity,
            steps: self.steps,
            particles: &mut self.particles,
            rng: &mut self.rng,
        }
    }

    /// The state at the start: the fluid seeded, its first markings, the fluid at rest.
    pub fn new(config: SimConfig<D>) -> Self {
        let grid = Grid::new(config.dims);
        let solids = Solids::new(
            &grid,
            &config.solids,
            &config.obstacles,
            config.obstacle_mode,
        );
        let mut rng = SimRng::seed_from_u64(config.seed);
        let particles = particles::seed(
            &grid,
            &config.fluid,
            &solids.solid,
            config.per_axis,
            config.jitter,
            &mut rng,
        );
        let (markings, active) =
            Markings::compute_keeping(&grid, &particles.pos, solids.cells(), None);
        let total = particles.len();
        State {
            target_volume: total as f64 / config.mu() as f64,
            velocity: MacField::zeros(&grid),
            active,
            markings,
            time_secs: 0.0,
            steps: 0,
            total_particles: total,
            grid,
            particles,
            solids,
            config,
            rng,
            pressure: Default::default(),
        }
    }

    /// The volume measure of eq. volume as a percentage of `V*`.
    pub fn volume_percent(&self) -> f64 {
        if self.target_volume == 0.0 {
            return 100.0;
        }
        let mu = self.config.mu();
        100.0 * volume::volume_cells(&self.markings, mu, &self.active) / self.target_volume
    }

    /// New markings from the particles and the obstacles where they are now, with their
    /// active cells; cells of `keep` stay fluid without particles. Returns the markings they
    /// replace.
    pub fn remark(&mut self, keep: Option<&NearCells>) -> Markings {
        let (pos, solids) = (&self.particles.pos, self.solids.cells());
        let (new, active) = Markings::compute_keeping(&self.grid, pos, solids, keep);
        self.active = active;
        std::mem::replace(&mut self.markings, new)
    }
}
