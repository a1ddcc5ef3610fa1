//! `cellflip run`: a scene through the runner, with its progress bar, recording, checkpoints,
//! signal handling and the summary at the end; or the run a checkpoint holds, going on.

use crate::checkpoint::{self, Saver};
use crate::cmd::cli::{RunArgs, ServeArgs, SinkArgs};
use crate::cmd::export;
use crate::frames::FrameWorker;
use crate::interrupt::{self, Watchdog};
use crate::methods::StepFile;
use crate::record::{Drawing, Recorder, Sink, WebServe};
use crate::runner::{Exports, Limit, Runner};
use crate::scene::{peak_memory_mib, MemoryEstimate, Overrides, Scene};
use crate::step::Simulation;
use anyhow::{anyhow, bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod start;

use start::{checkpoint_every, checkpoints_of, recording_of, resumed_scene, Start};

impl RunArgs {
    fn overrides(&self) -> Overrides {
        Overrides {
            method: self.method,
            duration: self.scale.duration,
            cells: self.scale.res,
            ppc: self.scale.ppc,
            seed: self.scale.seed,
            obstacle: self.obstacle.map(Into::into),
            pressure: self.pressure.preconditioner.map(Into::into),
            flags: self.methods.clone(),
        }
    }
}

/// `cellflip run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let every = checkpoint_every(args.checkpoint.checkpoint_every)?;
    let t = Instant::now();
    let resumed = args
        .checkpoint
        .resume
        .as_deref()
        .map(checkpoint::open)
        .transpose()?;
    let read = t.elapsed();
    let scene = match &resumed {
        Some(c) => resumed_scene(args, c)?,
        None => {
            let name = args
                .scene
                .as_deref()
                .expect("clap asks for a scene without --resume");
            Scene::load(name, &args.overrides())?
        }
    };
    let estimate = scene.ensure_fits_in_memory(!args.sink.no_record)?;
    scene.method.check_flags(&args.methods)?;
    let limit = match args.steps {
        Some(0) => bail!("--steps: must be at least 1"),
        Some(n) => Limit::Steps(n),
        None => Limit::SimSeconds(scene.duration_secs()),
    };
    let drawing = Drawing {
        surface: !args.no_surface,
        moves: args.moves.into(),
        slice: parse_slice(args.slice.as_deref(), scene.dim())?,
    };
    let (sink, continued) = recording_of(args, &scene, resumed.as_ref())?;
    let mut method = scene.method.clone();
    let files = method.files(&files_stem(&scene, sink.as_ref().and_then(Sink::file))?);
    files.iter().try_for_each(|f| check_file_step(f, limit))?;
    if let (Some(s), false) = (&sink, args.no_viewer_check) {
        s.check_reachable()?;
    }
    let start = Start {
        method,
        files,
        checkpoints: checkpoints_of(args, every, &scene, sink.as_ref(), resumed.as_ref())?,
        continued,
        resumed,
        read,
    };
    interrupt::install()?;
    let sink = sink.as_ref();
    match scene.dim() {
        2 => run_dim::<2>(&scene, &estimate, limit, sink, drawing, args, start),
        3 => run_dim::<3>(&scene, &estimate, limit, sink, drawing, args, start),
        d => unreachable!("scene checks the dimension, got {d}"),
    }
}

fn run_dim<const D: usize>(
    scene: &Scene,
    estimate: &MemoryEstimate,
    limit: Limit,
    sink: Option<&Sink>,
    drawing: Drawing,
    args: &RunArgs,
    start: Start,
) -> Result<()> {
    let recorder = sink
        .map(|s| Recorder::create(s, scene, drawing, start.continued.as_ref()))
        .transpose()?;
    let files = start.files.clone();
    match simulate::<D>(scene, limit, recorder.as_ref(), args, start) {
        Ok(ran) => finish(scene, estimate, ran, recorder, sink, args, &files),
        Err(e) => {
            if let Some(r) = recorder {
                r.abandon();
            }
            Err(e)
        }
    }
}

