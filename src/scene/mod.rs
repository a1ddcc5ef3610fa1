//! Scene files: TOML as written -> checked ([`check`]) -> [`SimConfig`] in grid units.
//!
//! Scene files speak SI (metres, seconds, m/s^2) and cells per axis; everything below this
//! module works in grid units. All checks of user input live here, and every error is a
//! [`SceneError`] that names the file, the key and the reason.

mod check;
mod limits;
mod memory;
mod tables;

pub use check::{ErrorKind, SceneError};
pub use memory::{ensure_fit, peak_memory_mib, MemoryEstimate};
pub use tables::SimulationFile;

use crate::grid::Vector;
use crate::methods::{MethodFlags, MethodKind, MethodSettings};
use crate::particles::{Region, SpiralBlock};
use crate::solvers::pcg::Preconditioner;
use crate::stages::emit::Emitter;
use crate::stages::solids::{Motion, Obstacle, ObstacleMode};
use crate::stages::SimConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `(name, text)` of each scene file `scenes/<name>.toml`, embedded into the binary.
macro_rules! built_in {
    ($($name:literal),* $(,)?) => {
        &[$(($name, include_str!(concat!("../../scenes/", $name, ".toml")))),*]
    };
}

/// The built-in scenes, embedded from `scenes/`.
pub const BUILT_IN: &[(&str, &str)] = built_in![
    "dam-2d",
    "dam-1ppc-2d",
    "dam-3d",
    "compress-2d",
    "spiral-2d",
    "falling-obstacle-2d",
    "falling-obstacle-3d",
    "falling-obstacle-zero-bc-2d",
    "large-obstacle-2d",
    "large-obstacle-3d",
    "drop-2d",
    "drop-3d",
    "hydrostatic-2d",
    "martin-moyce-2d",
    "deep-pool-2d",
    "deep-pool-3d",
];

/// Why a scene does not load.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("cannot read scene file '{path}'")]
    Read {
        path: String,
        #[source]
        error: std::io::Error,
    },
    #[error(
        "unknown scene '{name}': not a built-in scene ({}) and not a .toml file",
        built_in_names()
    )]
    Unknown { name: String },
    #[error(transparent)]
    Scene(#[from] SceneError),
}

fn built_in_names() -> String {
    BUILT_IN
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The rate at which a falling obstacle approaches its terminal speed in the water, 1/s,
/// unless `obstacle.drag` says otherwise.
pub const DEFAULT_DRAG: f64 = 10.0;

/// A scene file as written.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// 2 or 3.
    pub dim: usize,
    pub domain: DomainFile,
    #[serde(default)]
    pub simulation: SimulationFile,
    /// Regions filled with fluid at the start.
    #[serde(default)]
    pub fluid: Vec<RegionFile>,
    /// Static solid regions (cells whose centre is inside are solid).
    #[serde(default)]
    pub solid: Vec<RegionFile>,
    #[serde(default)]
    pub emitter: Vec<EmitterFile>,
    /// Moving obstacles (sec. 7).
    #[serde(default)]
    pub obstacle: Vec<ObstacleFile>,
}

/// A moving box (`min`, `max`) or ball (`center`, `radius`), in metres, with a velocity.
/// The shape keys repeat [`RegionFile`]'s because serde cannot flatten a struct into one that
/// rejects unknown keys.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleFile {
    /// Names the obstacle in recordings (`world/obstacles/<name>`).
    pub name: String,
    /// A box or a ball (no spiral).
    pub shape: Shape,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub center: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// m/s: constant, or the start velocity of a falling obstacle.
    pub velocity: Vec<f64>,
    /// Constant, or falling: gravity in the air, then buoyancy and drag towards
    /// `terminal_speed` in the water (a dense object, sec. 7).
    #[serde(default)]
    pub motion: MotionKind,
    /// Falling: the speed it settles to in the water, m/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_speed: Option<f64>,
    /// Falling: how fast it approaches the terminal speed in the water, 1/s (default 10).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drag: Option<f64>,
    /// The zero-velocity variant: the pressure solve sees the obstacle at rest.
    #[serde(default)]
    pub zero_velocity_bc: bool,
}

/// The shape of a region.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// `min`, `max`.
    #[default]
    Box,
    /// `center`, `radius`.
    Ball,
    /// A 2D static solid only: a box with a spiral channel (see [`SpiralBlock`]).
    Spiral,
}

impl Shape {
    pub fn name(self) -> &'static str {
        match self {
            Shape::Box => "box",
            Shape::Ball => "ball",
            Shape::Spiral => "spiral",
        }
    }
}

