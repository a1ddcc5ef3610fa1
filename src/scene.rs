//! Scene files: TOML as written -> checked -> [`SimConfig`] in grid units.
//!
//! Scene files speak SI (metres, seconds, m/s^2) and cells per axis; everything below this
//! module works in grid units. All checks of user input live here, and every error names the
//! file, the key and the reason.

use crate::grid::{Grid, Vector};
use crate::particles::{self, Region, SpiralBlock};
use crate::sim::band::BandSettings;
use crate::sim::correct::band::BandVariant;
use crate::sim::correct::problem::Directions;
use crate::sim::correct::{CorrectionSettings, Solver};
use crate::sim::emit::Emitter;
use crate::sim::solids::{Motion, Obstacle, ObstacleMode};
use crate::sim::{Method, SimConfig};
use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `(name, text)` of each scene file `scenes/<name>.toml`, embedded into the binary.
macro_rules! built_in {
    ($($name:literal),* $(,)?) => {
        &[$(($name, include_str!(concat!("../scenes/", $name, ".toml")))),*]
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
];

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
    /// "box" or "ball".
    pub shape: String,
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
    /// "constant", or "falling": gravity in the air, then buoyancy and drag towards
    /// `terminal_speed` in the water (a dense object, sec. 7).
    #[serde(default = "default_motion")]
    pub motion: String,
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

fn default_motion() -> String {
    "constant".into()
}

impl ObstacleFile {
    /// Its shape as a region.
    pub fn region(&self) -> RegionFile {
        RegionFile {
            shape: self.shape.clone(),
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

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulationFile {
    pub method: String,
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
    pub seed: u64,
    /// Solver of the correction step (method ccp): "flow" or "simplex".
    pub solver: String,
    /// Candidate moves of the correction: "von-neumann" (5 in 2D, 7 in 3D) or "moore" (9, 27).
    pub directions: String,
    /// The band method of method ccp (sec. band_method): "none", or how the band's count is
    /// kept: "paths" (sec. push_part, the paper's choice), "one-way" (sec. band_con2) or
    /// "full" (sec. band_con, small problems only).
    pub band: String,
    /// `R`: depth of the band interface; the band is `R + 1` cells thick (the paper: 3, and 6
    /// for the dam scenes).
    pub band_r: u32,
    /// How obstacles get through particles: "couple" (method ccp, sec. 7), or for the other
    /// methods "naive" (wait until the way is free) or "ignore" (move regardless). Default:
    /// couple for ccp, naive otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub obstacle: Option<String>,
}

impl Default for SimulationFile {
    fn default() -> Self {
        Self {
            method: "flip".into(),
            duration: 2.0,
            ppc: 4,
            jitter: 0.1,
            gravity: None,
            flip_ratio: 0.9,
            cfl: 1.0,
            max_dt: 0.01,
            max_speed: 10.0,
            pressure_tolerance: 1e-9,
            seed: 1,
            solver: "flow".into(),
            directions: "von-neumann".into(),
            band: "none".into(),
            band_r: 3,
            obstacle: None,
        }
    }
}

/// A box (`min`, `max`) or a ball (`center`, `radius`), in metres.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RegionFile {
    /// "box" (`min`, `max`), "ball" (`center`, `radius`), or, for a 2D solid only, "spiral":
    /// the box `min`..`max` with a spiral channel carved into it, centred at `center`, its
    /// centre line starting `radius` above the centre and winding `turns` times inwards, the
    /// channel `width` wide and open to the box's top face (see `particles::SpiralBlock`).
    pub shape: String,
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
    pub method: Option<String>,
    pub duration: Option<f64>,
    pub cells: Option<usize>,
    pub ppc: Option<usize>,
    pub seed: Option<u64>,
    pub solver: Option<String>,
    pub directions: Option<String>,
    pub band: Option<String>,
    pub band_r: Option<u32>,
    pub obstacle: Option<String>,
}

/// A scene ready to run: its source, the file with overrides applied, and its checked values.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Where it came from: `built-in:NAME` or the file path.
    pub source: String,
    pub file: SceneFile,
    pub dims: Vec<usize>,
    pub cell_size_m: f64,
    pub method: Method,
    pub correction: CorrectionSettings,
    pub band: Option<BandSettings>,
    pub obstacle_mode: ObstacleMode,
}

impl Scene {
    pub fn name(&self) -> &str {
        &self.file.name
    }

    pub fn dim(&self) -> usize {
        self.file.dim
    }

    pub fn duration_secs(&self) -> f64 {
        self.file.simulation.duration
    }

    /// The scene as run, as TOML (defaults and overrides filled in).
    pub fn resolved_toml(&self) -> String {
        toml::to_string_pretty(&self.file).expect("a scene file always serialises")
    }

    /// Loads a built-in scene by name, or a scene file by path.
    pub fn load(name_or_path: &str, overrides: &Overrides) -> Result<Scene> {
        let (source, text) =
            if let Some((_, text)) = BUILT_IN.iter().find(|(n, _)| *n == name_or_path) {
                (format!("built-in scene '{name_or_path}'"), text.to_string())
            } else if name_or_path.ends_with(".toml") || Path::new(name_or_path).exists() {
                let text = std::fs::read_to_string(name_or_path)
                    .with_context(|| format!("cannot read scene file '{name_or_path}'"))?;
                (format!("scene file '{name_or_path}'"), text)
            } else {
                let names: Vec<&str> = BUILT_IN.iter().map(|(n, _)| *n).collect();
                bail!(
                "unknown scene '{name_or_path}': not a built-in scene ({}) and not a .toml file",
                names.join(", ")
            );
            };
        Self::parse(&source, &text, overrides)
    }

    /// Parses and checks scene text; `source` names it in errors.
    pub fn parse(source: &str, text: &str, overrides: &Overrides) -> Result<Scene> {
        let mut file: SceneFile = toml::from_str(text).map_err(|e| anyhow!("{source}: {e}"))?;
        let o = overrides;
        let sim = &mut file.simulation;
        if let Some(m) = &o.method {
            sim.method = m.clone();
        }
        if let Some(d) = o.duration {
            sim.duration = d;
        }
        if let Some(p) = o.ppc {
            sim.ppc = p;
        }
        if let Some(s) = o.seed {
            sim.seed = s;
        }
        if let Some(s) = &o.solver {
            sim.solver = s.clone();
        }
        if let Some(d) = &o.directions {
            sim.directions = d.clone();
        }
        if let Some(b) = &o.band {
            sim.band = b.clone();
        }
        if let Some(r) = o.band_r {
            sim.band_r = r;
        }
        if let Some(m) = &o.obstacle {
            sim.obstacle = Some(m.clone());
        }
        if let Some(c) = o.cells {
            file.domain.cells = c;
        }
        if sim.gravity.is_none() {
            let mut g = vec![0.0; file.dim];
            if file.dim > 1 {
                g[1] = -9.81;
            }
            sim.gravity = Some(g);
        }
        check(source, file)
    }

    /// The configuration in grid units.
    pub fn config<const D: usize>(&self) -> SimConfig<D> {
        assert_eq!(D, self.dim(), "scene dimension");
        let h = self.cell_size_m;
        let s = &self.file.simulation;
        let vec = |v: &[f64]| Vector::<D>::from_fn(|k, _| v[k] / h);
        let region = |r: &RegionFile| match r.shape.as_str() {
            "box" => Region::Box {
                min: vec(r.min.as_deref().unwrap()),
                max: vec(r.max.as_deref().unwrap()),
            },
            "ball" => Region::Ball {
                center: vec(r.center.as_deref().unwrap()),
                radius: r.radius.unwrap() / h,
            },
            "spiral" => Region::Spiral(SpiralBlock {
                min: vec(r.min.as_deref().unwrap()),
                max: vec(r.max.as_deref().unwrap()),
                center: vec(r.center.as_deref().unwrap()),
                radius: r.radius.unwrap() / h,
                turns: r.turns.unwrap(),
                width: r.width.unwrap() / h,
            }),
            other => unreachable!("shape '{other}' passed the scene checks"),
        };
        let dims: [usize; D] = std::array::from_fn(|k| self.dims[k]);
        let per_axis = ppc_per_axis(s.ppc, D).unwrap();
        let cells: usize = dims.iter().product();
        SimConfig {
            dims,
            cell_size_m: h,
            method: self.method,
            per_axis,
            jitter: s.jitter,
            gravity: vec(s.gravity.as_deref().unwrap()),
            flip_ratio: s.flip_ratio,
            cfl: s.cfl,
            max_dt_secs: s.max_dt,
            max_speed: s.max_speed / h,
            pressure_tolerance: s.pressure_tolerance,
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
            correction: self.correction,
            band: self.band,
            obstacles: self
                .file
                .obstacle
                .iter()
                .map(|o| Obstacle {
                    name: o.name.clone(),
                    shape: region(&o.region()),
                    offset: Vector::<D>::zeros(),
                    velocity: vec(&o.velocity),
                    motion: match o.motion.as_str() {
                        "falling" => Motion::Falling {
                            terminal_speed: o.terminal_speed.unwrap() / h,
                            drag: o.drag.unwrap_or(10.0),
                        },
                        _ => Motion::Constant,
                    },
                    zero_velocity_bc: o.zero_velocity_bc,
                })
                .collect(),
            obstacle_mode: self.obstacle_mode,
        }
    }
}

/// `k` with `k^dim = ppc`, if there is one.
fn ppc_per_axis(ppc: usize, dim: usize) -> Option<usize> {
    (1..=ppc).find(|k| k.pow(dim as u32) == ppc)
}

fn check(source: &str, file: SceneFile) -> Result<Scene> {
    let err = |key: &str, why: String| anyhow!("{source}: key '{key}': {why}");
    let dim = file.dim;
    if dim != 2 && dim != 3 {
        return Err(err("dim", format!("must be 2 or 3, got {dim}")));
    }
    let len = |key: &str, v: &[f64]| -> Result<()> {
        if v.len() != dim {
            return Err(err(
                key,
                format!("needs {dim} numbers (dim = {dim}), got {}", v.len()),
            ));
        }
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            return Err(err(key, format!("must be finite, got {x}")));
        }
        Ok(())
    };
    let d = &file.domain;
    len("domain.size", &d.size)?;
    if let Some(x) = d.size.iter().find(|x| **x <= 0.0) {
        return Err(err(
            "domain.size",
            format!("every extent must be positive, got {x}"),
        ));
    }
    if d.cells < 4 {
        return Err(err(
            "domain.cells",
            format!("needs at least 4 cells per axis, got {}", d.cells),
        ));
    }
    let longest = d.size.iter().cloned().fold(0.0, f64::max);
    let h = longest / d.cells as f64;
    let mut dims = vec![];
    for (k, &s) in d.size.iter().enumerate() {
        let n = s / h;
        let rounded = n.round();
        if (n - rounded).abs() > 1e-6 * n.max(1.0) {
            return Err(err(
                "domain.size",
                format!(
                    "axis {k}: extent {s} m is not a whole number of cells of {h} m ({n:.4} cells)"
                ),
            ));
        }
        if rounded < 4.0 {
            return Err(err(
                "domain.cells",
                format!("axis {k} gets {rounded} cells; at least 4 per axis are needed"),
            ));
        }
        dims.push(rounded as usize);
    }
    let total: usize = dims.iter().product();
    if total > 200_000_000 {
        return Err(err(
            "domain.cells",
            format!("{total} cells is more than this program can hold"),
        ));
    }
    let s = &file.simulation;
    // A named choice: the value must be one of `options`.
    let pick = |key: &str, value: &str, options: &[&str]| -> Result<usize> {
        options.iter().position(|o| *o == value).ok_or_else(|| {
            err(
                key,
                format!("unknown value '{value}' (known: {})", options.join(", ")),
            )
        })
    };
    let method = Method::ALL[pick(
        "simulation.method",
        &s.method,
        &Method::ALL.map(Method::name),
    )?];
    let solver = Solver::ALL[pick(
        "simulation.solver",
        &s.solver,
        &Solver::ALL.map(Solver::name),
    )?];
    let directions = [Directions::VonNeumann, Directions::Moore][pick(
        "simulation.directions",
        &s.directions,
        &["von-neumann", "moore"],
    )?];
    let band_names: Vec<&str> = std::iter::once("none")
        .chain(BandVariant::ALL.map(BandVariant::name))
        .collect();
    let band_variant = match pick("simulation.band", &s.band, &band_names)? {
        0 => None,
        k => Some(BandVariant::ALL[k - 1]),
    };
    if band_variant.is_some() && directions == Directions::Moore {
        return Err(err(
            "simulation.band",
            "the band method moves particles to von Neumann neighbours only (sec. push_part); \
             use directions = \"von-neumann\" or band = \"none\""
                .into(),
        ));
    }
    if !(1..=10_000).contains(&s.band_r) {
        return Err(err(
            "simulation.band_r",
            format!(
                "must be at least 1 (the band interface lies R cells below the surface), got {}",
                s.band_r
            ),
        ));
    }
    if !(s.duration.is_finite() && s.duration > 0.0) {
        return Err(err(
            "simulation.duration",
            format!("must be a positive number of seconds, got {}", s.duration),
        ));
    }
    if s.ppc == 0 {
        return Err(err(
            "simulation.ppc",
            "must be at least 1 particle per cell, got 0".into(),
        ));
    }
    if ppc_per_axis(s.ppc, dim).is_none() {
        return Err(err(
            "simulation.ppc",
            format!(
                "must be k^{dim} for a whole k (e.g. 1, {}, {}), got {}",
                2usize.pow(dim as u32),
                3usize.pow(dim as u32),
                s.ppc
            ),
        ));
    }
    if !(0.0..0.5).contains(&s.jitter) {
        return Err(err(
            "simulation.jitter",
            format!("must be in [0, 0.5), got {}", s.jitter),
        ));
    }
    len("simulation.gravity", s.gravity.as_deref().unwrap())?;
    if !(0.0..=1.0).contains(&s.flip_ratio) {
        return Err(err(
            "simulation.flip_ratio",
            format!("must be in [0, 1], got {}", s.flip_ratio),
        ));
    }
    if !(s.cfl > 0.0 && s.cfl <= 1.0) {
        return Err(err(
            "simulation.cfl",
            format!("must be in (0, 1] cells per step, got {}", s.cfl),
        ));
    }
    if !(s.max_dt.is_finite() && s.max_dt > 0.0) {
        return Err(err(
            "simulation.max_dt",
            format!("must be a positive number of seconds, got {}", s.max_dt),
        ));
    }
    if !(s.max_speed.is_finite() && s.max_speed > 0.0) {
        return Err(err(
            "simulation.max_speed",
            format!("must be a positive speed in m/s, got {}", s.max_speed),
        ));
    }
    if !(s.pressure_tolerance > 0.0 && s.pressure_tolerance < 1.0) {
        return Err(err(
            "simulation.pressure_tolerance",
            format!("must be in (0, 1), got {}", s.pressure_tolerance),
        ));
    }
    let inside = |key: &str, p: &[f64]| -> Result<()> {
        len(key, p)?;
        for k in 0..dim {
            if p[k] < 0.0 || p[k] > d.size[k] {
                return Err(err(
                    key,
                    format!(
                        "axis {k}: {} lies outside the domain [0, {}]",
                        p[k], d.size[k]
                    ),
                ));
            }
        }
        Ok(())
    };
    // A box's corners inside the domain and below each other.
    let block = |key: &str, min: &[f64], max: &[f64]| -> Result<()> {
        inside(&format!("{key}.min"), min)?;
        inside(&format!("{key}.max"), max)?;
        if (0..dim).any(|k| min[k] >= max[k]) {
            return Err(err(
                key,
                format!("'min' {min:?} must be below 'max' {max:?} on every axis"),
            ));
        }
        Ok(())
    };
    let positive = |key: String, v: f64| -> Result<()> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(err(&key, format!("must be positive, got {v}")))
        }
    };
    // Which keys each shape takes, in the order they are named in errors.
    let takes = |key: &str, r: &RegionFile, shape: &str, wanted: &[&str]| -> Result<()> {
        let given = [
            ("min", r.min.is_some()),
            ("max", r.max.is_some()),
            ("center", r.center.is_some()),
            ("radius", r.radius.is_some()),
            ("turns", r.turns.is_some()),
            ("width", r.width.is_some()),
        ];
        let quoted = |names: Vec<&str>| {
            let q: Vec<String> = names.iter().map(|n| format!("'{n}'")).collect();
            match q.split_last() {
                Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
                _ => q.join(""),
            }
        };
        let extra: Vec<&str> = given
            .iter()
            .filter(|(n, g)| *g && !wanted.contains(n))
            .map(|(n, _)| *n)
            .collect();
        if given.iter().any(|(n, g)| !g && wanted.contains(n)) {
            return Err(err(
                key,
                format!("a {shape} needs {}", quoted(wanted.to_vec())),
            ));
        }
        if !extra.is_empty() {
            return Err(err(
                key,
                format!(
                    "a {shape} takes {}, not {}",
                    quoted(wanted.to_vec()),
                    quoted(extra)
                ),
            ));
        }
        Ok(())
    };
    let region = |key: String, r: &RegionFile, solid: bool| -> Result<()> {
        match r.shape.as_str() {
            "box" => {
                takes(&key, r, "box", &["min", "max"])?;
                block(&key, r.min.as_deref().unwrap(), r.max.as_deref().unwrap())?;
            }
            "ball" => {
                takes(&key, r, "ball", &["center", "radius"])?;
                let (c, rad) = (r.center.as_deref().unwrap(), r.radius.unwrap());
                len(&format!("{key}.center"), c)?;
                positive(format!("{key}.radius"), rad)?;
                for k in 0..dim {
                    if c[k] - rad < 0.0 || c[k] + rad > d.size[k] {
                        return Err(err(&key, format!("the ball leaves the domain on axis {k}")));
                    }
                }
            }
            "spiral" if solid && dim == 2 => {
                takes(
                    &key,
                    r,
                    "spiral",
                    &["min", "max", "center", "radius", "turns", "width"],
                )?;
                let (min, max) = (r.min.as_deref().unwrap(), r.max.as_deref().unwrap());
                block(&key, min, max)?;
                let c = r.center.as_deref().unwrap();
                len(&format!("{key}.center"), c)?;
                let (rad, turns, width) = (r.radius.unwrap(), r.turns.unwrap(), r.width.unwrap());
                positive(format!("{key}.radius"), rad)?;
                positive(format!("{key}.turns"), turns)?;
                positive(format!("{key}.width"), width)?;
                // Rasterised by cell centres, a channel or wall under two cells across can
                // break into pockets where it runs diagonally, or leak into the next turn.
                if width < 2.0 * h {
                    return Err(err(
                        &format!("{key}.width"),
                        format!(
                            "{width} m is narrower than two cells ({:.4} m): the channel \
                             would break into pockets",
                            2.0 * h
                        ),
                    ));
                }
                let wall = particles::pitch(rad, turns) - width;
                if wall < 2.0 * h {
                    return Err(err(
                        &key,
                        format!(
                            "the walls between turns are {wall:.4} m thick, thinner than two \
                             cells ({:.4} m): fewer turns, a narrower channel or a larger radius",
                            2.0 * h
                        ),
                    ));
                }
                let reach = rad + width / 2.0;
                for k in 0..dim {
                    if c[k] - reach < min[k] || c[k] + reach > max[k] {
                        return Err(err(&key, format!("the channel leaves the box on axis {k}")));
                    }
                }
            }
            "spiral" => {
                return Err(err(
                    &format!("{key}.shape"),
                    "a spiral is a static 2D solid ([[solid]] in a 2D scene) only".into(),
                ))
            }
            other => {
                let shapes = if solid && dim == 2 {
                    "\"box\", \"ball\" or \"spiral\""
                } else {
                    "\"box\" or \"ball\""
                };
                return Err(err(
                    &format!("{key}.shape"),
                    format!("must be {shapes}, got \"{other}\""),
                ));
            }
        }
        Ok(())
    };
    if file.fluid.is_empty() && file.emitter.is_empty() {
        return Err(err("fluid", "the scene has no fluid and no emitter".into()));
    }
    for (i, r) in file.fluid.iter().enumerate() {
        region(format!("fluid[{i}]"), r, false)?;
    }
    for (i, r) in file.solid.iter().enumerate() {
        region(format!("solid[{i}]"), r, true)?;
    }
    for (i, e) in file.emitter.iter().enumerate() {
        let key = format!("emitter[{i}]");
        inside(&format!("{key}.min"), &e.min)?;
        inside(&format!("{key}.max"), &e.max)?;
        len(&format!("{key}.velocity"), &e.velocity)?;
        if !(e.start.is_finite() && e.start >= 0.0) {
            return Err(err(
                &format!("{key}.start"),
                format!("must be a time >= 0 s, got {}", e.start),
            ));
        }
        if let Some(stop) = e.stop {
            if stop.is_nan() || stop <= e.start {
                return Err(err(
                    &format!("{key}.stop"),
                    format!("must be after start ({} s), got {stop}", e.start),
                ));
            }
        }
        if let Some(f) = e.until_fill {
            if !(f > 0.0 && f <= 1.0) {
                return Err(err(
                    &format!("{key}.until_fill"),
                    format!("must be in (0, 1], got {f}"),
                ));
            }
        }
    }
    let mut names = std::collections::BTreeSet::new();
    for (i, o) in file.obstacle.iter().enumerate() {
        let key = format!("obstacle[{i}]");
        region(key.clone(), &o.region(), false)?;
        len(&format!("{key}.velocity"), &o.velocity)?;
        let ok = !o.name.is_empty()
            && o.name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '-' || ch == '_');
        if !ok {
            return Err(err(
                &format!("{key}.name"),
                format!("must be letters, digits, '-' or '_', got '{}'", o.name),
            ));
        }
        let falling = pick(
            &format!("{key}.motion"),
            &o.motion,
            &["constant", "falling"],
        )? == 1;
        match (falling, o.terminal_speed, o.drag) {
            (true, None, _) => {
                return Err(err(
                    &format!("{key}.terminal_speed"),
                    "a falling obstacle needs its terminal speed in the water (m/s)".into(),
                ))
            }
            (true, Some(v), _) if !(v.is_finite() && v >= 0.0) => {
                return Err(err(
                    &format!("{key}.terminal_speed"),
                    format!("must be a speed >= 0 m/s, got {v}"),
                ))
            }
            (true, _, Some(d)) if !(d.is_finite() && d > 0.0) => {
                return Err(err(
                    &format!("{key}.drag"),
                    format!("must be a rate > 0 per second, got {d}"),
                ))
            }
            (false, Some(_), _) | (false, _, Some(_)) => {
                return Err(err(
                    &key,
                    "'terminal_speed' and 'drag' apply to motion = \"falling\" only".into(),
                ))
            }
            _ => {}
        }
        if !names.insert(o.name.clone()) {
            return Err(err(
                &format!("{key}.name"),
                format!("'{}' names two obstacles", o.name),
            ));
        }
    }
    let modes = ObstacleMode::ALL.map(ObstacleMode::name);
    let obstacle_mode = match &s.obstacle {
        None if method == Method::Ccp => ObstacleMode::Couple,
        None => ObstacleMode::Naive,
        Some(m) => ObstacleMode::ALL[pick("simulation.obstacle", m, &modes)?],
    };
    if (method == Method::Ccp) != (obstacle_mode == ObstacleMode::Couple) {
        return Err(err(
            "simulation.obstacle",
            format!(
                "method {} cannot use obstacle mode '{}': ccp couples obstacles through its \
                 correction (sec. 7); the other methods use 'naive' or 'ignore'",
                method.name(),
                obstacle_mode.name()
            ),
        ));
    }
    let scene = Scene {
        source: source.to_string(),
        cell_size_m: h,
        dims,
        method,
        obstacle_mode,
        correction: CorrectionSettings {
            solver,
            directions,
            cross_check: false,
        },
        band: band_variant.map(|variant| BandSettings {
            variant,
            r: s.band_r,
        }),
        file,
    };
    match dim {
        2 => obstacles_start_clear::<2>(&scene),
        _ => obstacles_start_clear::<3>(&scene),
    }
    .map_err(|(key, why)| err(&key, why))?;
    Ok(scene)
}

