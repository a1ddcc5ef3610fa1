//! Checkpoints of `cellflip run` (docs/checkpoints.md): what a file holds besides the
//! simulation (the scene as run, the program, the recording it continues), how it is written
//! so that a half-written one is never taken for a whole one, which files are kept, and which
//! one `--resume` takes.
//!
//! A checkpoint is written to `.step-NNNNNNNN.ckpt.partial`, synced, renamed to
//! `step-NNNNNNNN.ckpt` and the folder synced; only then are older ones deleted, so the last
//! two complete checkpoints survive a crash, a second signal or a full disk at any moment.

use crate::frames::{FrameError, FrameWorker};
use crate::record::Recorder;
use crate::snapshot::{self, Reader, SnapshotError, Writer};
use crate::step::Simulation;
use std::fs::File;
use std::path::{Path, PathBuf};

/// Why a checkpoint could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot read checkpoint folder '{}'", .dir.display())]
    ReadDir {
        dir: PathBuf,
        #[source]
        error: std::io::Error,
    },
    #[error("cannot read checkpoint '{}'", .path.display())]
    Read {
        path: PathBuf,
        #[source]
        error: std::io::Error,
    },
    /// Read, but not a whole checkpoint of this format.
    #[error("checkpoint '{}'", .path.display())]
    Damaged {
        path: PathBuf,
        #[source]
        error: SnapshotError,
    },
    /// A folder whose checkpoints are all damaged: the newest's error.
    #[error("no complete checkpoint in '{}'", .dir.display())]
    AllDamaged {
        dir: PathBuf,
        #[source]
        newest: Box<CheckpointError>,
    },
    #[error(
        "no complete checkpoint in '{}' (no step-*.ckpt file; a .partial file is one whose \
         writing did not finish)",
        .dir.display()
    )]
    Empty { dir: PathBuf },
    #[error("--checkpoint-dir '{}': cannot write there", .dir.display())]
    NotWritable {
        dir: PathBuf,
        #[source]
        error: std::io::Error,
    },
    #[error("cannot write checkpoint '{}'", .path.display())]
    Write {
        path: PathBuf,
        #[source]
        error: std::io::Error,
    },
    /// The frames to note in it could not be drawn.
    #[error(transparent)]
    Frames(#[from] FrameError),
}

/// Complete checkpoints a run keeps in its folder: the newest and the one before it.
pub const KEEP: usize = 2;

/// This build of cellflip: its version and a CRC-32 of its executable. A checkpoint or a
/// report's kept run from another build may not continue or equal what this one computes.
pub fn build() -> &'static str {
    static BUILD: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| {
        let exe = std::env::current_exe()
            .and_then(File::open)
            .and_then(snapshot::crc_of);
        let crc = exe.map_or_else(|_| "unknown".into(), |c| format!("{c:08x}"));
        format!("cellflip {} ({crc})", env!("CARGO_PKG_VERSION"))
    });
    &BUILD
}

/// Where a run's recording stood when a checkpoint was written, for the resumed run to go on
/// with it: the file, its recording id, and its length in bytes with every step up to the
/// checkpoint's written (what lies beyond is cut off, so that no step is recorded twice).
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingMark {
    pub path: PathBuf,
    pub id: String,
    pub bytes: u64,
}

/// What a checkpoint says of the run it came from, beside the simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct Origin {
    /// The scene as the command line named it (a built-in name or a file's path).
    pub scene_arg: String,
    /// Where the scene came from, as errors name it (`built-in scene 'dam-2d'`).
    pub scene_source: String,
    /// The scene as run: the file with the command line's overrides applied.
    pub scene_toml: String,
    /// The command line that started the run (for the reader; nothing is parsed from it).
    pub command: String,
    /// Frames drawn so far (3D surfaces, `--export-frames` files number on from it).
    pub frames: u64,
    /// The recording file, if the run wrote one.
    pub recording: Option<RecordingMark>,
    /// `--checkpoint-every`: a resumed run checkpoints as the run it goes on with.
    pub every: Option<f64>,
    /// Each obstacle's trail so far in the recording (its centre at every recorded step, in
    /// world coordinates), which the recording draws whole at every recorded step.
    pub trails: Vec<Vec<[f32; 3]>>,
}

