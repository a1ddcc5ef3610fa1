//! The fluid methods, behind one seam.
//!
//! Every method here is PIC/FLIP on a MAC grid (paper alg. flip) plus something; they differ
//! only at the places where alg. flip and alg. band let them differ, and those places are the
//! hooks of two traits. [`FluidMethod`] holds the step's hooks:
//!
//! | hook | alg. flip / alg. band | who uses it |
//! |---|---|---|
//! | [`FluidMethod::start`] | after the first markings | ccp with the band: first exchange with the deep |
//! | [`FluidMethod::emitter_counts`] | emission | the band methods: the deep counts as full |
//! | [`FluidMethod::particles_not_held`] | the particle-count invariant | ccp's deep, nbflip's resampling |
//! | [`FluidMethod::particles_to_grid`] | line 1 | ccp with the band: the velocity combination |
//! | [`FluidMethod::grid_to_particles`] | line 4 | FLIP/PIC blend by default |
//! | [`FluidMethod::before_advection`], [`FluidMethod::next_grid_velocity`] | line 5 | ccp keeps `x_bar`; the band advects the grid velocity |
//! | [`FluidMethod::correct_positions`] | line 6 | ccp: eq. problem3 and the band corrections |
//! | [`FluidMethod::before_markings`], [`FluidMethod::after_markings`] | line 7, alg. band line 9 | the band methods: the deep; nbflip's level set and resampling |
//! | [`FluidMethod::check_invariants`] | after the step | what the method guarantees |
//! | [`FluidMethod::finish_step`] | after the step | what the method did, as a [`MethodReport`] |
//!
//! What a method records and sums up is apart from its step: [`MethodRecording`]
//! ([`MethodRecording::record_setup`]: its layers' classes; [`MethodRecording::is_deep`]: the
//! cells it holds no particles in), [`MethodReport::record`] (one step's scalars and drawings,
//! in the vocabulary of [`crate::draw`]) and [`MethodSummary`] (the run's totals, gathered from
//! the reports).
//!
//! Adding a method: a folder here whose `mod.rs` registers a type implementing [`MethodType`]
//! (its [`MethodInfo`], its `Settings` type with their `check`, how to build its step and its
//! summary), with its step in `physics.rs` (implementing [`FluidMethod`] and
//! [`MethodRecording`]) and its recording in `record.rs` (its panels, its [`MethodReport`] and
//! [`MethodSummary`]); then one line in the [`methods!`] list below, which makes its settings
//! a field of [`MethodSettings`] named after its folder. `flip` is the smallest example, `idp`
//! a typical one. An option of the command line or the scene file that only some methods have
//! is a [`MethodOption`], listed in their [`MethodInfo::options`]: the others refuse it in the
//! same words on both input paths ([`MethodKind::refusal`]).

pub mod ccp;
mod cost;
pub mod flip;
pub mod idp;
pub mod nbflip;
pub mod powerpic;
mod seam;

