//! A report's runs kept under `--out` (docs/report.md, "Stopped and started again"): each run
//! that ends is kept as `runs/<id>.result`, and the run under way is checkpointed in
//! `runs/<id>.checkpoints/` (every [`CHECKPOINT_WALL`] of wall time and when a signal stops
//! it). `cellflip report` started again with the same arguments and `--out` reads the ended
//! runs back instead of running them, and resumes the stopped one from its checkpoint, its
//! measurements so far included: the same rows as a report never stopped, but for the
//! timings.

use super::measured::{Gathered, Measured};
use super::options::MatrixOptions;
use super::RunSpec;
use crate::checkpoint::{Checkpoints, Opened, Origin};
use crate::machine::Machine;
use crate::metrics::{Stage, StageTimes};
use crate::runner::Summary;
use crate::scene::Scene;
use crate::snapshot::{Reader, SnapshotError, Writer};
use crate::step::Simulation;
use anyhow::{anyhow, Context, Result};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Wall time between a report run's checkpoints: what a crash or a SIGKILL can lose.
pub const CHECKPOINT_WALL: Duration = Duration::from_secs(120);

/// Where one run of a report keeps its result and its checkpoints.
#[derive(Clone, Debug)]
pub struct RunFiles {
    pub result: PathBuf,
    pub checkpoints: PathBuf,
    /// Wall time between checkpoints ([`CHECKPOINT_WALL`]).
    pub every: Duration,
    /// The matrix the run was planned from, kept with its result: `--merge` of the folder
    /// without matrix options merges the matrix its results name.
    pub matrix: MatrixOptions,
}

impl RunFiles {
    /// The files of `spec`, of the `matrix`, under the report's `out` folder.
    pub fn of(out: &Path, spec: &RunSpec, matrix: &MatrixOptions) -> Self {
        let dir = out.join("runs");
        let id = id(spec);
        Self {
            result: dir.join(format!("{id}.result")),
            checkpoints: dir.join(format!("{id}.checkpoints")),
            every: CHECKPOINT_WALL,
            matrix: matrix.clone(),
        }
    }
}

/// A name of the run as the matrix gives it: its label, method, resolution and seed, readable,
/// and a digest of all it is run with (scene text, duration, budget), so that another matrix
/// in the same `--out` never takes its result unless it runs the very same run. (The matrix is
/// not in it: a run of two matrices is one job, whose result either takes.)
pub fn id(spec: &RunSpec) -> String {
    let label = crate::record::path_part(&spec.label);
    let or_default = |x: Option<String>| x.unwrap_or_else(|| "default".into());
    let (res, seed) = (
        spec.res.map(|r| r.to_string()),
        spec.seed.map(|s| s.to_string()),
    );
    let (method, res, seed) = (spec.method.name(), or_default(res), or_default(seed));
    let digest = crc32fast::hash(format!("{spec:?}").as_bytes());
    format!("{label}-{method}-r{res}-s{seed}-{digest:08x}")
}

/// Keeps a run that ended (not one a signal stopped) in its result file, with its matrix.
pub fn save_result(files: &RunFiles, m: &Measured) -> Result<()> {
    let path = &files.result;
    let mut w = Writer::default();
    w.meta("program", &*m.build);
    w.meta("matrix", files.matrix.to_meta());
    w.meta("status", &*m.status);
    w.meta("res", m.res.to_string());
    w.meta("seed", m.seed.to_string());
    w.meta("dim", m.dim.to_string());
    if let Some(machine) = &m.machine {
        write_machine(&mut w, machine);
    }
    let names: Vec<&str> = m.values.keys().map(String::as_str).collect();
    w.meta("values", names.join("\n"));
    w.owned(
        "values",
        &[names.len()],
        m.values.values().copied().collect(),
    );
    for (name, series) in [("volume", &m.volume), ("ke", &m.ke), ("front", &m.front)] {
        pairs(&mut w, name, series);
    }
    std::fs::create_dir_all(path.parent().expect("a file in runs/"))
        .and_then(|()| w.write_file(path).map(drop))
        .map_err(|e| anyhow!("cannot write '{}': {e}", path.display()))
}

/// A run kept by [`save_result`], for `spec`, by whichever build ran it ([`Measured::build`]:
/// a merge takes it and names its build, a report run again runs it again): `None` when there
/// is none, an error (why) when the file is there but cannot be read.
pub fn load_result(path: &Path, spec: &RunSpec) -> Result<Option<Measured>> {
    let Ok(bytes) = std::fs::read(path) else {
        return Ok(None);
    };
    let read = || -> Result<Measured, SnapshotError> {
        let r = Reader::from_bytes(bytes)?;
        let names = r.meta("values")?;
        let values = r.slice::<f64>("values", None)?;
        let names: Vec<&str> = names.split('\n').filter(|n| !n.is_empty()).collect();
        Ok(Measured {
            spec: spec.clone(),
            res: parsed(&r, "res")?,
            seed: parsed(&r, "seed")?,
            status: r.meta("status")?.to_string(),
            dim: parsed(&r, "dim")?,
            build: r.meta("program")?.to_string(),
            machine: read_machine(&r)?,
            values: names.iter().map(|n| n.to_string()).zip(values).collect(),
            volume: read_pairs(&r, "volume")?,
            ke: read_pairs(&r, "ke")?,
            front: read_pairs(&r, "front")?,
        })
    };
    read()
        .map(Some)
        .with_context(|| format!("'{}'", path.display()))
}

