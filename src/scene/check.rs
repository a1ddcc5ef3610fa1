//! The checks of a scene file, one function per section (domain, simulation, fluid, solid,
//! emitter, obstacle). Every error is a [`SceneError`]: the file, the key, a kind that tests
//! match, and the reason in words.

use super::tables::BadValue;
use super::{
    EmitterFile, MotionKind, ObstacleFile, RegionFile, Scene, SceneFile, Shape, SimulationFile,
};
use crate::grid::Grid;
use crate::methods::{MethodFlags, MethodSettings, SettingContext, SettingError};
use crate::particles;
use std::collections::{BTreeSet, HashMap};

/// What is wrong with a scene, broadly: tests match on it, people read the reason.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorKind {
    /// Not valid TOML, an unknown key, a value of the wrong type or an unknown name.
    Syntax,
    /// A number out of its range, or a list of the wrong length.
    Range,
    /// A shape or motion missing a key it needs, or given one it does not take.
    Keys,
    /// Geometry that does not fit: outside the domain, too thin, overlapping.
    Geometry,
    /// Settings that do not go together.
    Conflict,
    /// A run larger than the memory this machine has left (`scene::ensure_fit`).
    Memory,
}

/// A scene that cannot run: which file, which key, what kind of problem and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{file}: key '{key}': {reason}")]
pub struct SceneError {
    /// The scene file (or built-in scene) it came from.
    pub file: String,
    pub key: String,
    pub kind: ErrorKind,
    pub reason: String,
}

/// A TOML error as a [`SceneError`] naming the key it points at (the table headers above it
/// and the key on its line).
pub(super) fn toml_error(source: &str, text: &str, e: &toml::de::Error) -> SceneError {
    let key = e
        .span()
        .map(|s| key_at(text, s.start))
        .filter(|k| !k.is_empty())
        .unwrap_or_else(|| "(file)".into());
    SceneError {
        file: source.into(),
        key,
        kind: ErrorKind::Syntax,
        reason: e.to_string().trim_end().into(),
    }
}

/// The dotted key at byte `offset` of a TOML text: `table.key`, or `array[i].key` for the
/// `i`-th `[[array]]`.
fn key_at(text: &str, offset: usize) -> String {
    let offset = offset.min(text.len());
    let line_start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[offset..].find('\n').map_or(text.len(), |i| offset + i);
    let mut table = String::new();
    let mut seen: Vec<(String, usize)> = vec![];
    // Table headers up to and including the error's line.
    for line in text[..line_end].lines().map(str::trim) {
        if let Some(name) = line.strip_prefix("[[").and_then(|l| l.split("]]").next()) {
            let name = name.trim().to_string();
            let i = match seen.iter_mut().find(|(n, _)| *n == name) {
                Some((_, i)) => {
                    *i += 1;
                    *i
                }
                None => {
                    seen.push((name.clone(), 0));
                    0
                }
            };
            table = format!("{name}[{i}]");
        } else if let Some(name) = line.strip_prefix('[').and_then(|l| l.split(']').next()) {
            table = name.trim().to_string();
        }
    }
    let line = text[line_start..line_end].trim();
    let key = match line.starts_with('[') {
        true => "",
        false => line.split_once('=').map_or("", |(k, _)| k.trim()),
    };
    match (table.is_empty(), key.is_empty()) {
        (_, true) => table,
        (true, false) => key.to_string(),
        (false, false) => format!("{table}.{key}"),
    }
}

/// `k` with `k^dim = ppc`, if there is one.
pub(super) fn ppc_per_axis(ppc: usize, dim: usize) -> Option<usize> {
    let root = (ppc as f64).powf(1.0 / dim as f64).round() as usize;
    (root.saturating_sub(1)..=root + 1).find(|k| *k > 0 && k.checked_pow(dim as u32) == Some(ppc))
}

type Checked<T> = Result<T, SceneError>;

/// What the checks of one scene share: where it came from, its dimension and tank.
struct Checker<'a> {
    source: &'a str,
    dim: usize,
    size: &'a [f64],
    /// Cell size, metres.
    h: f64,
}

