//! The seam between the step and the methods: what a method declares ([`MethodInfo`], its
//! options and settings), the traits it implements (the step's hooks in [`FluidMethod`], what
//! recordings ask of it in [`MethodRecording`], its step report [`MethodReport`] and its run's
//! [`MethodSummary`]) and how it is registered ([`MethodType`]); what it costs is in
//! [`super::cost`]. The hook table is in the
//! module doc of `crate::methods`.

use super::cost::{Footprint, StepCost};
use super::options::Flag;
use crate::draw::{LayerView, Log, Panel};
use crate::grid::{Grid, MacField, NearCells, Vector};
use crate::snapshot::{Reader, SnapshotError, Writer};
use crate::stages::invariants::InvariantViolation;
use crate::stages::markings::Markings;
use crate::stages::solids::ObstacleMode;
use crate::stages::transfer::{self, Known};
use crate::stages::{ParticlesMut, State, StepError};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::fmt::Debug;
use std::path::{Path, PathBuf};

/// A method's setting out of its range or at odds with another: its key under the scene file's
/// `[simulation]` table (e.g. `band_r`, `powerpic.eta`), whether it is a conflict between
/// settings (else a value out of range), and why.
#[derive(Clone, Debug, PartialEq)]
pub struct SettingError {
    pub key: String,
    pub conflict: bool,
    pub reason: String,
}

impl SettingError {
    /// A value out of its range.
    pub fn range(key: &str, reason: String) -> Self {
        Self {
            key: key.into(),
            conflict: false,
            reason,
        }
    }
}

/// The band a run keeps (sec. band_method): how it keeps its count, and its depth `R`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BandChoice {
    /// The variant's name, e.g. `paths`.
    pub variant: &'static str,
    pub r: u32,
}

/// A file a method writes at the end of a step, because the command line asked for it.
#[derive(Clone, Debug, PartialEq)]
pub struct StepFile {
    /// The flag that asked for it, without its dashes.
    pub flag: &'static str,
    pub step: u64,
    pub path: PathBuf,
}

/// A file a step hands over to be written, because the command line asked for it (ccp's
/// `--export-lp N`: the problem its correction solved): its path ([`StepFile::path`], or one
/// beside it), what it is, for the run's summary, and its text. No hook writes a file: the
/// run's observer writes these ([`crate::runner::Exports`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Export<'a> {
    pub path: &'a Path,
    /// E.g. `the correction problem of step 3`.
    pub what: String,
    pub text: &'a str,
}

/// A method without settings of its own: its scene table, if given, must be empty.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoSettings {}

/// What a method's settings are checked with besides themselves.
#[derive(Clone, Copy, Debug)]
pub struct SettingContext {
    pub dim: usize,
    /// Particles per cell along an axis, `k`; `mu = k^dim`.
    pub per_axis: usize,
}

/// What a method is, for lists, help and checks.
#[derive(Debug)]
pub struct MethodInfo {
    /// Its name in scene files and on the command line.
    pub name: &'static str,
    /// One line: the method and its paper.
    pub about: &'static str,
    /// The obstacle modes it supports; the first is its default.
    pub obstacle_modes: &'static [ObstacleMode],
    /// Time-series panels of its metrics in the recording's layout, one quantity family each.
    pub panels: &'static [Panel],
    /// Its layers that would hide or blend with the particles in the world view, each in a
    /// view of its own beside it.
    pub layer_views: &'static [LayerView],
    /// The names of the per-step figures its reports give ([`MethodReport::figures`]), which
    /// `cellflip report` summarises (median over the steps) in columns `<name>_median`.
    pub figures: &'static [&'static str],
}