/// The machine that ran a result, under `machine.*`.
fn write_machine(w: &mut Writer<'_>, machine: &Machine) {
    w.meta("machine.cpu", &*machine.cpu);
    w.meta("machine.cores", machine.cores.to_string());
    w.meta("machine.threads", machine.threads.to_string());
    w.meta("machine.copy_gb_s", machine.copy_gb_s.to_string());
}

/// The machine [`write_machine`] kept; `None` in a result kept before results recorded it
/// (no `machine.cpu`).
fn read_machine(r: &Reader) -> Result<Option<Machine>, SnapshotError> {
    let Ok(cpu) = r.meta("machine.cpu") else {
        return Ok(None);
    };
    Ok(Some(Machine {
        cpu: cpu.to_string(),
        cores: parsed(r, "machine.cores")?,
        threads: parsed(r, "machine.threads")?,
        copy_gb_s: parsed(r, "machine.copy_gb_s")?,
    }))
}

/// The metadata string `k` read as a number.
fn parsed<T: std::str::FromStr>(r: &Reader, k: &str) -> Result<T, SnapshotError> {
    let v = r.meta(k)?;
    v.parse()
        .map_err(|_| SnapshotError::Header(format!("meta.{k} is '{v}'")))
}

/// The matrix a kept result (of any build) was planned from; `None` for a file that is not
/// one (damaged) or one kept before results named their matrix.
pub fn matrix_of(path: &Path) -> Option<MatrixOptions> {
    let r = Reader::from_bytes(std::fs::read(path).ok()?).ok()?;
    r.meta("matrix").ok().map(MatrixOptions::from_meta)
}

fn pairs(w: &mut Writer<'_>, name: &str, series: &[(f64, f64)]) {
    let flat = series.iter().flat_map(|&(a, b)| [a, b]).collect();
    w.owned(name, &[series.len(), 2], flat);
}

fn read_pairs(r: &Reader, name: &str) -> Result<Vec<(f64, f64)>, SnapshotError> {
    let (v, _) = r.array::<f64>(name)?;
    Ok(v.chunks_exact(2).map(|p| (p[0], p[1])).collect())
}

/// What a report run measured so far, beside the simulation in its checkpoints.
pub struct Progress<'a> {
    pub measured: &'a Measured,
    pub gathered: &'a Gathered,
    pub summary: &'a Summary,
    /// The lowest the first obstacle can get (from the run's start), metres.
    pub lowest: f64,
    /// Wall time the run has taken so far, over all its processes (its budget counts it).
    pub spent: Duration,
}

impl Progress<'_> {
    fn write(&self, w: &mut Writer<'_>) {
        let (m, g, sum) = (self.measured, self.gathered, self.summary);
        pairs(w, "report.volume", &m.volume);
        pairs(w, "report.ke", &m.ke);
        w.scalar("report.compression", g.compression);
        w.scalar("report.held", g.held);
        w.scalar("report.particles_held", g.particles_held);
        w.scalar("report.particles_all", g.particles_all);
        let names: Vec<&str> = g.figures.keys().copied().collect();
        w.meta("report.figures", names.join("\n"));
        for (name, xs) in &g.figures {
            w.owned(&format!("report.figure.{name}"), &[xs.len()], xs.clone());
        }
        if let Some(p) = &g.probe {
            let flat = p.series.iter().flat_map(|&(t, f, c)| [t, f, c]).collect();
            w.owned("report.probe", &[p.series.len(), 3], flat);
        }
        w.scalar("report.steps", sum.steps);
        w.scalar("report.volume_min", sum.volume_min);
        w.scalar("report.volume_max", sum.volume_max);
        let its = sum.pcg_iterations.iter().map(|&i| i as u64).collect();
        w.owned("report.pcg_iterations", &[sum.pcg_iterations.len()], its);
        let times = sum
            .step_times
            .iter()
            .flat_map(|t| t.0.map(|d| d.as_secs_f64()));
        let shape = [sum.step_times.len(), Stage::ALL.len()];
        w.owned("report.step_times", &shape, times.collect());
        w.scalar("report.lowest", self.lowest);
        w.scalar("report.spent", self.spent.as_secs_f64());
    }
}

/// Checkpoints of a report run: the simulation and its [`Progress`].
pub struct RunCheckpoints {
    checkpoints: Checkpoints,
    origin: Origin,
}

