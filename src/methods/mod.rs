//! The fluid methods, behind one seam.
//!
//! Every method here is PIC/FLIP on a MAC grid (paper alg. flip) plus something; they differ
//! only at the places where alg. flip and alg. band let them differ, and those places are the
//! hooks of [`FluidMethod`]:
//!
//! | hook | alg. flip / alg. band | who uses it |
//! |---|---|---|
//! | [`FluidMethod::start`] | after the first markings | ccp with the band: first exchange with the deep |
//! | [`FluidMethod::emitter_counts`] | emission | the band methods: the deep counts as full |
//! | [`FluidMethod::particles_not_held`] | the particle-count invariant | ccp's deep, nbflip's resampling |
//! | [`FluidMethod::particles_to_grid`] | line 1 | ccp with the band: the velocity combination |
//! | [`FluidMethod::after_projection`] | after line 3 | (IDP's second solve) |
//! | [`FluidMethod::grid_to_particles`] | line 4 | FLIP/PIC blend by default |
//! | [`FluidMethod::before_advection`], [`FluidMethod::next_grid_velocity`] | line 5 | ccp keeps `x_bar`; the band advects the grid velocity |
//! | [`FluidMethod::correct_positions`] | line 6 | ccp: eq. problem3 and the band corrections |
//! | [`FluidMethod::before_markings`], [`FluidMethod::after_markings`] | line 7, alg. band line 9 | the band methods: the deep; nbflip's level set and resampling |
//! | [`FluidMethod::check_invariants`] | after the step | what the method guarantees |
//! | [`FluidMethod::finish_step`], [`MethodReport::record`], [`FluidMethod::summary`] | reporting | every method |
//!
//! Adding a method: one file in this folder with a type implementing [`MethodType`] and
//! [`FluidMethod`], and one line in the [`methods!`] list below.

use crate::grid::{MacField, Vector};
use crate::metrics::InvariantViolation;
use crate::record::layout::{LayerView, Panel};
use crate::record::Log;
use crate::sim::correct::band::BandMode;
use crate::sim::correct::problem::Directions;
use crate::sim::correct::Solver;
use crate::sim::markings::Markings;
use crate::sim::solids::ObstacleMode;
use crate::sim::{transfer, State};
use std::any::Any;
use std::fmt::Debug;
use std::path::PathBuf;

pub mod ccp;
pub mod flip;
pub mod idp;
pub mod nbflip;
pub mod powerpic;

/// Registers the methods (each module declared above, where `cargo fmt` sees it): makes
/// [`MethodKind`], the closed list of names that scene files (`simulation.method`) and the
/// command line (`--method`) accept.
macro_rules! methods {
    ($($module:ident :: $ty:ident),* $(,)?) => {
        /// The fluid methods a scene can run.
        #[derive(
            Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize,
            clap::ValueEnum,
        )]
        #[serde(rename_all = "kebab-case")]
        pub enum MethodKind {
            $(#[value(help = $module::$ty::INFO.about)] $ty,)*
        }

        impl MethodKind {
            pub const ALL: &'static [MethodKind] = &[$(MethodKind::$ty),*];

            /// What the method is and which options it takes.
            pub fn info(self) -> &'static MethodInfo {
                match self {
                    $(MethodKind::$ty => &$module::$ty::INFO,)*
                }
            }

            /// A new instance of the method for a `D`-dimensional simulation.
            pub fn build<const D: usize>(self, s: &MethodSettings) -> Box<dyn FluidMethod<D>> {
                match self {
                    $(MethodKind::$ty => $module::$ty::build::<D>(s),)*
                }
            }
        }
    };
}

methods! {
    flip::Flip,
    ccp::Ccp,
    idp::Idp,
    nbflip::Nbflip,
    powerpic::Powerpic,
}

impl MethodKind {
    pub fn name(self) -> &'static str {
        self.info().name
    }
}

/// The options of the command line and the scene file that only some methods have. A method
/// that has none of them refuses it (see [`MethodSettings::check_given`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodOption {
    Band,
    BandR,
    Solver,
    Directions,
    CrossCheck,
    ExportLp,
}