/// Registration of a method type: its description, its options, how to build its step and its
/// summary.
pub trait MethodType {
    const INFO: MethodInfo;
    /// Its own settings: as serde reads them, its scene table `[simulation.<name>]` (the keys of
    /// that table which a file of this method may also give directly in `[simulation]` are
    /// listed in `crate::scene`); the command line sets them through [`Self::FLAGS`].
    type Settings: Clone + Debug + PartialEq + Default + Serialize + DeserializeOwned + 'static;
    /// Its command-line flags (`crate::methods::options`).
    const FLAGS: &'static [Flag<Self::Settings>] = &[];
    /// Refuses settings out of range or at odds with each other (the scene file's check calls it
    /// for the method a scene runs).
    fn check(_settings: &Self::Settings, _ctx: SettingContext) -> Result<(), SettingError> {
        Ok(())
    }
    /// The band (sec. band_method) these settings keep, if any.
    fn band(_settings: &Self::Settings) -> Option<BandChoice> {
        None
    }
    /// Whether these settings solve each step twice and compare ([`crate::draw::Needs::CrossCheck`]).
    fn cross_checks(_settings: &Self::Settings) -> bool {
        false
    }
    /// The files these settings ask the method to write, named after `stem` (the recording's path
    /// without its extension), which it records in its settings for [`Self::build`].
    fn files(_settings: &mut Self::Settings, _stem: &Path) -> Vec<StepFile> {
        vec![]
    }
    fn build<const D: usize>(settings: &Self::Settings) -> Box<dyn FluidMethod<D>>;
    fn summary<const D: usize>(settings: &Self::Settings) -> Box<dyn MethodSummary<D>>;
    /// Its peak memory over a run in `dim` dimensions with these settings (the particles of its
    /// band, if it holds one, are counted up front from the seeded liquid).
    fn footprint(settings: &Self::Settings, dim: usize) -> Footprint;
    /// Its wall time per step in `dim` dimensions, for the plan of a sweep.
    fn step_cost(settings: &Self::Settings, dim: usize) -> StepCost;
}

/// One fluid method's step: the places where it departs from plain FLIP. Every hook has
/// FLIP's behaviour as its default.
pub trait FluidMethod<const D: usize>: MethodRecording<D> + Send {
    /// After seeding and the first markings.
    fn start(&mut self, _s: &mut State<D>) {}

    /// The particle count of cell `c` that emitters top up to `mu` (asked for the cells of
    /// emitters that emit this step only).
    fn emitter_count(&self, s: &State<D>, c: usize) -> u32 {
        s.markings.count[c]
    }

    /// Particles seeded or emitted that the method accounts for without holding them: the
    /// band's imaginary particles of the deep (ccp), or what resampling deleted net of what it
    /// seeded (nbflip; negative when it seeded more). Particles held plus these are all particles
    /// ever seeded or emitted (checked every step).
    fn particles_not_held(&self) -> isize {
        0
    }

    /// Whether cell `c`, which is not solid, holds liquid that no particle stands for, after
    /// the advection: `naive` obstacles wait for it as for a particle (sec. soilds). FLIP's
    /// liquid is its particles.
    fn holds_liquid(&self, _grid: &Grid<D>, _c: usize) -> bool {
        false
    }

    /// Alg. flip line 1: particle velocities to the grid's faces, and which faces got one.
    fn particles_to_grid(&mut self, s: &State<D>) -> Result<(MacField<D>, Known<D>), StepError> {
        Ok(transfer::particles_to_grid(
            &s.grid,
            &s.particles.pos,
            &s.particles.vel,
        ))
    }

    /// Alg. flip line 4: the grid velocity back to the particles (`u_old` is the field before
    /// forces and projection), their speeds bounded by `max_speed` (checked after every step's
    /// transfer: [`crate::stages::invariants::check_speed_bound`]). Returns true when it wrote
    /// `u(x_p)` per particle to `at` and the particles have not moved, for the advection (line
    /// 5) to use instead of interpolating `u` again at the same points.
    fn grid_to_particles(
        &mut self,
        s: ParticlesMut<'_, D>,
        u: &MacField<D>,
        u_old: &MacField<D>,
        at: &mut Vec<Vector<D>>,
    ) -> bool {
        let blend = transfer::Blend {
            flip_ratio: s.config.flip_ratio,
            max_speed: s.config.max_speed,
        };
        transfer::grid_to_particles(s.grid, u, u_old, blend, s.particles, at);
        true
    }

    /// Just before the particles are advected (their positions are `x_bar`).
    fn before_advection(&mut self, _s: &State<D>) {}

    /// The grid velocity the next step starts from, given this step's projected one.
    fn next_grid_velocity(&mut self, _s: &State<D>, u: MacField<D>, _dt: f64) -> MacField<D> {
        u
    }