/// How an obstacle's velocity evolves (`obstacle.motion`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotionKind {
    #[default]
    Constant,
    Falling,
}

impl ObstacleFile {
    /// Its shape as a region.
    pub fn region(&self) -> RegionFile {
        RegionFile {
            shape: self.shape,
            min: self.min.clone(),
            max: self.max.clone(),
            center: self.center.clone(),
            radius: self.radius,
            turns: None,
            width: None,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DomainFile {
    /// Extent of the tank in metres, one entry per axis; the tank spans `[0, size]`.
    pub size: Vec<f64>,
    /// Cells along the longest axis; the others get the same cell size.
    pub cells: usize,
}

/// A box (`min`, `max`) or a ball (`center`, `radius`), in metres.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RegionFile {
    /// Box (`min`, `max`), ball (`center`, `radius`), or, for a 2D solid only, spiral: the
    /// box `min`..`max` with a spiral channel carved into it, centred at `center`, its centre
    /// line starting `radius` above the centre and winding `turns` times inwards, the channel
    /// `width` wide and open to the box's top face (see [`SpiralBlock`]).
    pub shape: Shape,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub center: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Spiral: how many times the channel winds around the centre.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub turns: Option<f64>,
    /// Spiral: the channel's width, metres; at least two cells, and the walls between turns
    /// (`radius / (turns + 1/2) - width`) too.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub width: Option<f64>,
}

/// A box that injects particles at `velocity` from `start` to `stop` seconds.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EmitterFile {
    pub min: Vec<f64>,
    pub max: Vec<f64>,
    /// m/s.
    pub velocity: Vec<f64>,
    #[serde(default)]
    pub start: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stop: Option<f64>,
    /// Stop when the scene holds `until_fill * mu * cells` particles (0.5: half the tank).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub until_fill: Option<f64>,
}

/// Command-line overrides of scene values.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    pub method: Option<MethodKind>,
    pub duration: Option<f64>,
    pub cells: Option<usize>,
    pub ppc: Option<usize>,
    pub seed: Option<u64>,
    pub obstacle: Option<ObstacleMode>,
    /// `simulation.pressure_preconditioner`.
    pub pressure: Option<Preconditioner>,
    /// The methods' flags, applied to their settings after the file's.
    pub flags: MethodFlags,
}

/// A scene ready to run: its source, the file with overrides applied, and its checked values.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Where it came from: `built-in:NAME` or the file path.
    pub source: String,
    pub file: SceneFile,
    pub dims: Vec<usize>,
    pub cell_size_m: f64,
    /// The method and its settings.
    pub method: MethodSettings,
    pub obstacle_mode: ObstacleMode,
}

impl Overrides {
    /// Writes the overrides but the methods' flags into the scene file, and the default gravity
    /// where it has none.
    pub(crate) fn apply(&self, file: &mut SceneFile) {
        let sim = &mut file.simulation;
        macro_rules! set {
            ($($field:ident),*) => {
                $(if let Some(v) = &self.$field {
                    sim.$field = *v;
                })*
            };
        }
        set!(method, duration, ppc, seed);
        if let Some(m) = self.obstacle {
            sim.obstacle = Some(m);
        }
        if let Some(p) = self.pressure {
            sim.pressure_preconditioner = p;
        }
        if let Some(c) = self.cells {
            file.domain.cells = c;
        }
        // The default gravity (an unchecked `dim` gets none: the check refuses it).
        if sim.gravity.is_none() && (2..=3).contains(&file.dim) {
            let mut g = vec![0.0; file.dim];
            if file.dim > 1 {
                g[1] = -9.81;
            }
            sim.gravity = Some(g);
        }
    }
}

impl Scene {
    pub fn name(&self) -> &str {
        &self.file.name
    }

    pub fn dim(&self) -> usize {
        self.file.dim
    }

    /// What tells runs of this scene apart, in order: scene, method, band and its `R` (with a
    /// band), cells per axis, particles per cell and seed, e.g. `dam-3d ccp band-paths r6
    /// 50x50x50 ppc8 seed1`. Names recordings and exported problems.
    pub fn run_tags(&self) -> Vec<String> {
        let mut tags = vec![self.name().to_string(), self.method.kind.name().to_string()];
        if let Some(band) = self.method.band() {
            tags.push(format!("band-{}", band.variant));
            tags.push(format!("r{}", band.r));
        }
        let cells: Vec<String> = self.dims.iter().map(usize::to_string).collect();
        tags.push(cells.join("x"));
        tags.push(format!("ppc{}", self.file.simulation.ppc));
        tags.push(format!("seed{}", self.file.simulation.seed));
        tags
    }