/// The simulation at the run's start, new or restored from the checkpoint, with the
/// recording's static data (and step 0 of a new run) logged.
fn begin<const D: usize>(
    scene: &Scene,
    recorder: Option<&Recorder>,
    args: &RunArgs,
    start: &mut Start,
) -> Result<Simulation<D>> {
    let method = &start.method;
    let t0 = Instant::now();
    let sim = match start.resumed.as_mut() {
        Some(c) => {
            let sim = Simulation::<D>::restore(scene.config::<D>(), method, &c.reader)
                .map_err(|e| anyhow!("checkpoint '{}': {e}", c.path.display()))?;
            // The file's copy of the state is not kept for the whole run.
            c.reader.release();
            sim
        }
        None => Simulation::<D>::new(scene.config::<D>(), method),
    };
    let resumed = start.resumed.as_ref();
    if let (Some(c), false) = (resumed, args.quiet) {
        let (read, restored) = (start.read.as_secs_f64(), t0.elapsed().as_secs_f64());
        eprintln!(
            "resuming from '{}': step {}, t = {:.3} s (read and checked in {read:.2} s, \
             restored in {restored:.2} s)",
            c.path.display(),
            c.step,
            sim.state.time_secs
        );
    }
    if let Some(r) = recorder {
        r.log_setup(&sim);
        match resumed {
            Some(c) => r.set_trails(c.origin.trails.clone()),
            None => r.log_step(&sim, None, true)?,
        }
    }
    if sim.method.particles_not_held() > 0 && sim.state.particles.is_empty() {
        let msg = "the fluid has no free surface, so the band method put every particle in the \
                   deep: the run is grid-only (use --band none)";
        eprintln!("warning: {msg}");
        if let Some(r) = recorder {
            r.warn(&sim, msg);
        }
    }
    Ok(sim)
}

/// Sets the scene up and runs it, recording and checkpointing as it goes; the runner (with
/// its summary), how the run ended and its checkpoints.
fn simulate<const D: usize>(
    scene: &Scene,
    limit: Limit,
    recorder: Option<&Recorder>,
    args: &RunArgs,
    mut start: Start,
) -> Result<Ran<D>> {
    let sim = begin::<D>(scene, recorder, args, &mut start)?;
    let resumed = start.resumed.as_ref();
    let sinks = [
        recorder.and_then(Recorder::surface_sink),
        export::requested(&args.export, scene, scene.method.kind.name())?,
    ];
    let first_frame = resumed.map_or(0, |c| c.origin.frames);
    let mut frames = FrameWorker::start(sinks.into_iter().flatten().collect(), first_frame)?;
    if let (Some(f), None) = (&mut frames, resumed) {
        f.submit(&sim)?;
    }
    let mut saver = start.checkpoints;
    let mut runner = Runner::new(sim);
    let say = Announce {
        bar: progress_bar(limit),
        quiet: args.quiet,
    };
    let t0 = Instant::now();
    let grace = match saver {
        Some(_) => interrupt::CHECKPOINT_GRACE,
        None => interrupt::GRACE,
    };
    let watchdog = Watchdog::start(recorder.map(|r| interrupt::finisher(r.finisher())), grace);
    let interrupted = || interrupt::signal().is_some();
    let cadence = Cadence::of(args.record_every, D);
    let mut last_time_secs = runner.sim.state.time_secs;
    let mut exports = Exports::default();
    let result = runner.run(limit, interrupted, |sim, rep| {
        exports.write(sim, rep)?;
        let s = &sim.state;
        let full = cadence.records(s.steps, last_time_secs, s.time_secs);
        if let Some(r) = recorder {
            r.log_step(sim, Some(rep), full)?;
        }
        if let (true, Some(f)) = (full, frames.as_mut()) {
            f.submit(sim)?;
        }
        let asked = interrupt::take_checkpoint_request();
        match saver.as_mut() {
            Some(c) if asked || c.due(last_time_secs, s.time_secs) => {
                say.checkpoint(c, sim, recorder, frames.as_mut(), asked)?
            }
            None if asked => say.warn(NO_CHECKPOINTS),
            _ => {}
        }
        last_time_secs = s.time_secs;
        let visible = !args.quiet && t0.elapsed() > Duration::from_secs(1);
        show_progress(&say.bar, sim, limit, visible);
        Ok(())
    });
    runner.summary.written = exports.written;
    // A run that ended well or was stopped by a signal leaves a checkpoint of its last step
    // (a failed step may have left the state half-way).
    let last = match (&result, saver.as_mut()) {
        (Ok(()), Some(c)) if !c.is_current(&runner.sim) => {
            say.checkpoint(c, &runner.sim, recorder, frames.as_mut(), false)
        }
        _ => Ok(()),
    };
    // The last frames are drawn and written before the recording is finished.
    let drawn = frames.map_or(Ok(()), FrameWorker::finish);
    watchdog.done();
    say.bar.finish_and_clear();
    Ok(Ran {
        runner,
        result: result.and(last).and(drawn.map_err(Into::into)),
        saver,
    })
}