impl MethodOption {
    /// The option as the command line spells it.
    pub fn flag(self) -> &'static str {
        match self {
            MethodOption::Band => "--band",
            MethodOption::BandR => "--band-r",
            MethodOption::Solver => "--solver",
            MethodOption::Directions => "--directions",
            MethodOption::CrossCheck => "--cross-check",
            MethodOption::ExportLp => "--export-lp",
        }
    }
}

/// What a method is, for lists, help and checks.
#[derive(Debug)]
pub struct MethodInfo {
    /// Its name in scene files and on the command line.
    pub name: &'static str,
    /// One line: the method and its paper.
    pub about: &'static str,
    /// The method-specific options it takes.
    pub options: &'static [MethodOption],
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

/// The settings of the methods, as the scene file and the command line give them; each method
/// reads the ones it has ([`MethodInfo::options`]).
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSettings {
    pub kind: MethodKind,
    /// Solver of the correction step.
    pub solver: Solver,
    /// Candidate moves of the correction.
    pub directions: Directions,
    /// The band method (sec. band_method) and how its count is kept.
    pub band: BandMode,
    /// `R`: depth of the band interface; the band is `R + 1` cells thick.
    pub band_r: u32,
    /// Solve every correction twice (other solver, other band variants) and compare.
    pub cross_check: bool,
    /// Write the correction problem of this step as MPS to this path.
    pub export_lp: Option<(u64, PathBuf)>,
    /// IDP: resample degenerate cells (`simulation.idp_resample`).
    pub idp_resample: bool,
    /// Power PIC's parameters (`[simulation.powerpic]`).
    pub powerpic: powerpic::PowerPicSettings,
}

impl MethodSettings {
    /// Refuses options the method does not have: `given` lists the ones the user set
    /// explicitly. The error names the option and the method.
    pub fn check_given(&self, given: &[MethodOption]) -> Result<(), String> {
        let info = self.kind.info();
        match given.iter().find(|o| !info.options.contains(o)) {
            None => Ok(()),
            Some(o) => {
                let having: Vec<&str> = MethodKind::ALL
                    .iter()
                    .filter(|k| k.info().options.contains(o))
                    .map(|k| k.name())
                    .collect();
                Err(format!(
                    "{}: method '{}' has no such option (it is an option of {})",
                    o.flag(),
                    info.name,
                    having.join(", ")
                ))
            }
        }
    }
}

/// Registration of a method type: its description and how to build it.
pub trait MethodType {
    const INFO: MethodInfo;
    fn build<const D: usize>(settings: &MethodSettings) -> Box<dyn FluidMethod<D>>;
}

/// Per face component, whether a face holds a value (from particles, the projection or the
/// grid) or still needs one from extrapolation.
pub type Known<const D: usize> = [Vec<bool>; D];

/// One fluid method: the places where it departs from plain FLIP. Every hook has FLIP's
/// behaviour as its default.
pub trait FluidMethod<const D: usize>: Send {
    /// After seeding and the first markings.
    fn start(&mut self, _s: &mut State<D>) {}

    /// The particle count per cell that emitters top up to `mu`, when it is not the markings'
    /// count.
    fn emitter_counts(&self, _s: &State<D>) -> Option<Vec<u32>> {
        None
    }

    /// Particles seeded or emitted that the method accounts for without holding them: the
    /// band's imaginary particles of the deep (ccp), or what resampling deleted net of what it
    /// seeded (nbflip; negative when it seeded more). Particles held plus these are all particles
    /// ever seeded or emitted (checked every step).
    fn particles_not_held(&self) -> isize {
        0
    }

    /// Alg. flip line 1: particle velocities to the grid's faces, and which faces got one.
    fn particles_to_grid(&mut self, s: &State<D>) -> anyhow::Result<(MacField<D>, Known<D>)> {
        Ok(transfer::particles_to_grid(
            &s.grid,
            &s.particles.pos,
            &s.particles.vel,
        ))
    }