impl Checker<'_> {
    fn err<T>(&self, key: &str, kind: ErrorKind, reason: String) -> Checked<T> {
        Err(SceneError {
            file: self.source.into(),
            key: key.into(),
            kind,
            reason,
        })
    }

    /// `dim` finite numbers.
    fn len(&self, key: &str, v: &[f64]) -> Checked<()> {
        let dim = self.dim;
        if v.len() != dim {
            let why = format!("needs {dim} numbers (dim = {dim}), got {}", v.len());
            return self.err(key, ErrorKind::Range, why);
        }
        match v.iter().find(|x| !x.is_finite()) {
            Some(x) => self.err(key, ErrorKind::Range, format!("must be finite, got {x}")),
            None => Ok(()),
        }
    }

    fn positive(&self, key: &str, v: f64) -> Checked<()> {
        if v.is_finite() && v > 0.0 {
            return Ok(());
        }
        self.err(key, ErrorKind::Range, format!("must be positive, got {v}"))
    }

    /// A point inside the tank.
    fn inside(&self, key: &str, p: &[f64]) -> Checked<()> {
        self.len(key, p)?;
        match (0..self.dim).find(|&k| p[k] < 0.0 || p[k] > self.size[k]) {
            Some(k) => self.err(
                key,
                ErrorKind::Geometry,
                format!(
                    "axis {k}: {} lies outside the domain [0, {}]",
                    p[k], self.size[k]
                ),
            ),
            None => Ok(()),
        }
    }

    /// A box's corners inside the tank and below each other.
    fn block(&self, key: &str, min: &[f64], max: &[f64]) -> Checked<()> {
        self.inside(&format!("{key}.min"), min)?;
        self.inside(&format!("{key}.max"), max)?;
        if (0..self.dim).any(|k| min[k] >= max[k]) {
            let why = format!("'min' {min:?} must be below 'max' {max:?} on every axis");
            return self.err(key, ErrorKind::Geometry, why);
        }
        Ok(())
    }

    /// The shape has exactly the keys in `wanted`.
    fn takes(&self, key: &str, r: &RegionFile, wanted: &[&str]) -> Checked<()> {
        let given = [
            ("min", r.min.is_some()),
            ("max", r.max.is_some()),
            ("center", r.center.is_some()),
            ("radius", r.radius.is_some()),
            ("turns", r.turns.is_some()),
            ("width", r.width.is_some()),
        ];
        let quoted = |names: &[&str]| {
            let q: Vec<String> = names.iter().map(|n| format!("'{n}'")).collect();
            match q.split_last() {
                Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
                _ => q.join(""),
            }
        };
        let shape = r.shape.name();
        if given.iter().any(|(n, g)| !g && wanted.contains(n)) {
            return self.err(
                key,
                ErrorKind::Keys,
                format!("a {shape} needs {}", quoted(wanted)),
            );
        }
        let extra: Vec<&str> = given
            .iter()
            .filter(|(n, g)| *g && !wanted.contains(n))
            .map(|(n, _)| *n)
            .collect();
        if !extra.is_empty() {
            let why = format!("a {shape} takes {}, not {}", quoted(wanted), quoted(&extra));
            return self.err(key, ErrorKind::Keys, why);
        }
        Ok(())
    }

    /// A region of section `fluid`, `solid` (which alone may be a 2D spiral) or `obstacle`.
    fn region(&self, key: &str, r: &RegionFile, solid: bool) -> Checked<()> {
        match r.shape {
            Shape::Box => {
                self.takes(key, r, &["min", "max"])?;
                self.block(key, r.min.as_deref().unwrap(), r.max.as_deref().unwrap())
            }
            Shape::Ball => {
                self.takes(key, r, &["center", "radius"])?;
                let (c, rad) = (r.center.as_deref().unwrap(), r.radius.unwrap());
                self.len(&format!("{key}.center"), c)?;
                self.positive(&format!("{key}.radius"), rad)?;
                match (0..self.dim).find(|&k| c[k] - rad < 0.0 || c[k] + rad > self.size[k]) {
                    Some(k) => self.err(
                        key,
                        ErrorKind::Geometry,
                        format!("the ball leaves the domain on axis {k}"),
                    ),
                    None => Ok(()),
                }
            }
            Shape::Spiral if solid && self.dim == 2 => self.spiral(key, r),
            Shape::Spiral => self.err(
                &format!("{key}.shape"),
                ErrorKind::Conflict,
                "a spiral is a static 2D solid ([[solid]] in a 2D scene) only".into(),
            ),
        }
    }

    fn spiral(&self, key: &str, r: &RegionFile) -> Checked<()> {
        let wanted = ["min", "max", "center", "radius", "turns", "width"];
        self.takes(key, r, &wanted)?;
        let (min, max) = (r.min.as_deref().unwrap(), r.max.as_deref().unwrap());
        self.block(key, min, max)?;
        let c = r.center.as_deref().unwrap();
        self.len(&format!("{key}.center"), c)?;
        let (rad, turns, width) = (r.radius.unwrap(), r.turns.unwrap(), r.width.unwrap());
        self.positive(&format!("{key}.radius"), rad)?;
        self.positive(&format!("{key}.turns"), turns)?;
        self.positive(&format!("{key}.width"), width)?;
        // Rasterised by cell centres, a channel or wall under two cells across can break
        // into pockets where it runs diagonally, or leak into the next turn.
        let two = 2.0 * self.h;
        if width < two {
            let why = format!(
                "{width} m is narrower than two cells ({two:.4} m): the channel would break into pockets"
            );
            return self.err(&format!("{key}.width"), ErrorKind::Geometry, why);
        }
        let wall = particles::pitch(rad, turns) - width;
        if wall < two {
            let why = format!(
                "the walls between turns are {wall:.4} m thick, thinner than two cells ({two:.4} m): \
                 fewer turns, a narrower channel or a larger radius"
            );
            return self.err(key, ErrorKind::Geometry, why);
        }
        let reach = rad + width / 2.0;
        match (0..self.dim).find(|&k| c[k] - reach < min[k] || c[k] + reach > max[k]) {
            Some(k) => self.err(
                key,
                ErrorKind::Geometry,
                format!("the channel leaves the box on axis {k}"),
            ),
            None => Ok(()),
        }
    }
}