/// What SIGUSR1 gets from a run without checkpoints.
const NO_CHECKPOINTS: &str =
    "SIGUSR1 asks for a checkpoint; this run writes none (--checkpoint-every SECS)";

/// A run that got going: the runner (with its summary), how it ended, and its checkpoints.
struct Ran<const D: usize> {
    runner: Runner<D>,
    result: Result<()>,
    saver: Option<Saver>,
}

/// What a run says while its progress bar is up: above the bar, and nothing when quiet.
struct Announce {
    bar: ProgressBar,
    quiet: bool,
}

impl Announce {
    /// Writes a checkpoint and says where it went, its size and how long it took.
    fn checkpoint<const D: usize>(
        &self,
        saver: &mut Saver,
        sim: &Simulation<D>,
        recorder: Option<&Recorder>,
        frames: Option<&mut FrameWorker>,
        asked: bool,
    ) -> Result<()> {
        let t = Instant::now();
        let path = saver.save(sim, recorder, frames)?;
        if !self.quiet {
            let mb = std::fs::metadata(&path).map_or(0.0, |m| m.len() as f64 / 1e6);
            let why = if asked { ", asked for by SIGUSR1" } else { "" };
            let secs = t.elapsed().as_secs_f64();
            let line = format!(
                "checkpoint: {} ({mb:.1} MB in {secs:.2} s{why})",
                path.display()
            );
            self.bar.suspend(|| eprintln!("{line}"));
        }
        Ok(())
    }

    /// A warning, which `--quiet` does not silence.
    fn warn(&self, msg: &str) {
        self.bar.suspend(|| eprintln!("warning: {msg}"));
    }
}

/// Ends the recording (with the run's error or interruption in its log), prints the summary
/// and says how the run ended: an error, or `Ok` (the caller exits 128 + the signal's number
/// after an interrupted run).
fn finish<const D: usize>(
    scene: &Scene,
    estimate: &MemoryEstimate,
    ran: Ran<D>,
    recorder: Option<Recorder>,
    sink: Option<&Sink>,
    args: &RunArgs,
    files: &[StepFile],
) -> Result<()> {
    let Ran {
        runner,
        result,
        saver,
    } = ran;
    let mut served = None;
    if let Some(r) = recorder {
        let sim = &runner.sim;
        match (&result, interrupt::signal()) {
            (Err(e), _) => r.error(sim, &format!("{e:#}")),
            (Ok(()), Some(sig)) => r.warn(sim, &format!("run stopped by {}", interrupt::name(sig))),
            (Ok(()), None) => {}
        }
        served = match &result {
            Ok(()) => r.finish().context("cannot finish the recording")?,
            Err(_) => {
                r.abandon();
                None
            }
        };
    }
    if !args.quiet {
        summarise(scene, estimate, &runner, sink, saver.as_ref(), args);
    }
    let steps = runner.sim.state.steps;
    result.and_then(|()| files.iter().try_for_each(|f| check_file_written(f, steps)))?;
    if let Some(s) = served {
        s.hold_until_signal();
    }
    Ok(())
}