impl Origin {
    fn write(&self, w: &mut Writer<'_>) {
        for (k, t) in self.trails.iter().enumerate() {
            let flat = t.iter().flatten().map(|&x| x as f64).collect();
            w.owned(&format!("recording.trail.{k}"), &[t.len(), 3], flat);
        }
        w.meta("program", build());
        w.meta("scene.arg", &*self.scene_arg);
        w.meta("scene.source", &*self.scene_source);
        w.meta("scene.toml", &*self.scene_toml);
        w.meta("command", &*self.command);
        w.meta("frames", self.frames.to_string());
        if let Some(e) = self.every {
            w.meta("checkpoint_every", e.to_string());
        }
        if let Some(r) = &self.recording {
            w.meta("recording.path", r.path.to_string_lossy());
            w.meta("recording.id", &*r.id);
            w.meta("recording.bytes", r.bytes.to_string());
        }
    }

    fn read(r: &Reader) -> Result<Self, SnapshotError> {
        let mut trails = vec![];
        while let Ok((v, _)) = r.array::<f64>(&format!("recording.trail.{}", trails.len())) {
            trails.push(
                v.chunks_exact(3)
                    .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
                    .collect(),
            );
        }
        let text = |k: &str| r.meta(k).map(str::to_string);
        let number = |k: &str| -> Result<u64, SnapshotError> {
            let v = r.meta(k)?;
            v.parse().map_err(|_| SnapshotError::Array {
                name: format!("meta.{k}"),
                reason: format!("'{v}', not a count"),
            })
        };
        let recording = match r.meta("recording.path") {
            Ok(path) => Some(RecordingMark {
                path: path.into(),
                id: text("recording.id")?,
                bytes: number("recording.bytes")?,
            }),
            Err(_) => None,
        };
        Ok(Self {
            scene_arg: text("scene.arg")?,
            scene_source: text("scene.source")?,
            scene_toml: text("scene.toml")?,
            command: text("command")?,
            frames: number("frames")?,
            recording,
            every: match r.meta("checkpoint_every") {
                Ok(v) => Some(v.parse().map_err(|_| SnapshotError::Array {
                    name: "meta.checkpoint_every".into(),
                    reason: format!("'{v}', not a number"),
                })?),
                Err(_) => None,
            },
            trails,
        })
    }
}

/// A checkpoint read and checked: its file, its reader and its origin.
pub struct Opened {
    pub path: PathBuf,
    pub reader: Reader,
    pub origin: Origin,
    /// The step it was written after.
    pub step: u64,
}

/// The file name of the checkpoint after `step`.
pub fn file_name(step: u64) -> String {
    format!("step-{step:08}.ckpt")
}

/// The step of a complete checkpoint's file name.
fn step_of(name: &str) -> Option<u64> {
    let digits = name.strip_prefix("step-")?.strip_suffix(".ckpt")?;
    digits
        .bytes()
        .all(|b| b.is_ascii_digit())
        .then(|| digits.parse().ok())?
}

/// The complete checkpoints in `dir` by step, oldest first.
fn complete(dir: &Path) -> Result<Vec<(u64, PathBuf)>, CheckpointError> {
    let entries = std::fs::read_dir(dir).map_err(|error| CheckpointError::ReadDir {
        dir: dir.into(),
        error,
    })?;
    let mut found: Vec<(u64, PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| Some((step_of(e.file_name().to_str()?)?, e.path())))
        .collect();
    found.sort();
    Ok(found)
}

/// Reads `path`, a checkpoint file or a checkpoint folder (its newest complete checkpoint:
/// one that a later write damaged is passed over, with a warning, for the one before).
pub fn open(path: &Path) -> Result<Opened, CheckpointError> {
    if !path.is_dir() {
        return open_file(path);
    }
    let found = complete(path)?;
    let mut damaged = vec![];
    for (_, file) in found.iter().rev() {
        match open_file(file) {
            Ok(c) => {
                for e in damaged {
                    let e = crate::out::chain(&e);
                    eprintln!("warning: {e}; resuming from the checkpoint before it");
                }
                return Ok(c);
            }
            Err(e) => damaged.push(e),
        }
    }
    let dir = path.to_path_buf();
    Err(match damaged.into_iter().next() {
        Some(e) => CheckpointError::AllDamaged {
            dir,
            newest: Box::new(e),
        },
        None => CheckpointError::Empty { dir },
    })
}