    pub fn duration_secs(&self) -> f64 {
        self.file.simulation.duration
    }

    /// The scene as run, as TOML (defaults and overrides filled in).
    pub fn resolved_toml(&self) -> String {
        toml::to_string_pretty(&self.file).expect("a scene file always serialises")
    }

    /// Loads a built-in scene by name, or a scene file by path.
    pub fn load(name_or_path: &str, overrides: &Overrides) -> Result<Scene, LoadError> {
        let (source, text) = if let Some((_, text)) =
            BUILT_IN.iter().find(|(n, _)| *n == name_or_path)
        {
            (format!("built-in scene '{name_or_path}'"), text.to_string())
        } else if name_or_path.ends_with(".toml") || Path::new(name_or_path).exists() {
            let text = std::fs::read_to_string(name_or_path).map_err(|error| LoadError::Read {
                path: name_or_path.into(),
                error,
            })?;
            (format!("scene file '{name_or_path}'"), text)
        } else {
            let name = name_or_path.into();
            return Err(LoadError::Unknown { name });
        };
        Ok(Self::parse(&source, &text, overrides)?)
    }

    /// Parses and checks scene text; `source` names it in errors. The method keys the file
    /// sets are checked against the file's own method, before the command line's overrides
    /// (whose flags the commands check against the method run).
    pub fn parse(source: &str, text: &str, overrides: &Overrides) -> Result<Scene, SceneError> {
        let file: SceneFile =
            toml::from_str(text).map_err(|e| check::toml_error(source, text, &e))?;
        check::method_keys(source, &file.simulation)?;
        Self::checked(source, file, overrides)
    }

    /// The scene as run, from its [`Scene::resolved_toml`] (a checkpoint's) with `overrides`:
    /// checked as any scene.
    pub fn parse_resolved(
        source: &str,
        text: &str,
        overrides: &Overrides,
    ) -> Result<Scene, SceneError> {
        let file: SceneFile =
            toml::from_str(text).map_err(|e| check::toml_error(source, text, &e))?;
        Self::checked(source, file, overrides)
    }

    /// The file with `overrides` applied, checked; its `[simulation]` then holds every method's
    /// table as it runs ([`SimulationFile::with_tables`]).
    fn checked(
        source: &str,
        mut file: SceneFile,
        overrides: &Overrides,
    ) -> Result<Scene, SceneError> {
        overrides.apply(&mut file);
        let mut scene = check::check(source, file, &overrides.flags)?;
        scene.file.simulation = scene.file.simulation.with_tables(&scene.method);
        Ok(scene)
    }