/// The run's summary: its stages and figures, its memory, where its recording and its
/// checkpoints went.
fn summarise<const D: usize>(
    scene: &Scene,
    estimate: &MemoryEstimate,
    runner: &Runner<D>,
    sink: Option<&Sink>,
    saver: Option<&Saver>,
    args: &RunArgs,
) {
    let mut title = format!(
        "{} ({}D, {}",
        scene.name(),
        scene.dim(),
        scene.method.kind.name()
    );
    if !scene.file.obstacle.is_empty() {
        title += &format!(", obstacles {}", scene.obstacle_mode.name());
    }
    title += ")";
    runner.summary.print(&title);
    if let Some(peak) = peak_memory_mib() {
        crate::outln!(
            "memory: peak {peak:.0} MiB resident (the process's); estimated up front {:.0} MiB",
            estimate.mib()
        );
    }
    let cadence = Cadence::of(args.record_every, D).describe();
    let live = match sink {
        Some(s @ (Sink::Spawn | Sink::Connect(_) | Sink::Stdout)) => {
            Some(format!("streamed to {}", s.describe()))
        }
        Some(Sink::Web { serve, .. }) => Some(format!("served at {}", serve.url())),
        _ => None,
    };
    if let Some(live) = live {
        crate::outln!("recording: {live}, particles and cells {cadence}");
    }
    if let Some(p) = sink.and_then(Sink::file).filter(|p| p.exists()) {
        let mb = std::fs::metadata(p).map_or(0.0, |m| m.len() as f64 / 1e6);
        crate::outln!(
            "recording: {}, {mb:.1} MB, particles and cells {cadence}  (open with: rerun {}, \
             or in a browser: cellflip view --serve-web {})",
            p.display(),
            p.display(),
            p.display()
        );
    }
    if let Some(c) = saver.map(|s| &s.checkpoints) {
        let last = c.last_step.map_or("none written".into(), |k| {
            format!("the last after step {k}")
        });
        crate::outln!(
            "checkpoints: {} ({last}; go on with: cellflip run --resume {})",
            c.dir().display(),
            c.dir().display()
        );
    }
}

impl SinkArgs {
    /// Where the recording goes: `None` without one; by default a file
    /// `recordings/<name>.rrd` (the folder is made here, so that it fails before the run);
    /// served to browsers too when `serve` says.
    pub fn choice(&self, name: &str, serve: &ServeArgs) -> Result<Option<Sink>> {
        if self.stdout {
            crate::out::to_stderr();
        }
        Ok(match self {
            s if s.no_record => None,
            s if s.spawn => Some(Sink::Spawn),
            s if s.stdout => Some(Sink::Stdout),
            SinkArgs {
                connect: Some(url), ..
            } => Some(Sink::Connect(url.clone())),
            SinkArgs { save, .. } if save.is_some() || serve.serve_web.is_some() => {
                serve.sink(save.clone())
            }
            _ => {
                let dir = PathBuf::from("recordings");
                std::fs::create_dir_all(&dir)
                    .with_context(|| format!("cannot create directory '{}'", dir.display()))?;
                Some(Sink::File(dir.join(format!("{name}.rrd"))))
            }
        })
    }
}

impl ServeArgs {
    /// How `--serve-web` serves, if given.
    pub fn web(&self) -> Option<WebServe> {
        Some(WebServe {
            web_port: self.serve_web?,
            grpc_port: self.grpc_port,
            bind: self.bind,
            memory_limit: self.server_memory_limit.clone(),
        })
    }

    /// The recording written to `file` (if any) and, with `--serve-web`, served.
    pub fn sink(&self, file: Option<PathBuf>) -> Option<Sink> {
        match (self.web(), file) {
            (Some(serve), save) => Some(Sink::Web { serve, save }),
            (None, Some(p)) => Some(Sink::File(p)),
            (None, None) => None,
        }
    }
}

/// When a step's particles, cells and moves are recorded (its metrics always are).
#[derive(Clone, Copy, Debug)]
enum Cadence {
    Steps(u64),
    SimSeconds(f64),
}

/// How often 3D runs record their particles and cells without `--record-every`, in simulated
/// seconds: 25 frames a second. A 50^3 frame takes about 1 MB (issue 15, item 9), so the 3 s
/// of dam-3d take about 75 frames.
const FRAME_SECS_3D: f64 = 1.0 / 25.0;

impl Cadence {
    /// `--record-every N`, or the default of the dimension: 2D every step, 3D by simulated time.
    fn of(record_every: Option<u64>, dim: usize) -> Self {
        match (record_every, dim) {
            (Some(n), _) => Cadence::Steps(n),
            (None, 2) => Cadence::Steps(1),
            (None, _) => Cadence::SimSeconds(FRAME_SECS_3D),
        }
    }

    /// Whether step `steps`, which took the clock from `before` to `after` seconds, is recorded.
    fn records(self, steps: u64, before: f64, after: f64) -> bool {
        match self {
            Cadence::Steps(n) => steps.is_multiple_of(n),
            Cadence::SimSeconds(f) => (after / f).floor() > (before / f).floor(),
        }
    }