/// Reads and checks one checkpoint file.
fn open_file(path: &Path) -> Result<Opened, CheckpointError> {
    let bytes = std::fs::read(path).map_err(|error| CheckpointError::Read {
        path: path.into(),
        error,
    })?;
    let bad = |error| CheckpointError::Damaged {
        path: path.into(),
        error,
    };
    let reader = Reader::from_bytes(bytes).map_err(bad)?;
    let origin = Origin::read(&reader).map_err(bad)?;
    let step = reader.scalar::<u64>("steps").map_err(bad)?;
    Ok(Opened {
        path: path.to_path_buf(),
        reader,
        origin,
        step,
    })
}

/// A run's checkpoint folder: writes checkpoints and keeps this run's newest [`KEEP`].
pub struct Checkpoints {
    dir: PathBuf,
    /// This run's complete checkpoints, oldest first (with a resumed run's first).
    written: Vec<PathBuf>,
    /// Whether the folder still holds other runs' checkpoints (removed at the first write).
    first: bool,
    /// The step of the last checkpoint written or resumed from.
    pub last_step: Option<u64>,
}

impl Checkpoints {
    /// The folder `dir`, made if missing and checked writable before the run starts;
    /// `resumed` is the checkpoint the run resumed from.
    pub fn new(dir: &Path, resumed: Option<&Opened>) -> Result<Self, CheckpointError> {
        let fail = |error| CheckpointError::NotWritable {
            dir: dir.into(),
            error,
        };
        std::fs::create_dir_all(dir).map_err(fail)?;
        let probe = dir.join(".cellflip-write-test");
        File::create(&probe).map_err(fail)?;
        let _ = std::fs::remove_file(&probe);
        let resumed_here = resumed.filter(|c| c.path.parent() == Some(dir));
        Ok(Self {
            dir: dir.to_path_buf(),
            written: resumed_here.map(|c| c.path.clone()).into_iter().collect(),
            first: true,
            last_step: resumed.map(|c| c.step),
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes the checkpoint of `sim` after its last step; then deletes what it replaces.
    /// On failure the file being written is removed and the earlier ones are untouched.
    pub fn write<const D: usize>(
        &mut self,
        sim: &Simulation<D>,
        origin: &Origin,
    ) -> Result<PathBuf, CheckpointError> {
        self.write_with(sim, origin, |_| {})
    }

    /// [`Checkpoints::write`] with what `more` adds (a report's measurements so far).
    pub fn write_with<const D: usize>(
        &mut self,
        sim: &Simulation<D>,
        origin: &Origin,
        more: impl FnOnce(&mut Writer<'_>),
    ) -> Result<PathBuf, CheckpointError> {
        let step = sim.state.steps;
        let path = self.dir.join(file_name(step));
        let mut w = Writer::default();
        origin.write(&mut w);
        sim.save(&mut w);
        more(&mut w);
        if let Err(error) = w.write_file(&path) {
            return Err(CheckpointError::Write { path, error });
        }
        self.written.retain(|p| p != &path);
        self.written.push(path.clone());
        self.last_step = Some(step);
        self.prune();
        Ok(path)
    }

    /// Keeps this run's newest [`KEEP`]; at the first write, removes other runs' checkpoints
    /// and half-written files left in the folder.
    fn prune(&mut self) {
        let old = self.written.len().saturating_sub(KEEP);
        for p in self.written.drain(..old) {
            let _ = std::fs::remove_file(p);
        }
        if std::mem::take(&mut self.first) {
            let others = complete(&self.dir).unwrap_or_default();
            let others = others
                .into_iter()
                .map(|(_, p)| p)
                .filter(|p| !self.written.contains(p));
            let partials = std::fs::read_dir(&self.dir)
                .into_iter()
                .flatten()
                .flatten()
                .map(|e| e.path());
            let partials = partials.filter(|p| p.to_string_lossy().ends_with(".ckpt.partial"));
            for p in others.chain(partials.collect::<Vec<_>>()) {
                let _ = std::fs::remove_file(p);
            }
        }
    }
}

/// A run's checkpointing: when it writes one, where, and what it notes of the run.
pub struct Saver {
    pub checkpoints: Checkpoints,
    /// Simulated seconds between checkpoints.
    every: f64,
    /// The run's origin; the recording's length and the frames are filled in at each write.
    origin: Origin,
}

impl Saver {
    pub fn new(checkpoints: Checkpoints, every: f64, origin: Origin) -> Self {
        Self {
            checkpoints,
            every,
            origin: Origin {
                every: Some(every),
                ..origin
            },
        }
    }

    /// Whether a step from `before` to `after` simulated seconds passed a checkpoint's time.
    pub fn due(&self, before: f64, after: f64) -> bool {
        (after / self.every).floor() > (before / self.every).floor()
    }

    /// Whether the last checkpoint is of the simulation's current step.
    pub fn is_current<const D: usize>(&self, sim: &Simulation<D>) -> bool {
        self.checkpoints.last_step == Some(sim.state.steps)
    }

    /// Writes a checkpoint of `sim` with the recording up to now (the frames handed to the
    /// frame worker drawn first) noted in it.
    pub fn save<const D: usize>(
        &mut self,
        sim: &Simulation<D>,
        recorder: Option<&Recorder>,
        frames: Option<&mut FrameWorker>,
    ) -> Result<PathBuf, CheckpointError> {
        if let Some(f) = frames {
            f.wait()?;
            self.origin.frames = f.submitted();
        }
        self.origin.trails = recorder.map(Recorder::trails).unwrap_or_default();
        self.origin.recording = recorder.and_then(|r| {
            let (path, bytes) = r.written()?;
            Some(RecordingMark {
                path,
                id: r.id(),
                bytes,
            })
        });
        self.checkpoints.write(sim, &self.origin)
    }
}

/// The default checkpoint folder: beside the recording, `<recording stem>.checkpoints/`, or
/// without a recording file `recordings/<scene>.checkpoints/`.
pub fn default_dir(recording: Option<&Path>, scene: &str) -> PathBuf {
    match recording {
        Some(p) => {
            let stem = p
                .file_stem()
                .map_or_else(|| scene.into(), |s| s.to_string_lossy());
            p.with_file_name(format!("{stem}.checkpoints"))
        }
        None => Path::new("recordings").join(format!("{scene}.checkpoints")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_whole_checkpoint_names_count() {
        assert_eq!(step_of("step-00000120.ckpt"), Some(120));
        assert_eq!(step_of(".step-00000120.ckpt.partial"), None);
        assert_eq!(step_of("step-12a.ckpt"), None);
        assert_eq!(step_of("step-.ckpt"), None);
        assert_eq!(file_name(7), "step-00000007.ckpt");
    }

    /// A run keeps its newest two; its first write removes what other runs left (whole or
    /// half-written), the checkpoint it resumed from is its own.
    #[test]
    fn a_run_keeps_its_last_two_checkpoints_and_clears_other_runs() {
        let dir = std::env::temp_dir().join(format!("cellflip-ckpt-keep-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(file_name(9999)), b"another run").unwrap();
        std::fs::write(dir.join(".step-00000003.ckpt.partial"), b"half").unwrap();
        let scene = crate::scene::Scene::load("dam-2d", &Default::default()).unwrap();
        let mut sim = Simulation::<2>::new(scene.config::<2>(), &scene.method);
        let origin = Origin {
            scene_arg: "dam-2d".into(),
            scene_source: scene.source.clone(),
            scene_toml: scene.resolved_toml(),
            command: "test".into(),
            frames: 0,
            recording: None,
            every: None,
            trails: vec![],
        };
        let mut c = Checkpoints::new(&dir, None).unwrap();
        let names = |d: &Path| {
            let mut v: Vec<String> = std::fs::read_dir(d)
                .unwrap()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        for _ in 0..3 {
            sim.step().unwrap();
            c.write(&sim, &origin).unwrap();
        }
        assert_eq!(names(&dir), [file_name(2), file_name(3)]);
        // Resumed from step 3: the run's own; a later write keeps it as the one before.
        let opened = open(&dir).unwrap();
        assert_eq!((opened.step, &opened.origin), (3, &origin));
        let mut c = Checkpoints::new(&dir, Some(&opened)).unwrap();
        sim.step().unwrap();
        c.write(&sim, &origin).unwrap();
        assert_eq!(names(&dir), [file_name(3), file_name(4)]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_default_folder_sits_beside_the_recording() {
        let p = default_dir(Some(Path::new("out/run.rrd")), "dam-2d");
        assert_eq!(p, Path::new("out/run.checkpoints"));
        let p = default_dir(None, "dam-2d");
        assert_eq!(p, Path::new("recordings/dam-2d.checkpoints"));
    }
}