/// Every obstacle starts clear of the static solids and of the other obstacles, cell by cell
/// at the scene's resolution; otherwise the key of the first offender and why.
fn obstacles_start_clear<const D: usize>(scene: &Scene) -> Result<(), (String, String)> {
    let config = scene.config::<D>();
    let grid = Grid::new(config.dims);
    // What holds each cell: a static solid or an obstacle, by index.
    enum Holder {
        Solid(usize),
        Obstacle(usize),
    }
    let mut holder: Vec<Option<Holder>> = (0..grid.num_cells()).map(|_| None).collect();
    for (i, r) in config.solids.iter().enumerate() {
        r.cells(&grid)
            .for_each(|c| holder[c] = Some(Holder::Solid(i)));
    }
    for (i, o) in config.obstacles.iter().enumerate() {
        let cells = o.cells_at(&grid, &o.offset);
        if let Some(&c) = cells.iter().find(|&&c| holder[c].is_some()) {
            let other = match holder[c] {
                Some(Holder::Solid(j)) => format!("solid[{j}]"),
                Some(Holder::Obstacle(j)) => {
                    format!("obstacle[{j}] '{}'", config.obstacles[j].name)
                }
                None => unreachable!(),
            };
            return Err((
                format!("obstacle[{i}]"),
                format!(
                    "'{}' starts in a cell of {other} (cell {:?}); obstacles must start \
                     clear of solids and of each other",
                    o.name,
                    grid.cell_coords(c)
                ),
            ));
        }
        cells
            .into_iter()
            .for_each(|c| holder[c] = Some(Holder::Obstacle(i)));
    }
    Ok(())
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
}