    fn describe(self) -> String {
        match self {
            Cadence::Steps(1) => "every step".into(),
            Cadence::Steps(n) => format!("every {n} steps"),
            Cadence::SimSeconds(f) => format!("every {f} s simulated"),
        }
    }
}

/// `--slice AXIS[=FRACTION]` as `(axis, fraction)`, `z=0.5` when not given; refused for 2D
/// scenes.
fn parse_slice(arg: Option<&str>, dim: usize) -> Result<(usize, f64)> {
    let Some(s) = arg else {
        return Ok((2, 0.5));
    };
    if dim != 3 {
        bail!("--slice {s}: the scene is 2D; slices are drawn for 3D scenes only");
    }
    let (axis, at) = s.split_once('=').unwrap_or((s, "0.5"));
    let axis = match axis {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        _ => bail!("--slice {s}: the axis must be x, y or z"),
    };
    let at = at
        .parse::<f64>()
        .ok()
        .filter(|f| (0.0..=1.0).contains(f))
        .ok_or_else(|| {
            anyhow!("--slice {s}: the position must be a fraction of the tank, 0 to 1")
        })?;
    Ok((axis, at))
}

/// A file a flag asked for (`--export-lp N`) must be of a step the run can reach: steps
/// count from 1 and, with `--steps M`, end at M.
fn check_file_step(f: &StepFile, limit: Limit) -> Result<()> {
    match limit {
        _ if f.step == 0 => bail!("--{} 0: steps are numbered from 1", f.flag),
        Limit::Steps(m) if f.step > m => bail!(
            "--{} {n}: the run has only {m} steps (--steps {m}), so step {n} is never reached",
            f.flag,
            n = f.step
        ),
        _ => Ok(()),
    }
}

/// A run limited by time (or stopped by a signal) may end before the step a file was asked
/// for; then it was not written, and the run fails saying so (its recording is finished).
fn check_file_written(f: &StepFile, steps: u64) -> Result<()> {
    match steps < f.step {
        true => bail!(
            "--{} {n}: the run ended after {steps} steps, so step {n} was never reached and \
             '{}' was not written",
            f.flag,
            f.path.display(),
            n = f.step
        ),
        false => Ok(()),
    }
}

/// What files a method writes are named after ([`MethodSettings::files`]): the recording's
/// path without its extension, or without one `recordings/` (created here, so that a missing
/// folder fails before the run) and what tells runs of a scene apart ([`Scene::run_tags`]),
/// e.g. `recordings/dam-3d-ccp-band-paths-r6-50x50x50-ppc8-seed1`.
fn files_stem(scene: &Scene, out: Option<&Path>) -> Result<PathBuf> {
    let name = scene.run_tags().join("-");
    match out {
        Some(p) => Ok(p.with_file_name(name)),
        None => {
            let dir = Path::new("recordings");
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create directory '{}'", dir.display()))?;
            Ok(dir.join(name))
        }
    }
}

fn progress_bar(limit: Limit) -> ProgressBar {
    let (len, unit) = match limit {
        Limit::Steps(n) => (n, "steps"),
        Limit::SimSeconds(t) => ((t * 1000.0).ceil() as u64, "ms"),
    };
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    let style = ProgressStyle::with_template(&format!(
        "{{bar:30}} {{pos}}/{{len}} {unit}  {{msg}}  ETA {{eta}}"
    ))
    .expect("a valid progress template");
    bar.set_style(style);
    bar
}

/// Moves the bar; it appears once `visible` (runs longer than a second, not quiet).
fn show_progress<const D: usize>(
    bar: &ProgressBar,
    sim: &Simulation<D>,
    limit: Limit,
    visible: bool,
) {
    let s = &sim.state;
    if visible && bar.is_hidden() {
        bar.set_draw_target(ProgressDrawTarget::stderr());
    }
    bar.set_position(match limit {
        Limit::Steps(_) => s.steps,
        Limit::SimSeconds(_) => (s.time_secs * 1000.0) as u64,
    });
    bar.set_message(format!(
        "step {}  t = {:.3} s  volume {:.1}%",
        s.steps,
        s.time_secs,
        s.volume_percent()
    ));
}