/// Checks a scene file (with overrides applied) and the methods' settings with `flags` set, and
/// makes the [`Scene`].
pub(super) fn check(source: &str, file: SceneFile, flags: &MethodFlags) -> Checked<Scene> {
    let dim = file.dim;
    if dim != 2 && dim != 3 {
        return Err(SceneError {
            file: source.into(),
            key: "dim".into(),
            kind: ErrorKind::Range,
            reason: format!("must be 2 or 3, got {dim}"),
        });
    }
    let size = file.domain.size.clone();
    let mut ch = Checker {
        source,
        dim,
        size: &size,
        h: 0.0,
    };
    name(&ch, &file.name)?;
    let (dims, h) = domain(&ch, file.domain.cells)?;
    ch.h = h;
    let method = simulation(&ch, &file.simulation, flags)?;
    regions(&ch, &file)?;
    file.emitter.iter().enumerate().try_for_each(|(i, e)| {
        emitter(&ch, &format!("emitter[{i}]"), e, file.simulation.max_speed)
    })?;
    obstacles(&ch, &file.obstacle)?;
    let obstacle_mode = obstacle_mode(&ch, &file.simulation, &method)?;
    let scene = Scene {
        source: source.to_string(),
        cell_size_m: h,
        dims,
        method,
        obstacle_mode,
        file,
    };
    match dim {
        2 => obstacles_start_clear::<2>(&ch, &scene).and(regions_cover_cells::<2>(&ch, &scene)),
        _ => obstacles_start_clear::<3>(&ch, &scene).and(regions_cover_cells::<3>(&ch, &scene)),
    }?;
    Ok(scene)
}

/// The longest scene name: it becomes a file name (`recordings/<name>.rrd`).
pub const MAX_NAME_BYTES: usize = 100;

/// Key `name`: it names the default recording file, so it must be a plain file name.
fn name(ch: &Checker, name: &str) -> Checked<()> {
    let why = if name.is_empty() {
        "must not be empty".to_string()
    } else if name.len() > MAX_NAME_BYTES {
        format!("must be at most {MAX_NAME_BYTES} bytes, got {}", name.len())
    } else if name.contains(['/', '\\']) || name.contains("..") {
        format!("names the recording file, so it must not contain '/', '\\' or '..', got {name:?}")
    } else if name.chars().any(char::is_control) {
        format!("must not contain control characters, got {name:?}")
    } else {
        return Ok(());
    };
    ch.err("name", ErrorKind::Range, why)
}