    /// Alg. flip line 6: corrects the advected positions. `penalty` is the per-cell cost of
    /// a particle in a cell a moving obstacle wants (eq. solid_penalty2), when obstacles are
    /// coupled.
    fn correct_positions(
        &mut self,
        _s: ParticlesMut<'_, D>,
        _penalty: Option<&[f64]>,
    ) -> Result<(), StepError> {
        Ok(())
    }

    /// Just before new markings are computed from the particles (`s.markings` are still the
    /// previous ones): the method may resample its particles (nbflip) and returns the cells
    /// that stay fluid even without particles.
    fn before_markings(&mut self, _s: ParticlesMut<'_, D>) -> Option<NearCells> {
        None
    }

    /// After new markings and their active cells were computed (after emission and at the
    /// end of the step); `previous` are the markings they replace. The method may change the
    /// particles and their counts, not which cells are fluid.
    fn after_markings(&mut self, _s: &mut State<D>, _previous: &Markings) {}

    /// The invariants this method guarantees beyond those of every method.
    fn check_invariants(&self, _s: &State<D>) -> Result<(), InvariantViolation> {
        Ok(())
    }

    /// What the method carries from one step to the next, written to a checkpoint after a
    /// step (`crate::checkpoint`; arrays named `<method>.<what>`). FLIP carries nothing.
    fn save_state<'a>(&'a self, _w: &mut Writer<'a>) {}

    /// Takes back what [`save_state`](Self::save_state) wrote, on the state restored from the
    /// same checkpoint; called instead of [`start`](Self::start).
    fn restore_state(&mut self, _s: &State<D>, _r: &Reader) -> Result<(), SnapshotError> {
        Ok(())
    }

    /// Ends the step: what the method did in it, as one value.
    fn finish_step(&mut self, _s: &State<D>) -> Box<dyn MethodReport<D>> {
        Box::new(NoReport)
    }
}

/// What a recording asks of a method's state beyond its step reports ([`MethodReport`]);
/// every hook has a default for a method with nothing to add.
pub trait MethodRecording<const D: usize> {
    /// Static recording data (class colours of its layers).
    fn record_setup(&self, _log: &mut dyn Log<D>) {}

    /// Whether cell `c` is in the method's deep: fluid below its band, whose particles it does
    /// not hold. Recordings draw it as its own class in the markings rather than as a bubble.
    fn is_deep(&self, _s: &State<D>, _c: usize) -> bool {
        false
    }
}

/// What a method did over a run, gathered from its step reports, for the run's summary.
pub trait MethodSummary<const D: usize>: Send {
    /// Adds one step's report (of this method) with the state after the step.
    fn add(&mut self, report: &dyn MethodReport<D>, s: &State<D>);

    /// Lines for the run's summary.
    fn lines(&self) -> Vec<String>;
}

/// The summary of a method with nothing to add to the run's.
pub struct NoSummary;

impl<const D: usize> MethodSummary<D> for NoSummary {
    fn add(&mut self, _report: &dyn MethodReport<D>, _s: &State<D>) {}

    fn lines(&self) -> Vec<String> {
        vec![]
    }
}

/// What a method did in one step.
pub trait MethodReport<const D: usize>: Any + Debug + Send {
    /// Logs the report: metrics every step, drawings when `full`.
    fn record(&self, s: &State<D>, log: &mut dyn Log<D>, full: bool);

    /// Per-step figures for `cellflip report`: solver statistics by name (each name listed
    /// in [`MethodInfo::figures`]).
    fn figures(&self) -> Vec<(&'static str, f64)> {
        vec![]
    }

    /// The files this step hands over to be written ([`Export`]).
    fn exports(&self) -> Vec<Export<'_>> {
        vec![]
    }

    fn as_any(&self) -> &dyn Any;
}

/// The report of a method with nothing to say.
#[derive(Debug)]
pub struct NoReport;

impl<const D: usize> MethodReport<D> for NoReport {
    fn record(&self, _s: &State<D>, _log: &mut dyn Log<D>, _full: bool) {}

    fn as_any(&self) -> &dyn Any {
        self
    }
}
