//! The scene file's `[simulation]` table: the settings of every method's run, the method's own
//! keys the file may give there, and a table per registered method (`[simulation.<method>]`,
//! its `Settings` as serde reads them), made from the registry (`crate::methods::registry`).

use crate::methods::{MethodKind, MethodSettings, MethodType};
use crate::solvers::pcg::Preconditioner;
use crate::stages::solids::ObstacleMode;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

macro_rules! simulation_file {
    ($($module:ident :: $ty:ident),*) => {
        /// `[simulation]` as written.
        #[derive(Clone, Debug, Deserialize, Serialize)]
        #[serde(deny_unknown_fields, default)]
        pub struct SimulationFile {
            pub method: MethodKind,
            /// Simulated time in seconds.
            pub duration: f64,
            /// Particles per cell, `mu`; must be `k^dim` for a whole `k`.
            pub ppc: usize,
            /// Seeding jitter, a fraction of the sub-cell spacing in [0, 0.5).
            pub jitter: f64,
            /// m/s^2 per axis; defaults to 9.81 down axis 1 (y is up, as in the paper).
            pub gravity: Option<Vec<f64>>,
            /// FLIP share of the FLIP/PIC velocity blend, in [0, 1].
            pub flip_ratio: f64,
            /// Largest motion per step in cells, in (0, 1].
            pub cfl: f64,
            /// Largest time step in seconds.
            pub max_dt: f64,
            /// Bound on the fluid speed, m/s.
            pub max_speed: f64,
            /// Relative tolerance of the pressure solve.
            pub pressure_tolerance: f64,
            /// CG's preconditioner in the pressure solve and idp's second solve, for every
            /// method: auto (the default: multigrid from 10,000 unknown rows in 2D and 100,000
            /// in 3D, where it was measured faster, mic0 below; `Preconditioner::AUTO_ROWS`),
            /// mic0 (modified incomplete Cholesky) or multigrid (a geometric V-cycle, McAdams,
            /// Sifakis and Teran 2010: an iteration count nearly independent of the grid, and
            /// parallel). All stop at `pressure_tolerance`; results differ within it.
            pub pressure_preconditioner: Preconditioner,
            /// Whether each pressure solve starts CG from the last step's pressure (the
            /// default) rather than from zero. Both stop at `pressure_tolerance`; results
            /// differ within it. Written out only when off, so that a scene written before the
            /// key existed keeps its text (and `report`'s job names, which digest it).
            #[serde(skip_serializing_if = "is_true")]
            pub pressure_warm_start: bool,
            pub seed: u64,
            /// How obstacles get through particles: couple (method ccp, sec. 7), or for the
            /// other methods naive (wait until the way is free) or ignore (move regardless).
            /// Default: the method's first mode ([`crate::methods::MethodInfo::obstacle_modes`]).
            #[serde(skip_serializing_if = "Option::is_none")]
            pub obstacle: Option<ObstacleMode>,
            /// The method keys of [`SimulationFile::scene_keys`], read by the tables they set.
            #[serde(skip_serializing_if = "Option::is_none")]
            pub solver: Option<toml::Value>,
            #[serde(skip_serializing_if = "Option::is_none")]
            pub directions: Option<toml::Value>,
            #[serde(skip_serializing_if = "Option::is_none")]
            pub band: Option<toml::Value>,
            #[serde(skip_serializing_if = "Option::is_none")]
            pub band_r: Option<toml::Value>,
            #[serde(skip_serializing_if = "Option::is_none")]
            pub idp_resample: Option<toml::Value>,
            $(
                #[doc = concat!("`[simulation.", stringify!($module), "]`: method ",
                    stringify!($module), "'s settings whenever it runs the scene (its own \
                    method, `--method`, `cellflip report`), unset keys at their defaults.")]
                #[serde(skip_serializing_if = "Option::is_none")]
                pub $module: Option<<crate::methods::$module::$ty as MethodType>::Settings>,
            )*
        }

        impl Default for SimulationFile {
            fn default() -> Self {
                Self {
                    method: MethodKind::Flip,
                    duration: 2.0,
                    ppc: 4,
                    jitter: 0.1,
                    gravity: None,
                    flip_ratio: 0.9,
                    cfl: 1.0,
                    max_dt: 0.01,
                    max_speed: 10.0,
                    pressure_tolerance: 1e-9,
                    pressure_preconditioner: Preconditioner::Auto,
                    pressure_warm_start: true,
                    seed: 1,
                    obstacle: None,
                    solver: None,
                    directions: None,
                    band: None,
                    band_r: None,
                    idp_resample: None,
                    $($module: None,)*
                }
            }
        }

        impl SimulationFile {
            /// Whether the file has method `kind`'s table.
            pub fn has_table(&self, kind: MethodKind) -> bool {
                match kind {
                    $(MethodKind::$ty => self.$module.is_some(),)*
                }
            }

            /// Each method's settings: its table, or else its defaults with the method keys
            /// the file gives ([`SimulationFile::scene_keys`]).
            pub fn method_settings(&self) -> Result<MethodSettings, BadValue> {
                let keys = self.scene_keys();
                Ok(MethodSettings {
                    kind: self.method,
                    $($module: match &self.$module {
                        Some(table) => table.clone(),
                        None => with_keys(&keys)?,
                    },)*
                })
            }

            /// The file as run with `m`: every method's table as it ran, and none of the method
            /// keys of [`SimulationFile::scene_keys`] (their values are in the tables).
            pub fn with_tables(&self, m: &MethodSettings) -> Self {
                Self {
                    solver: None,
                    directions: None,
                    band: None,
                    band_r: None,
                    idp_resample: None,
                    $($module: Some(m.$module.clone()),)*
                    ..self.clone()
                }
            }
        }
    };
}
crate::methods::registry!(simulation_file);

