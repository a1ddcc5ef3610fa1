//! The fluid methods, behind one seam.
//!
//! Every method here is PIC/FLIP on a MAC grid (paper alg. flip) plus something; they differ
//! only at the places where alg. flip and alg. band let them differ, and those places are the
//! hooks of two traits. [`FluidMethod`] holds the step's hooks:
//!
//! | hook | alg. flip / alg. band | who uses it |
//! |---|---|---|
//! | [`FluidMethod::start`] | after the first markings | ccp with the band: first exchange with the deep; nbflip: its first level set and resampling; powerpic: its transport grid |
//! | [`FluidMethod::emitter_count`] | emission | the band methods: the deep counts as full (asked for the cells of emitters that emit) |
//! | [`FluidMethod::particles_not_held`] | the particle-count invariant | ccp's deep, nbflip's resampling |
//! | [`FluidMethod::particles_to_grid`] | line 1 | the band methods: the velocity combination; powerpic: the transport |
//! | [`FluidMethod::grid_to_particles`] | line 4 | FLIP/PIC blend by default; powerpic: through the transport, and the move to the kernel's barycentre |
//! | [`FluidMethod::before_advection`], [`FluidMethod::next_grid_velocity`] | line 5 | ccp keeps `x_bar`; the band advects the grid velocity |
//! | [`FluidMethod::correct_positions`] | line 6 | ccp: eq. problem3 and the band corrections; idp: the density projection |
//! | [`FluidMethod::holds_liquid`] | line 6, the obstacles' move (sec. soilds) | nbflip: a `naive` obstacle waits for the level set's inside too |
//! | [`FluidMethod::before_markings`], [`FluidMethod::after_markings`] | line 7, alg. band line 9 | the band methods: the deep; nbflip's level set and resampling |
//! | [`FluidMethod::check_invariants`] | after the step | what the method guarantees |
//! | [`FluidMethod::finish_step`] | after the step | what the method did, as a [`MethodReport`] |
//! | [`FluidMethod::save_state`], [`FluidMethod::restore_state`] | a checkpoint | what it carries from one step to the next: ccp's deep and prices, nbflip's level set, powerpic's scalings |
//!
//! The hooks that change only the particles (lines 4 and 6, and the resampling before line 7)
//! get a [`crate::stages::ParticlesMut`]: the particles and the random stream mutable, the grid,
//! markings, solids and velocity read-only; `start` and `after_markings` may change the
//! markings too (the band's exchange with the deep), so they get the whole state.
//!
//! What a method records and sums up is apart from its step: [`MethodRecording`]
//! ([`MethodRecording::record_setup`]: its layers' classes; [`MethodRecording::is_deep`]: the
//! cells it holds no particles in), [`MethodReport::record`] (one step's scalars and drawings,
//! in the vocabulary of [`crate::draw`]) and [`MethodSummary`] (the run's totals, gathered from
//! the reports). A method writes no file: what a step hands over to be written (ccp's
//! exported problems) is in its report ([`MethodReport::exports`]), which the run's observer
//! writes.
//!
//! Adding a method: a folder here whose `mod.rs` registers a type implementing [`MethodType`]
//! (its [`MethodInfo`], its `Settings` type with their `check`, how to build its step and its
//! summary), with its step in `physics.rs` (implementing [`FluidMethod`] and
//! [`MethodRecording`]), its `Settings` in `settings.rs`, and its report types and
//! recording in `record.rs` (its panels, its [`MethodReport`] and [`MethodSummary`]); then one
//! line in the [`methods!`] list below, which makes its settings
//! a field of [`MethodSettings`] named after its folder. `flip` is the smallest example, `idp`
//! a typical one. Its options are declared once, beside its settings: the keys of its scene
//! table are its `Settings` as serde reads them, its flags are [`MethodType::FLAGS`]
//! ([`options`]); the scene file, the command line and the refusal of options the run's method
//! lacks ([`MethodKind::refusal`]) all come from there.

pub mod ccp;
mod cost;
pub mod flip;
pub mod idp;
pub mod nbflip;
pub mod options;
pub mod powerpic;
mod seam;

pub use cost::{Footprint, Holds, Rest, StartPeak, StepCost, Unit};
pub use options::{Flag, FlagValue, MethodFlags};
pub use seam::{
    BandChoice, Export, FluidMethod, MethodInfo, MethodRecording, MethodReport, MethodSummary,
    MethodType, NoReport, NoSettings, NoSummary, SettingContext, SettingError, StepFile,
};