    /// After the pressure projection, with the projected velocity.
    fn after_projection(&mut self, _s: &mut State<D>, _u: &mut MacField<D>) {}

    /// Alg. flip line 4: the grid velocity back to the particles (`u_old` is the field before
    /// forces and projection), their speeds bounded by `max_speed` (checked after every step's
    /// transfer: [`crate::metrics::check_speed_bound`]). Returns true when it wrote
    /// `u(x_p)` per particle to `at` and the particles have not moved, for the advection (line
    /// 5) to use instead of interpolating `u` again at the same points.
    fn grid_to_particles(
        &mut self,
        s: &mut State<D>,
        u: &MacField<D>,
        u_old: &MacField<D>,
        at: &mut Vec<Vector<D>>,
    ) -> bool {
        let blend = transfer::Blend {
            flip_ratio: s.config.flip_ratio,
            max_speed: s.config.max_speed,
        };
        transfer::grid_to_particles(&s.grid, u, u_old, blend, &mut s.particles, at);
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
        _s: &mut State<D>,
        _penalty: Option<&[f64]>,
    ) -> anyhow::Result<()> {
        Ok(())
    }

    /// Just before new markings are computed from the particles (`s.markings` are still the
    /// previous ones): the method may resample its particles (nbflip) and returns the cells
    /// that stay fluid even without particles.
    fn before_markings(&mut self, _s: &mut State<D>) -> Option<Vec<bool>> {
        None
    }

    /// After new markings were computed (after emission and at the end of the step);
    /// `previous` are the markings they replace.
    fn after_markings(&mut self, _s: &mut State<D>, _previous: &Markings) {}

    /// The invariants this method guarantees beyond those of every method.
    fn check_invariants(&self, _s: &State<D>) -> Result<(), InvariantViolation> {
        Ok(())
    }

    /// Ends the step: what the method did in it, as one value.
    fn finish_step(&mut self, _s: &State<D>) -> Box<dyn MethodReport<D>> {
        Box::new(NoReport)
    }

    /// Static recording data (class colours of its layers).
    fn record_setup(&self, _log: &mut dyn Log<D>) {}

    /// Whether cell `c` is in the method's deep: fluid below its band, whose particles it does
    /// not hold. Recordings draw it as its own class in the markings rather than as a bubble.
    fn is_deep(&self, _s: &State<D>, _c: usize) -> bool {
        false
    }

    /// Lines for the run's summary, from everything the method did since the start or the
    /// last [`FluidMethod::reset_summary`].
    fn summary(&self) -> Vec<String> {
        vec![]
    }

    /// Forgets what the summary has gathered so far (after a warm-up).
    fn reset_summary(&mut self) {}
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    #[test]
    fn registered_names_are_the_names_scene_files_and_the_command_line_accept() {
        for k in MethodKind::ALL {
            let clap_name = k.to_possible_value().unwrap().get_name().to_string();
            assert_eq!(clap_name, k.name());
            let toml: MethodKind = serde_json_like(k.name());
            assert_eq!(toml, *k);
        }
    }

    fn serde_json_like(name: &str) -> MethodKind {
        #[derive(serde::Deserialize)]
        struct W {
            m: MethodKind,
        }
        toml::from_str::<W>(&format!("m = \"{name}\"")).unwrap().m
    }

    #[test]
    fn an_option_the_method_lacks_is_refused_naming_both() {
        let s = MethodSettings {
            kind: MethodKind::Flip,
            solver: Solver::Flow,
            directions: Directions::VonNeumann,
            band: BandMode::None,
            band_r: 3,
            cross_check: false,
            export_lp: None,
            idp_resample: false,
            powerpic: Default::default(),
        };
        let e = s.check_given(&[MethodOption::Band]).unwrap_err();
        assert!(e.contains("--band") && e.contains("'flip'") && e.contains("ccp"));
        let ccp = MethodSettings {
            kind: MethodKind::Ccp,
            ..s
        };
        assert!(ccp
            .check_given(&[MethodOption::Band, MethodOption::ExportLp])
            .is_ok());
    }
}