    /// The configuration in grid units.
    pub fn config<const D: usize>(&self) -> SimConfig<D> {
        assert_eq!(D, self.dim(), "scene dimension");
        let h = self.cell_size_m;
        let s = &self.file.simulation;
        let vec = |v: &[f64]| Vector::<D>::from_fn(|k, _| v[k] / h);
        let region = |r: &RegionFile| match r.shape {
            Shape::Box => Region::Box {
                min: vec(r.min.as_deref().unwrap()),
                max: vec(r.max.as_deref().unwrap()),
            },
            Shape::Ball => Region::Ball {
                center: vec(r.center.as_deref().unwrap()),
                radius: r.radius.unwrap() / h,
            },
            Shape::Spiral => Region::Spiral(SpiralBlock {
                min: vec(r.min.as_deref().unwrap()),
                max: vec(r.max.as_deref().unwrap()),
                center: vec(r.center.as_deref().unwrap()),
                radius: r.radius.unwrap() / h,
                turns: r.turns.unwrap(),
                width: r.width.unwrap() / h,
            }),
        };
        let dims: [usize; D] = std::array::from_fn(|k| self.dims[k]);
        let per_axis = check::ppc_per_axis(s.ppc, D).unwrap();
        let cells: usize = dims.iter().product();
        SimConfig {
            dims,
            cell_size_m: h,
            per_axis,
            jitter: s.jitter,
            gravity: vec(s.gravity.as_deref().unwrap()),
            flip_ratio: s.flip_ratio,
            cfl: s.cfl,
            max_dt_secs: s.max_dt,
            max_speed: s.max_speed / h,
            pressure_tolerance: s.pressure_tolerance,
            pressure_preconditioner: s.pressure_preconditioner,
            pressure_warm_start: s.pressure_warm_start,
            seed: s.seed,
            fluid: self.file.fluid.iter().map(region).collect(),
            solids: self.file.solid.iter().map(region).collect(),
            emitters: self
                .file
                .emitter
                .iter()
                .map(|e| Emitter {
                    region: Region::Box {
                        min: vec(&e.min),
                        max: vec(&e.max),
                    },
                    velocity: vec(&e.velocity),
                    start_secs: e.start,
                    stop_secs: e.stop.unwrap_or(f64::INFINITY),
                    until_particles: e
                        .until_fill
                        .map(|f| (f * (s.ppc * cells) as f64).round() as usize),
                })
                .collect(),
            obstacles: self
                .file
                .obstacle
                .iter()
                .map(|o| Obstacle {
                    name: o.name.clone(),
                    shape: region(&o.region()),
                    offset: Vector::<D>::zeros(),
                    velocity: vec(&o.velocity),
                    motion: match o.motion {
                        MotionKind::Falling => Motion::Falling {
                            terminal_speed: o.terminal_speed.unwrap() / h,
                            drag: o.drag.unwrap_or(DEFAULT_DRAG),
                        },
                        MotionKind::Constant => Motion::Constant,
                    },
                    zero_velocity_bc: o.zero_velocity_bc,
                })
                .collect(),
            obstacle_mode: self.obstacle_mode,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_scene_parses_and_converts() {
        for (name, _) in BUILT_IN {
            let s = Scene::load(name, &Overrides::default()).unwrap();
            assert_eq!(s.name(), *name);
            match s.dim() {
                2 => assert_eq!(s.config::<2>().dims.len(), 2),
                _ => assert_eq!(s.config::<3>().dims.len(), 3),
            }
            // The resolved TOML parses back to the same scene.
            let again =
                Scene::parse("resolved", &s.resolved_toml(), &Overrides::default()).unwrap();
            assert_eq!(again.dims, s.dims);
        }
    }

    /// A resumed run refuses a flag that changes its scene as run (`cmd::run::start`): a flag
    /// that repeats the run method's value must leave it as it was, even where another method
    /// declaring the same flag has another value in its table.
    #[test]
    fn a_flag_repeating_the_run_methods_value_leaves_the_scene_as_run_unchanged() {
        let text = "name = \"x\"\ndim = 2\n[domain]\nsize = [1.0, 1.0]\ncells = 24\n\
                    [simulation]\nmethod = \"ccp\"\n[simulation.ccp]\nband = \"paths\"\n\
                    band_r = 6\n[[fluid]]\nshape = \"box\"\nmin = [0.0, 0.0]\nmax = [1.0, 0.5]\n";
        let base = Scene::parse("x", text, &Overrides::default()).unwrap();
        assert_eq!((base.method.ccp.band_r, base.method.nbflip.band_r), (6, 3));
        let resolved = base.resolved_toml();
        let flag = |r: u32| Overrides {
            flags: MethodFlags::default().with("band-r", r),
            ..Default::default()
        };
        let same = Scene::parse_resolved("x", &resolved, &flag(6)).unwrap();
        assert_eq!(same.resolved_toml(), resolved);
        let other = Scene::parse_resolved("x", &resolved, &flag(5)).unwrap();
        assert_ne!(other.resolved_toml(), resolved);
        assert_eq!(
            (other.method.ccp.band_r, other.method.nbflip.band_r),
            (5, 3)
        );
    }

    #[test]
    fn the_pressure_preconditioner_comes_from_the_file_or_the_flag() {
        let dam = |o: &Overrides| Scene::load("dam-2d", o).unwrap().config::<2>();
        assert_eq!(
            dam(&Overrides::default()).pressure_preconditioner,
            Preconditioner::Auto
        );
        let flag = Overrides {
            pressure: Some(Preconditioner::Multigrid),
            ..Default::default()
        };
        let s = Scene::load("dam-2d", &flag).unwrap();
        assert_eq!(
            s.config::<2>().pressure_preconditioner,
            Preconditioner::Multigrid
        );
        // The resolved file names it, and reads back as a scene key.
        let toml = s.resolved_toml();
        assert!(
            toml.contains("pressure_preconditioner = \"multigrid\""),
            "{toml}"
        );
        let again = Scene::parse("resolved", &toml, &Overrides::default()).unwrap();
        assert_eq!(
            again.config::<2>().pressure_preconditioner,
            Preconditioner::Multigrid
        );
        let bad = toml.replace("\"multigrid\"", "\"amg\"");
        let e = Scene::parse("bad", &bad, &Overrides::default()).unwrap_err();
        assert!(
            format!("{e:#}").contains("pressure_preconditioner"),
            "{e:#}"
        );
    }
}