/// Registers the methods (each module declared above, where `cargo fmt` sees it): makes
/// [`MethodKind`], the closed list of names that scene files (`simulation.method`) and the
/// command line (`--method`) accept, [`MethodSettings`], and `registry!`, which hands the list
/// to code that needs a field per method elsewhere (the scene file's tables).
macro_rules! methods {
    ($($module:ident :: $ty:ident),* $(,)?) => {
        methods!(@ ($) $($module::$ty),*);
    };
    (@ ($d:tt) $($module:ident :: $ty:ident),*) => {
        /// Calls `callback!(module::Type, ...)` with every registered method.
        macro_rules! registry {
            ($d callback:ident) => {
                $d callback!($($module::$ty),*);
            };
        }

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

            /// The band the method to run keeps ([`MethodType::band`]).
            pub fn band(&self) -> Option<BandChoice> {
                match self.kind {
                    $(MethodKind::$ty => $module::$ty::band(&self.$module),)*
                }
            }

            /// Whether the method to run cross-checks its solves ([`MethodType::cross_checks`]).
            pub fn cross_checks(&self) -> bool {
                match self.kind {
                    $(MethodKind::$ty => $module::$ty::cross_checks(&self.$module),)*
                }
            }

            /// The files the method to run writes, named after `stem` ([`MethodType::files`]).
            pub fn files(&mut self, stem: &std::path::Path) -> Vec<StepFile> {
                match self.kind {
                    $(MethodKind::$ty => $module::$ty::files(&mut self.$module, stem),)*
                }
            }

            /// Sets flag `name` of the method to run, if it declares it (the command line
            /// configures the run's method only, so a scene as run keeps the other methods'
            /// tables as its file gave them).
            pub fn apply_flag(&mut self, name: &str, value: &toml::Value) {
                match self.kind {
                    $(MethodKind::$ty => set_flag::<$module::$ty>(&mut self.$module, name, value),)*
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

            /// Whether the method declares flag `name`.
            pub fn declares_flag(self, name: &str) -> bool {
                match self {
                    $(MethodKind::$ty => $module::$ty::FLAGS.iter().any(|f| f.name == name),)*
                }
            }

            /// Every method's flags, once each, in registry order.
            pub fn flags() -> Vec<options::OfferedFlag> {
                let mut all: Vec<options::OfferedFlag> = vec![];
                $(for f in $module::$ty::FLAGS {
                    let i = match all.iter().position(|o| o.name == f.name) {
                        Some(i) => i,
                        None => {
                            all.push(options::OfferedFlag::new(f.name, f.value));
                            all.len() - 1
                        }
                    };
                    all[i].declared_by.push(($module::$ty::INFO.name, f.help));
                })*
                all
            }

            /// The keys of the method's scene table that its defaults write (an unset optional
            /// key is not among them).
            pub fn table_keys(self) -> Vec<String> {
                fn keys<S: serde::Serialize + Default>() -> Vec<String> {
                    let t = toml::Table::try_from(S::default()).expect("settings are a table");
                    t.keys().cloned().collect()
                }
                match self {
                    $(MethodKind::$ty => keys::<<$module::$ty as MethodType>::Settings>(),)*
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
pub(crate) use registry;

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
    /// Why this method refuses an option, or `None` when it has it (`has` tells which methods
    /// have it): the same words whether the option came from the command line or the scene file.
    pub fn refusal(self, has: impl Fn(MethodKind) -> bool) -> Option<NoSuchOption> {
        if has(self) {
            return None;
        }
        let having = MethodKind::ALL.iter().filter(|&&k| has(k));
        Some(NoSuchOption {
            method: self,
            having: having.map(|k| k.name()).collect(),
        })
    }
}

/// Sets flag `name` of method `M` in `settings`, if `M` declares it.
fn set_flag<M: MethodType>(settings: &mut M::Settings, name: &str, value: &toml::Value) {
    for f in M::FLAGS.iter().filter(|f| f.name == name) {
        (f.set)(settings, value.clone()).expect("a flag's value has the type its setter takes");
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

/// A flag the user gave that the method does not have ([`MethodSettings::check_flags`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("--{flag}: {why}")]
pub struct OptionRefused {
    /// The flag, without its dashes.
    pub flag: &'static str,
    pub why: NoSuchOption,
}

impl MethodSettings {
    /// Refuses flags the method to run does not declare. The error names the flag and the
    /// method.
    pub fn check_flags(&self, flags: &MethodFlags) -> Result<(), OptionRefused> {
        let refused = flags.0.iter().find_map(|&(name, _)| {
            let why = self.kind.refusal(|k| k.declares_flag(name))?;
            Some(OptionRefused { flag: name, why })
        });
        refused.map_or(Ok(()), Err)
    }

    /// Sets every flag given, in order.
    pub fn apply_flags(&mut self, flags: &MethodFlags) {
        for (name, value) in &flags.0 {
            self.apply_flag(name, value);
        }
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
    fn a_flag_the_method_lacks_is_refused_naming_both() {
        let s = MethodSettings::new(MethodKind::Flip);
        let band = MethodFlags(vec![("band", toml::Value::String("paths".into()))]);
        let e = s.check_flags(&band).unwrap_err();
        assert_eq!(e.flag, "band");
        assert_eq!(e.why.method, MethodKind::Flip);
        assert_eq!(e.why.having, ["ccp"]);
        let said = e.to_string();
        assert!(said.contains("--band") && said.contains("'flip'") && said.contains("ccp"));
        let mut ccp = MethodSettings {
            kind: MethodKind::Ccp,
            ..s
        };
        assert!(ccp.check_flags(&band).is_ok());
        ccp.apply_flags(&band);
        assert_eq!(ccp.band().map(|b| b.variant), Some("paths"));
    }

    #[test]
    fn a_flag_two_methods_declare_is_offered_once_and_sets_the_run_methods() {
        let flags = MethodKind::flags();
        let band_r: Vec<_> = flags.iter().filter(|f| f.name == "band-r").collect();
        assert_eq!(band_r.len(), 1);
        let by: Vec<&str> = band_r[0].declared_by.iter().map(|d| d.0).collect();
        assert_eq!(by, ["ccp", "nbflip"]);
        let r = MethodFlags::default().with("band-r", 5u32);
        let (default_r, mut s) = (
            crate::stages::band::DEFAULT_BAND_R,
            MethodSettings::new(MethodKind::Nbflip),
        );
        s.apply_flags(&r);
        assert_eq!((s.ccp.band_r, s.nbflip.band_r), (default_r, 5));
        let mut s = MethodSettings::new(MethodKind::Ccp);
        s.apply_flags(&r);
        assert_eq!((s.ccp.band_r, s.nbflip.band_r), (5, default_r));
    }
}