/// A method key the file gives directly in `[simulation]`: its name there, the key it sets in
/// the tables, and its value.
pub struct SceneKey<'a> {
    pub name: &'static str,
    pub table_key: &'static str,
    pub value: &'a toml::Value,
}

impl SimulationFile {
    /// The method keys the file gives directly in `[simulation]`. They predate the tables (a
    /// new option belongs in its method's table only); each sets the key of the name given here
    /// in every method's table that has it. The file's own method must have it, and one that
    /// has its table sets it there instead.
    pub fn scene_keys(&self) -> Vec<SceneKey<'_>> {
        let keys = [
            ("solver", "solver", &self.solver),
            ("directions", "directions", &self.directions),
            ("band", "band", &self.band),
            ("band_r", "band_r", &self.band_r),
            ("idp_resample", "resample", &self.idp_resample),
        ];
        let given = keys.into_iter().filter_map(|(name, table_key, v)| {
            let value = v.as_ref()?;
            Some(SceneKey {
                name,
                table_key,
                value,
            })
        });
        given.collect()
    }
}

/// A method key given in `[simulation]` whose value the tables refuse (of the wrong type, or an unknown
/// name): the key and why.
#[derive(Debug)]
pub struct BadValue {
    pub key: &'static str,
    pub reason: String,
}

/// Whether a flag is on (for `skip_serializing_if`: a key that is on by default).
fn is_true(flag: &bool) -> bool {
    *flag
}

/// A method's default settings with the scene keys its table has set.
fn with_keys<S: Serialize + DeserializeOwned + Default>(keys: &[SceneKey]) -> Result<S, BadValue> {
    keys.iter().try_fold(S::default(), |settings, k| {
        let mut table = toml::Table::try_from(&settings).expect("settings are a table");
        if !table.contains_key(k.table_key) {
            return Ok(settings);
        }
        table.insert(k.table_key.into(), k.value.clone());
        table.try_into().map_err(|e: toml::de::Error| BadValue {
            key: k.name,
            reason: e.message().to_string(),
        })
    })
}