/// Section `domain`: the tank's size in whole cells, at least 4 per axis. Returns the cells
/// per axis and the cell size.
fn domain(ch: &Checker, cells: usize) -> Checked<(Vec<usize>, f64)> {
    ch.len("domain.size", ch.size)?;
    if let Some(x) = ch.size.iter().find(|x| **x <= 0.0) {
        let why = format!("every extent must be positive, got {x}");
        return ch.err("domain.size", ErrorKind::Range, why);
    }
    if !(4..=MAX_CELLS).contains(&cells) {
        let why = format!("needs 4 to {MAX_CELLS} cells along the longest axis, got {cells}");
        return ch.err("domain.cells", ErrorKind::Range, why);
    }
    let longest = ch.size.iter().cloned().fold(0.0, f64::max);
    let h = longest / cells as f64;
    let mut dims = vec![];
    for (k, &s) in ch.size.iter().enumerate() {
        let n = s / h;
        let rounded = n.round();
        if (n - rounded).abs() > 1e-6 * n.max(1.0) {
            let why = format!(
                "axis {k}: extent {s} m is not a whole number of cells of {h} m ({n:.4} cells)"
            );
            return ch.err("domain.size", ErrorKind::Geometry, why);
        }
        if rounded < 4.0 {
            let why = format!("axis {k} gets {rounded} cells; at least 4 per axis are needed");
            return ch.err("domain.cells", ErrorKind::Range, why);
        }
        dims.push(rounded as usize);
    }
    let total = dims.iter().try_fold(1usize, |t, &n| t.checked_mul(n));
    match total.filter(|&t| t <= MAX_TOTAL_CELLS) {
        Some(_) => Ok((dims, h)),
        None => {
            let why = format!(
                "{} cells is more than this program can hold ({MAX_TOTAL_CELLS})",
                dims.iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(" x ")
            );
            ch.err("domain.cells", ErrorKind::Range, why)
        }
    }
}

/// The most cells along the longest axis (cell indices are `u32` in the correction).
const MAX_CELLS: usize = 1 << 16;
/// The most cells in all (about 2 GB of grid arrays at the least).
const MAX_TOTAL_CELLS: usize = 200_000_000;
/// The most steps a run may need at its shortest possible step (see [`step_count`]).
pub const MAX_STEPS: f64 = 1e7;
/// The tightest pressure tolerance that f64 arithmetic can meet: residuals stall near
/// 1e-16 times the right-hand side.
const MIN_PRESSURE_TOLERANCE: f64 = 1e-14;

/// Section `simulation`: the ranges of its numbers, and the method's settings.
fn simulation(ch: &Checker, s: &SimulationFile, flags: &MethodFlags) -> Checked<MethodSettings> {
    let range = |key: &str, ok: bool, why: String| -> Checked<()> {
        match ok {
            true => Ok(()),
            false => ch.err(&format!("simulation.{key}"), ErrorKind::Range, why),
        }
    };
    let d = s.duration;
    range(
        "duration",
        d.is_finite() && d > 0.0,
        format!("must be a positive number of seconds, got {d}"),
    )?;
    range(
        "ppc",
        s.ppc > 0,
        "must be at least 1 particle per cell, got 0".into(),
    )?;
    let dim = ch.dim;
    range(
        "ppc",
        ppc_per_axis(s.ppc, dim).is_some(),
        format!(
            "must be k^{dim} for a whole k (e.g. 1, {}, {}), got {}",
            2usize.pow(dim as u32),
            3usize.pow(dim as u32),
            s.ppc
        ),
    )?;
    range(
        "jitter",
        (0.0..0.5).contains(&s.jitter),
        format!("must be in [0, 0.5), got {}", s.jitter),
    )?;
    ch.len("simulation.gravity", s.gravity.as_deref().unwrap())?;
    let f = s.flip_ratio;
    range(
        "flip_ratio",
        (0.0..=1.0).contains(&f),
        format!("must be in [0, 1], got {f}"),
    )?;
    let c = s.cfl;
    range(
        "cfl",
        c > 0.0 && c <= 1.0,
        format!("must be in (0, 1] cells per step, got {c}"),
    )?;
    let dt = s.max_dt;
    range(
        "max_dt",
        dt.is_finite() && dt > 0.0,
        format!("must be a positive number of seconds, got {dt}"),
    )?;
    let v = s.max_speed;
    range(
        "max_speed",
        v.is_finite() && v > 0.0,
        format!("must be a positive speed in m/s, got {v}"),
    )?;
    let t = s.pressure_tolerance;
    range(
        "pressure_tolerance",
        (MIN_PRESSURE_TOLERANCE..1.0).contains(&t),
        format!("must be in [{MIN_PRESSURE_TOLERANCE:e}, 1) (f64 cannot do better), got {t:e}"),
    )?;
    range(
        "seed",
        i64::try_from(s.seed).is_ok(),
        format!(
            "must be below 2^63 (TOML integers are signed), got {}",
            s.seed
        ),
    )?;
    step_count(ch, s)?;
    let setting_error = |e: SettingError| SceneError {
        file: ch.source.into(),
        key: format!("simulation.{}", e.key),
        kind: match e.conflict {
            true => ErrorKind::Conflict,
            false => ErrorKind::Range,
        },
        reason: e.reason,
    };
    let bad_value = |e: BadValue| SceneError {
        file: ch.source.into(),
        key: format!("simulation.{}", e.key),
        kind: ErrorKind::Syntax,
        reason: e.reason,
    };
    let mut m = s.method_settings().map_err(bad_value)?;
    m.apply_flags(flags);
    let ctx = SettingContext {
        dim,
        per_axis: ppc_per_axis(s.ppc, dim).unwrap_or(1),
    };
    m.check(ctx)
        .map_err(|e| given_as_flag(e, flags))
        .map_err(setting_error)?;
    Ok(m)
}