pub use cost::{Footprint, Holds, StartPeak, StepCost};
pub use seam::{
    FluidMethod, MethodInfo, MethodOption, MethodRecording, MethodReport, MethodSummary,
    MethodType, NoReport, NoSummary, SettingContext, SettingError,
};

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

        /// The settings of every method, as the scene file and the command line give them: the
        /// method to run and, per method, its own settings ([`MethodType::Settings`]).
        #[derive(Clone, Debug, PartialEq)]
        pub struct MethodSettings {
            pub kind: MethodKind,
            $(pub $module: <$module::$ty as MethodType>::Settings,)*
        }

        impl MethodSettings {
            /// `kind` with every method's default settings.
            pub fn new(kind: MethodKind) -> Self {
                Self { kind, $($module: Default::default(),)* }
            }

            /// The peak memory of the method to run ([`MethodType::footprint`]).
            pub fn footprint(&self, dim: usize) -> Footprint {
                match self.kind {
                    $(MethodKind::$ty => $module::$ty::footprint(&self.$module, dim),)*
                }
            }

            /// The wall time per step of the method to run ([`MethodType::step_cost`]).
            pub fn step_cost(&self, dim: usize) -> StepCost {
                match self.kind {
                    $(MethodKind::$ty => $module::$ty::step_cost(&self.$module, dim),)*
                }
            }

            /// The checks of the settings of the method to run ([`MethodType::check`]).
            pub fn check(&self, ctx: SettingContext) -> Result<(), SettingError> {
                match self.kind {
                    $(MethodKind::$ty => $module::$ty::check(&self.$module, ctx),)*
                }
            }
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
                    $(MethodKind::$ty => $module::$ty::build::<D>(&s.$module),)*
                }
            }

            /// An empty summary of what the method does over a run.
            pub fn summary<const D: usize>(self, s: &MethodSettings) -> Box<dyn MethodSummary<D>> {
                match self {
                    $(MethodKind::$ty => $module::$ty::summary::<D>(&s.$module),)*
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

    /// The method's colour (RGB), by its place in the registry: the same in the report's plots
    /// and in its recording.
    pub fn rgb(self) -> [u8; 3] {
        const PALETTE: [[u8; 3]; 6] = [
            [31, 119, 180],
            [214, 39, 40],
            [44, 160, 44],
            [148, 103, 189],
            [255, 127, 14],
            [23, 190, 207],
        ];
        let i = MethodKind::ALL.iter().position(|m| *m == self).unwrap_or(0);
        PALETTE[i % PALETTE.len()]
    }
}

impl MethodKind {
    /// Why this method refuses `option`, or `None` when it has it: the same words whether the
    /// option came from the command line or the scene file.
    pub fn refusal(self, option: MethodOption) -> Option<NoSuchOption> {
        if self.info().options.contains(&option) {
            return None;
        }
        let having = MethodKind::ALL
            .iter()
            .filter(|k| k.info().options.contains(&option))
            .map(|k| k.name())
            .collect();
        Some(NoSuchOption {
            method: self,
            having,
        })
    }
}

/// A method asked for an option it does not have.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "method '{}' has no such option (it is an option of {})",
    .method.name(),
    .having.join(", ")
)]
pub struct NoSuchOption {
    pub method: MethodKind,
    /// The methods that have it.
    pub having: Vec<&'static str>,
}

/// An option the user set that the method does not have ([`MethodSettings::check_given`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}: {why}", .option.name())]
pub struct OptionRefused {
    pub option: MethodOption,
    pub why: NoSuchOption,
}

impl MethodSettings {
    /// The band the run keeps: ccp's band mode when ccp runs, none for the other methods (whose
    /// scene files may configure ccp's band for when ccp runs them).
    pub fn band(&self) -> ccp::BandMode {
        match self.kind {
            MethodKind::Ccp => self.ccp.band,
            _ => ccp::BandMode::None,
        }
    }

    /// Refuses options the method does not have: `given` lists the ones the user set
    /// explicitly. The error names the option and the method.
    pub fn check_given(&self, given: &[MethodOption]) -> Result<(), OptionRefused> {
        let refused = given.iter().find_map(|&option| {
            let why = self.kind.refusal(option)?;
            Some(OptionRefused { option, why })
        });
        refused.map_or(Ok(()), Err)
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
        let s = MethodSettings::new(MethodKind::Flip);
        let e = s.check_given(&[MethodOption::Band]).unwrap_err();
        assert_eq!(e.option, MethodOption::Band);
        assert_eq!(e.why.method, MethodKind::Flip);
        assert_eq!(e.why.having, ["ccp"]);
        let said = e.to_string();
        assert!(said.contains("--band") && said.contains("'flip'") && said.contains("ccp"));
        let ccp = MethodSettings {
            kind: MethodKind::Ccp,
            ..s
        };
        assert!(ccp
            .check_given(&[MethodOption::Band, MethodOption::ExportLp])
            .is_ok());
    }
}