impl RunCheckpoints {
    /// The folder of `files`, for a run of `scene`; `resumed` is the checkpoint it goes on from.
    pub fn new(files: &RunFiles, scene: &Scene, resumed: Option<&Opened>) -> Result<Self> {
        let origin = Origin {
            scene_arg: scene.name().into(),
            scene_source: scene.source.clone(),
            scene_toml: scene.resolved_toml(),
            command: std::env::args().collect::<Vec<_>>().join(" "),
            frames: 0,
            recording: None,
            every: None,
            trails: vec![],
        };
        let checkpoints = Checkpoints::new(&files.checkpoints, resumed)?;
        Ok(Self {
            checkpoints,
            origin,
        })
    }

    pub fn save<const D: usize>(&mut self, sim: &Simulation<D>, p: &Progress<'_>) -> Result<()> {
        let written = self
            .checkpoints
            .write_with(sim, &self.origin, |w| p.write(w));
        Ok(written.map(drop)?)
    }

    /// The run ended: its checkpoints go (its result is kept instead).
    pub fn remove(self) {
        let _ = std::fs::remove_dir_all(self.checkpoints.dir());
    }
}

/// What [`Progress`] restores: the measurements into `m` and `g`, the summary's figures into
/// `sum`; returns the obstacle's lowest point and the wall time spent.
pub fn restore_progress(
    r: &Reader,
    m: &mut Measured,
    g: &mut Gathered,
    sum: &mut Summary,
) -> Result<(f64, Duration), SnapshotError> {
    m.volume = read_pairs(r, "report.volume")?;
    m.ke = read_pairs(r, "report.ke")?;
    g.compression = r.scalar("report.compression")?;
    g.held = r.scalar("report.held")?;
    g.particles_held = r.scalar("report.particles_held")?;
    g.particles_all = r.scalar("report.particles_all")?;
    let names = r.meta("report.figures")?;
    for name in names.split('\n').filter(|n| !n.is_empty()) {
        let known = crate::methods::MethodKind::ALL.iter();
        let name: &'static str = (known.flat_map(|k| k.info().figures.iter()))
            .find(|f| **f == name)
            .ok_or_else(|| SnapshotError::Missing(format!("method figure {name}")))?;
        g.figures
            .insert(name, r.slice(&format!("report.figure.{name}"), None)?);
    }
    if let Some(p) = &mut g.probe {
        let (v, _) = r.array::<f64>("report.probe")?;
        p.series = v.chunks_exact(3).map(|x| (x[0], x[1], x[2])).collect();
    }
    sum.steps = r.scalar("report.steps")?;
    sum.volume_min = r.scalar("report.volume_min")?;
    sum.volume_max = r.scalar("report.volume_max")?;
    let its = r.slice::<u64>("report.pcg_iterations", None)?;
    sum.pcg_iterations = its.into_iter().map(|i| i as usize).collect();
    let (times, _) = r.array::<f64>("report.step_times")?;
    sum.step_times = (times.chunks_exact(Stage::ALL.len()))
        .map(|t| StageTimes(std::array::from_fn(|k| Duration::from_secs_f64(t[k]))))
        .collect();
    let spent = Duration::from_secs_f64(r.scalar("report.spent")?);
    Ok((r.scalar("report.lowest")?, spent))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cmd::report::Source;
    use crate::methods::MethodKind;

    fn spec() -> RunSpec {
        RunSpec {
            label: "dam-2d".into(),
            source: Source::Named("dam-2d".into()),
            method: MethodKind::ALL[0],
            res: Some(24),
            seed: None,
            duration: Some(0.05),
            accuracy: true,
            stability: false,
            budget: None,
        }
    }

    /// A kept result names the machine that ran it; one kept before results did (the keys of
    /// those a sweep at commit 3b9a88e kept: no `matrix`, no `machine.*`) still reads, with
    /// its machine not recorded.
    #[test]
    fn a_result_keeps_its_machine_and_an_older_one_reads_without() {
        let dir = std::env::temp_dir().join(format!("cellflip-saved-{}", std::process::id()));
        let files = RunFiles::of(&dir, &spec(), &MatrixOptions::default());
        let machine = Machine {
            cpu: "Intel(R) Xeon(R) CPU E5-2680 v4 @ 2.40GHz".into(),
            cores: 28,
            threads: 4,
            copy_gb_s: 9.876_543_21,
        };
        let m = Measured {
            status: "ok".into(),
            machine: Some(machine.clone()),
            ..Measured::new(&spec())
        };
        save_result(&files, &m).unwrap();
        let kept = load_result(&files.result, &spec()).unwrap().unwrap();
        assert_eq!(kept.machine, Some(machine));

        let mut w = Writer::default();
        for (k, v) in [
            ("program", crate::checkpoint::build()),
            ("status", "ok"),
            ("res", "24"),
            ("seed", "1"),
            ("dim", "2"),
            ("values", "steps\nvolume_error"),
        ] {
            w.meta(k, v);
        }
        w.owned("values", &[2], vec![12.0, 0.5]);
        for name in ["volume", "ke", "front"] {
            w.owned::<f64>(name, &[0, 2], vec![]);
        }
        w.write_file(&files.result).unwrap();
        let old = load_result(&files.result, &spec()).unwrap().unwrap();
        assert_eq!((&old.machine, old.get("steps")), (&None, 12.0));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