/// A setting's refusal says so when a command-line flag gave the value (the flag of a setting
/// is its key with dashes: `band_r`, `--band-r`), so that the user finds what they typed.
fn given_as_flag(mut e: SettingError, flags: &MethodFlags) -> SettingError {
    let flag = flags
        .0
        .iter()
        .rev()
        .find(|(name, _)| name.replace('-', "_") == e.key);
    if let Some((name, value)) = flag {
        e.reason = format!("{} (given as --{name} {value})", e.reason);
    }
    e
}

/// Refuses a method key (`simulation.band`, ...) that the file's own method does not have,
/// with the words the command line's flags are refused with, and one the method has when the
/// file also has the method's table (each setting has one place).
pub(super) fn method_keys(source: &str, s: &SimulationFile) -> Checked<()> {
    let table = s.has_table(s.method).then_some(s.method.name());
    let refused = s.scene_keys().into_iter().find_map(|k| {
        let has = |m: crate::methods::MethodKind| m.table_keys().iter().any(|t| t == k.table_key);
        let why = match (s.method.refusal(has), table) {
            (Some(why), _) => format!("{why}; remove the key or set simulation.method"),
            (None, Some(m)) => format!("the file has [simulation.{m}]: set the key there"),
            (None, None) => return None,
        };
        Some((k.name, why))
    });
    let Some((key, reason)) = refused else {
        return Ok(());
    };
    Err(SceneError {
        file: source.into(),
        key: format!("simulation.{key}"),
        kind: ErrorKind::Conflict,
        reason,
    })
}

/// The run ends in about [`MAX_STEPS`] steps at most, however the fluid moves: a step is
/// never much shorter (a factor of 2 at most) than the smallest of `max_dt`, `cfl` cells at
/// `max_speed`, and the time gravity takes to move a resting particle `cfl` cells (see
/// `stages::timestep`). The key named is the one that sets that shortest step.
fn step_count(ch: &Checker, s: &SimulationFile) -> Checked<()> {
    let g = s
        .gravity
        .as_deref()
        .unwrap()
        .iter()
        .fold(0.0f64, |m, g| m.max(g.abs()))
        / ch.h;
    let v = s.max_speed / ch.h;
    let bounds = [
        ("max_dt", s.max_dt),
        ("cfl", s.cfl / v),
        (
            "gravity",
            if g > 0.0 {
                (s.cfl / g).sqrt()
            } else {
                f64::INFINITY
            },
        ),
    ];
    let (key, dt) =
        bounds.into_iter().fold(
            ("max_dt", f64::INFINITY),
            |a, b| {
                if b.1 < a.1 {
                    b
                } else {
                    a
                }
            },
        );
    let steps = s.duration / dt;
    if steps <= MAX_STEPS {
        return Ok(());
    }
    let why = format!(
        "steps could shrink to {dt:.3e} s, so the {} s run could take {steps:.3e} steps \
         (at most {MAX_STEPS:e})",
        s.duration
    );
    ch.err(&format!("simulation.{key}"), ErrorKind::Range, why)
}

/// Sections `fluid` and `solid`: at least some fluid (or an emitter), every region valid.
fn regions(ch: &Checker, file: &SceneFile) -> Checked<()> {
    if file.fluid.is_empty() && file.emitter.is_empty() {
        return ch.err(
            "fluid",
            ErrorKind::Conflict,
            "the scene has no fluid and no emitter".into(),
        );
    }
    for (i, r) in file.fluid.iter().enumerate() {
        ch.region(&format!("fluid[{i}]"), r, false)?;
    }
    for (i, r) in file.solid.iter().enumerate() {
        ch.region(&format!("solid[{i}]"), r, true)?;
    }
    Ok(())
}

/// One `[[emitter]]`: a box in the tank, a velocity within `max_speed`, start before stop, a
/// fill in (0, 1].
fn emitter(ch: &Checker, key: &str, e: &EmitterFile, max_speed: f64) -> Checked<()> {
    ch.inside(&format!("{key}.min"), &e.min)?;
    ch.inside(&format!("{key}.max"), &e.max)?;
    ch.len(&format!("{key}.velocity"), &e.velocity)?;
    let speed = e.velocity.iter().fold(0.0f64, |a, v| a.hypot(*v));
    if speed > max_speed {
        let why = format!("{speed:.3e} m/s is faster than simulation.max_speed ({max_speed} m/s)");
        return ch.err(&format!("{key}.velocity"), ErrorKind::Range, why);
    }
    if !(e.start.is_finite() && e.start >= 0.0) {
        let why = format!("must be a time >= 0 s, got {}", e.start);
        return ch.err(&format!("{key}.start"), ErrorKind::Range, why);
    }
    if let Some(stop) = e.stop.filter(|&stop| stop.is_nan() || stop <= e.start) {
        let why = format!("must be after start ({} s), got {stop}", e.start);
        return ch.err(&format!("{key}.stop"), ErrorKind::Range, why);
    }
    if let Some(f) = e.until_fill.filter(|&f| !(f > 0.0 && f <= 1.0)) {
        return ch.err(
            &format!("{key}.until_fill"),
            ErrorKind::Range,
            format!("must be in (0, 1], got {f}"),
        );
    }
    Ok(())
}

/// Section `obstacle`: shapes, velocities, names (unique, path-safe) and motion keys.
fn obstacles(ch: &Checker, obstacles: &[ObstacleFile]) -> Checked<()> {
    let mut names = BTreeSet::new();
    for (i, o) in obstacles.iter().enumerate() {
        let key = format!("obstacle[{i}]");
        ch.region(&key, &o.region(), false)?;
        ch.len(&format!("{key}.velocity"), &o.velocity)?;
        let ok = !o.name.is_empty()
            && o.name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !ok {
            let why = format!("must be letters, digits, '-' or '_', got '{}'", o.name);
            return ch.err(&format!("{key}.name"), ErrorKind::Range, why);
        }
        motion(ch, &key, o)?;
        if !names.insert(o.name.clone()) {
            let why = format!("'{}' names two obstacles", o.name);
            return ch.err(&format!("{key}.name"), ErrorKind::Conflict, why);
        }
    }
    Ok(())
}

/// An obstacle's motion: a falling one needs its terminal speed; only a falling one takes
/// `terminal_speed` and `drag`.
fn motion(ch: &Checker, key: &str, o: &ObstacleFile) -> Checked<()> {
    match (o.motion, o.terminal_speed, o.drag) {
        (MotionKind::Falling, None, _) => ch.err(
            &format!("{key}.terminal_speed"),
            ErrorKind::Keys,
            "a falling obstacle needs its terminal speed in the water (m/s)".into(),
        ),
        (MotionKind::Falling, Some(v), _) if !(v.is_finite() && v >= 0.0) => ch.err(
            &format!("{key}.terminal_speed"),
            ErrorKind::Range,
            format!("must be a speed >= 0 m/s, got {v}"),
        ),
        (MotionKind::Falling, _, Some(d)) if !(d.is_finite() && d > 0.0) => ch.err(
            &format!("{key}.drag"),
            ErrorKind::Range,
            format!("must be a rate > 0 per second, got {d}"),
        ),
        (MotionKind::Constant, Some(_), _) | (MotionKind::Constant, _, Some(_)) => ch.err(
            key,
            ErrorKind::Keys,
            "'terminal_speed' and 'drag' apply to motion = \"falling\" only".into(),
        ),
        _ => Ok(()),
    }
}

/// `simulation.obstacle`: one of the method's modes, its first by default.
fn obstacle_mode(
    ch: &Checker,
    s: &SimulationFile,
    method: &MethodSettings,
) -> Checked<crate::stages::solids::ObstacleMode> {
    let info = method.kind.info();
    let mode = s.obstacle.unwrap_or(info.obstacle_modes[0]);
    if info.obstacle_modes.contains(&mode) {
        return Ok(mode);
    }
    let modes: Vec<&str> = info.obstacle_modes.iter().map(|m| m.name()).collect();
    let why = format!(
        "method {} cannot use obstacle mode '{}' (it has: {}); ccp couples obstacles through \
         its correction (sec. 7), the other methods wait ('naive') or move regardless ('ignore')",
        info.name,
        mode.name(),
        modes.join(", ")
    );
    ch.err("simulation.obstacle", ErrorKind::Conflict, why)
}

/// Every obstacle starts clear of the static solids and of the other obstacles, cell by cell
/// at the scene's resolution. The work of the obstacles' cells: a cell's solid is asked of the
/// regions, and the obstacles' cells are kept as they are checked.
fn obstacles_start_clear<const D: usize>(ch: &Checker, scene: &Scene) -> Checked<()> {
    let config = scene.config::<D>();
    let grid = Grid::new(config.dims);
    // What holds a cell, named as in the scene file: the last static solid whose region holds
    // its centre, or an obstacle checked before.
    let mut obstacle: HashMap<usize, String> = HashMap::new();
    let holder = |c: usize, obstacle: &HashMap<usize, String>| {
        let x = grid.center(grid.cell_coords(c));
        match config.solids.iter().rposition(|r| r.contains(&x)) {
            Some(i) => Some(format!("solid[{i}]")),
            None => obstacle.get(&c).cloned(),
        }
    };
    for (i, o) in config.obstacles.iter().enumerate() {
        let cells = o.cells_at(&grid, &o.offset);
        if let Some((c, held_by)) = cells.iter().find_map(|&c| Some((c, holder(c, &obstacle)?))) {
            let why = format!(
                "'{}' starts in a cell of {held_by} (cell {:?}); obstacles must start clear of \
                 solids and of each other",
                o.name,
                grid.cell_coords(c)
            );
            return ch.err(&format!("obstacle[{i}]"), ErrorKind::Geometry, why);
        }
        let name = format!("obstacle[{i}] '{}'", o.name);
        obstacle.extend(cells.into_iter().map(|c| (c, name.clone())));
    }
    Ok(())
}

/// Every fluid region and emitter holds at least one cell centre at the scene's resolution:
/// one that holds none would seed or emit nothing.
fn regions_cover_cells<const D: usize>(ch: &Checker, scene: &Scene) -> Checked<()> {
    let config = scene.config::<D>();
    let grid = Grid::new(config.dims);
    let fluid = config
        .fluid
        .iter()
        .enumerate()
        .map(|(i, r)| (format!("fluid[{i}]"), r, "seed"));
    let emitters = (config.emitters.iter().enumerate())
        .map(|(i, e)| (format!("emitter[{i}]"), &e.region, "emit"));
    for (key, region, verb) in fluid.chain(emitters) {
        if region.cells(&grid).next().is_none() {
            let why = format!(
                "holds no cell centre at this resolution (cells of {} m), so it would {verb} nothing",
                ch.h
            );
            return ch.err(&key, ErrorKind::Geometry, why);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::ccp::Solver;
    use crate::methods::MethodFlags;

    fn band_of(s: &Scene) -> Option<&'static str> {
        s.method.band().map(|b| b.variant)
    }

    #[test]
    fn a_toml_error_names_the_key_it_points_at() {
        let text = "name = \"x\"\n[simulation]\nband = \"wide\"\n[[fluid]]\nshape = \"box\"\n[[fluid]]\nshape = \"cone\"\n";
        assert_eq!(
            key_at(text, text.find("\"wide\"").unwrap()),
            "simulation.band"
        );
        assert_eq!(
            key_at(text, text.find("\"cone\"").unwrap()),
            "fluid[1].shape"
        );
        assert_eq!(key_at(text, 2), "name");
        assert_eq!(key_at("dim = 2\n[domain\n", 9), "domain");
    }

    /// A scene with `method` and the extra `[simulation]` lines, parsed with `overrides`.
    fn scene_with(method: &str, keys: &str, overrides: &super::super::Overrides) -> Checked<Scene> {
        let text = format!(
            "name = \"x\"\ndim = 2\n[domain]\nsize = [1.0, 1.0]\ncells = 8\n\
             [simulation]\nmethod = \"{method}\"\n{keys}\n\
             [[fluid]]\nshape = \"box\"\nmin = [0.0, 0.0]\nmax = [1.0, 0.5]\n"
        );
        let file: SceneFile = toml::from_str(&text).expect("valid TOML");
        method_keys("x.toml", &file.simulation)?;
        let mut file = file;
        overrides.apply(&mut file);
        check("x.toml", file, &overrides.flags)
    }

    #[test]
    fn a_method_key_the_files_method_lacks_is_refused_naming_the_key() {
        let none = super::super::Overrides::default();
        let e = scene_with("flip", "band = \"paths\"", &none).unwrap_err();
        assert_eq!(
            (e.key.as_str(), e.kind),
            ("simulation.band", ErrorKind::Conflict)
        );
        assert!(
            e.reason.contains("'flip'") && e.reason.contains("ccp"),
            "{e}"
        );
        let e = scene_with("ccp", "idp_resample = true", &none).unwrap_err();
        assert_eq!(e.key, "simulation.idp_resample");
        // A table named after its method applies when that method runs, whatever the file's.
        assert!(scene_with("idp", "[simulation.powerpic]\nrefine = 2", &none).is_ok());
        // Keys the method has are taken; R is both band methods'.
        assert!(scene_with("ccp", "band = \"paths\"\nband_r = 2", &none).is_ok());
        let nb = scene_with("nbflip", "band_r = 2", &none).unwrap();
        assert_eq!(nb.method.nbflip.band_r, 2);
        // A value its table refuses is refused naming the key as the file spelt it.
        let e = scene_with("ccp", "band = \"wide\"", &none).unwrap_err();
        assert_eq!(e.key, "simulation.band");
        assert!(
            e.reason.contains("wide") && e.reason.contains("paths"),
            "{e}"
        );
        let e = scene_with("idp", "idp_resample = 3", &none).unwrap_err();
        assert_eq!(e.key, "simulation.idp_resample");
    }

    #[test]
    fn another_method_from_the_command_line_runs_without_the_files_band() {
        let flip = super::super::Overrides {
            method: Some(crate::methods::MethodKind::Flip),
            ..Default::default()
        };
        let s = scene_with("ccp", "band = \"paths\"", &flip).unwrap();
        assert_eq!(s.method.kind, crate::methods::MethodKind::Flip);
        assert_eq!(band_of(&s), None);
        assert!(!s.run_tags().iter().any(|t| t.starts_with("band-")));
    }

    #[test]
    fn a_methods_own_check_names_its_key() {
        let none = super::super::Overrides::default();
        let e = scene_with("ccp", "band = \"paths\"\ndirections = \"moore\"", &none).unwrap_err();
        assert_eq!(
            (e.key.as_str(), e.kind),
            ("simulation.band", ErrorKind::Conflict)
        );
        let e = scene_with("nbflip", "band_r = 0", &none).unwrap_err();
        assert_eq!(
            (e.key.as_str(), e.kind),
            ("simulation.band_r", ErrorKind::Range)
        );
        let e = scene_with("powerpic", "[simulation.powerpic]\nrefine = 9", &none).unwrap_err();
        assert_eq!(e.key, "simulation.powerpic.refine");
    }

    #[test]
    fn a_methods_table_applies_whenever_it_runs_and_takes_the_flags() {
        let none = super::super::Overrides::default();
        let idp = super::super::Overrides {
            method: Some(crate::methods::MethodKind::Idp),
            ..Default::default()
        };
        // A ccp file configures idp for when idp runs it.
        let keys = "band_r = 6\n[simulation.idp]\nresample = true";
        let s = scene_with("ccp", keys, &idp).unwrap();
        assert!(s.method.idp.resample);
        // Its own method's table holds its keys: a key beside it is refused.
        let both = "band = \"paths\"\n[simulation.ccp]\nsolver = \"simplex\"";
        let e = scene_with("ccp", both, &none).unwrap_err();
        assert_eq!(
            (e.key.as_str(), e.kind),
            ("simulation.band", ErrorKind::Conflict)
        );
        assert!(e.reason.contains("[simulation.ccp]"), "{e}");
        // The table's unset keys take their defaults; the flags reach the table.
        let table = "[simulation.ccp]\nsolver = \"simplex\"";
        let s = scene_with("ccp", table, &none).unwrap();
        assert_eq!((s.method.ccp.solver, band_of(&s)), (Solver::Simplex, None));
        let band = super::super::Overrides {
            flags: MethodFlags(vec![("band", toml::Value::String("paths".into()))]),
            ..Default::default()
        };
        let s = scene_with("ccp", table, &band).unwrap();
        assert_eq!(band_of(&s), Some("paths"));
        // An unknown key in a table is refused naming it.
        let text_err = toml::from_str::<SceneFile>(
            "name = \"x\"\ndim = 2\n[domain]\nsize = [1.0, 1.0]\ncells = 8\n[simulation.idp]\nresampel = true\n",
        );
        let e = text_err.expect_err("an unknown key").to_string();
        assert!(e.contains("resampel"), "{e}");
    }
}
