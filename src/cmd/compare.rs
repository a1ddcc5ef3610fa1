//! `cellflip compare`: several methods on one scene, in one process, into one recording.
//!
//! Every run loads the same scene with the same seed and its own method (and obstacle mode).
//! The runs advance frame by frame: to each frame's simulated time (every `--frame-dt`
//! seconds) each run takes its own steps until it reaches it, and the step that reaches it is
//! drawn. Stepping in frames changes nothing in a run (the step does not depend on where the
//! runner stops), so each run's series equal those of `cellflip run` with the same scene,
//! method and seed. A run that fails stops alone: its world says why and when, the others go
//! on; a signal ends them all after the current step and finishes the recording.

use crate::cmd::cli::CompareArgs;
use crate::cmd::export;
use crate::frames::FrameWorker;
use crate::interrupt::{self, Watchdog};
use crate::methods::MethodKind;
use crate::record::{ComparedRun, Comparison};
use crate::runner::{Limit, Runner};
use crate::scene::{Overrides, Scene};
use crate::stages::solids::ObstacleMode;
use crate::step::Simulation;
use anyhow::{bail, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::cell::RefCell;
use std::time::{Duration, Instant};

/// One run of the comparison: what it runs and how the recording names it.
struct Entry {
    scene: Scene,
    label: String,
    title: String,
}

/// `cellflip compare`.
pub fn compare(args: &CompareArgs) -> Result<()> {
    if !(args.frame_dt.is_finite() && args.frame_dt > 0.0) {
        bail!(
            "--frame-dt {}: must be a positive number of seconds",
            args.frame_dt
        );
    }
    let entries = entries(args)?;
    let scenes: Vec<&Scene> = entries.iter().map(|e| &e.scene).collect();
    crate::scene::ensure_fit(&scenes, !args.sink.no_record)?;
    let sink = args
        .sink
        .choice(&format!("{}-compare", entries[0].scene.name()), &args.serve)?;
    if let (Some(s), false) = (&sink, args.no_viewer_check) {
        s.check_reachable()?;
    }
    interrupt::install()?;
    match entries[0].scene.dim() {
        2 => compare_dim::<2>(&entries, sink.as_ref(), args),
        3 => compare_dim::<3>(&entries, sink.as_ref(), args),
        d => unreachable!("scene checks the dimension, got {d}"),
    }
}

/// The runs `--methods` asks for, each scene loaded and checked before anything runs.
fn entries(args: &CompareArgs) -> Result<Vec<Entry>> {
    let specs: Vec<(MethodKind, Option<ObstacleMode>)> = match args.methods.is_empty() {
        true => MethodKind::ALL.iter().map(|&k| (k, None)).collect(),
        false => args.methods.clone(),
    };
    let mut out: Vec<Entry> = vec![];
    for (method, obstacle) in specs {
        let o = Overrides {
            method: Some(method),
            obstacle,
            duration: args.scale.duration,
            cells: args.scale.res,
            ppc: args.scale.ppc,
            seed: args.scale.seed,
            ..Default::default()
        };
        let scene = Scene::load(&args.scene, &o)?;
        let (label, title) = match obstacle {
            Some(m) => (
                format!("{}-{}", method.name(), m.name()),
                format!("{} ({})", method.name(), m.name()),
            ),
            None => (method.name().to_string(), method.name().to_string()),
        };
        if out.iter().any(|e| e.label == label) {
            bail!("--methods: '{title}' is given twice");
        }
        out.push(Entry {
            scene,
            label,
            title,
        });
    }
    Ok(out)
}

/// How a run of a comparison stands.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    Running,
    Failed { at: f64, why: String },
}

fn compare_dim<const D: usize>(
    entries: &[Entry],
    sink: Option<&crate::record::Sink>,
    args: &CompareArgs,
) -> Result<()> {
    let runs: Vec<ComparedRun<'_>> = entries
        .iter()
        .map(|e| ComparedRun {
            label: e.label.clone(),
            title: e.title.clone(),
            scene: &e.scene,
            color: e.scene.method.kind.rgb(),
            surface: !args.no_surface,
        })
        .collect();
    let labels: Vec<&str> = entries.iter().map(|e| e.title.as_str()).collect();
    let name = format!("{} compare {}", entries[0].scene.name(), labels.join(" "));
    let recording = sink
        .map(|s| Comparison::create(s, &name, &runs))
        .transpose()?;
    let mut runners = vec![];
    let mut workers = vec![];
    for (i, e) in entries.iter().enumerate() {
        let sim = Simulation::<D>::new(e.scene.config::<D>(), &e.scene.method);
        if let Some(r) = &recording {
            r.log_setup(i, &sim);
            r.log_step(i, &sim, None, true)?;
        }
        let sinks = [
            recording.as_ref().and_then(|r| r.surface_sink(i)),
            export::requested(&args.export, &e.scene, &e.label)?,
        ];
        let mut worker = FrameWorker::start(sinks.into_iter().flatten().collect(), 0)?;
        if let Some(w) = &mut worker {
            w.submit(&sim)?;
        }
        workers.push(worker);
        runners.push((Runner::new(sim), Status::Running));
    }
    let duration = entries[0].scene.duration_secs();
    let finisher = recording
        .as_ref()
        .map(|r| interrupt::finisher(r.finisher()));
    let watchdog = Watchdog::start(finisher, interrupt::GRACE);
    let frames = Frames {
        dt: args.frame_dt,
        until: duration,
        progress: !args.quiet,
    };
    let stepped = step_frames(
        &mut runners,
        &labels,
        recording.as_ref(),
        &mut workers,
        frames,
    );
    // The last frames are drawn and written before the recording is finished.
    let drawn = workers
        .into_iter()
        .flatten()
        .try_for_each(FrameWorker::finish);
    let stepped = stepped.and(drawn.map_err(Into::into));
    watchdog.done();
    let served = match (&stepped, recording) {
        (Ok(()), Some(r)) => r.finish()?,
        (Err(_), Some(r)) => {
            r.abandon();
            None
        }
        (_, None) => None,
    };
    stepped?;
    // Runs that stopped early are part of the comparison: it is served all the same.
    let summary = summarise(entries, &runners, args.quiet);
    if let Some(s) = served {
        s.hold_until_signal();
    }
    summary
}

/// How a comparison advances: a frame every `dt` simulated seconds until `until`.
#[derive(Clone, Copy, Debug)]
pub struct Frames {
    pub dt: f64,
    pub until: f64,
    /// Show a progress bar (after a second).
    pub progress: bool,
}

/// Steps every running run frame by frame to `frames.until` (or a signal), drawing each
/// frame, and handing it to the run's frame worker if it has one (`workers[i]`, see
/// [`crate::frames`]). A run's own failure stops it alone; a recording or an export that
/// cannot be written stops them all.
pub fn step_frames<const D: usize>(
    runners: &mut [(Runner<D>, Status)],
    titles: &[&str],
    recording: Option<&Comparison>,
    workers: &mut [Option<FrameWorker>],
    frames: Frames,
) -> Result<()> {
    let duration = frames.until;
    let bar = progress_bar(duration);
    let t0 = Instant::now();
    let interrupted = || interrupt::signal().is_some();
    let mut frame = 1u64;
    loop {
        let t_frame = (frame as f64 * frames.dt).min(duration);
        for (i, (runner, status)) in runners.iter_mut().enumerate() {
            if !matches!(status, Status::Running) {
                continue;
            }
            let write_error = RefCell::new(None);
            let mut worker = workers.get_mut(i).and_then(Option::as_mut);
            let stepped = runner.run(Limit::SimSeconds(t_frame), interrupted, |sim, rep| {
                let frame = sim.state.time_secs >= t_frame;
                let logged = recording.map_or(Ok(()), |r| r.log_step(i, sim, Some(rep), frame));
                let logged = logged.map_err(anyhow::Error::from);
                let handed = match (frame, worker.as_mut()) {
                    (true, Some(w)) => w.submit(sim),
                    _ => Ok(()),
                };
                logged.and(handed.map_err(Into::into)).inspect_err(|e| {
                    *write_error.borrow_mut() = Some(format!("{e:#}"));
                })
            });
            if let Some(e) = write_error.into_inner() {
                bail!("{e}");
            }
            if let Err(e) = stepped {
                let sim = &runner.sim;
                let why = format!("{e:#}");
                if let Some(r) = recording {
                    r.failed(i, sim, &why);
                }
                *status = Status::Failed {
                    at: sim.state.time_secs,
                    why,
                };
            }
        }
        let visible = frames.progress && t0.elapsed() > Duration::from_secs(1);
        show_progress(&bar, runners, titles, visible);
        let running = runners.iter().any(|(_, s)| matches!(s, Status::Running));
        if t_frame >= duration || interrupted() || !running {
            break;
        }
        frame += 1;
    }
    bar.finish_and_clear();
    Ok(())
}

/// Each run's summary, as `cellflip run` prints it; an error naming the runs that stopped.
fn summarise<const D: usize>(
    entries: &[Entry],
    runners: &[(Runner<D>, Status)],
    quiet: bool,
) -> Result<()> {
    let mut failed = vec![];
    for (e, (runner, status)) in entries.iter().zip(runners) {
        if !quiet {
            runner
                .summary
                .print(&format!("{} ({})", e.scene.name(), e.title));
            crate::outln!();
        }
        if let Status::Failed { at, why } = status {
            failed.push(format!("{} stopped at t = {at:.3} s: {why}", e.title));
        }
    }
    if !failed.is_empty() {
        bail!(
            "{} of {} runs stopped early (the others ran to the end):\n  {}",
            failed.len(),
            runners.len(),
            failed.join("\n  ")
        );
    }
    Ok(())
}

fn progress_bar(duration: f64) -> ProgressBar {
    let len = (duration * 1000.0).ceil() as u64;
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    let style = ProgressStyle::with_template("{bar:30} {pos}/{len} ms simulated  {msg}  ETA {eta}")
        .expect("a valid progress template");
    bar.set_style(style);
    bar
}

/// The slowest run's simulated time, and every run's volume (or that it stopped).
fn show_progress<const D: usize>(
    bar: &ProgressBar,
    runners: &[(Runner<D>, Status)],
    titles: &[&str],
    visible: bool,
) {
    if visible && bar.is_hidden() {
        bar.set_draw_target(ProgressDrawTarget::stderr());
    }
    let running = runners.iter().filter(|(_, s)| matches!(s, Status::Running));
    let slowest = running
        .map(|(r, _)| r.sim.state.time_secs)
        .fold(f64::INFINITY, f64::min);
    if slowest.is_finite() {
        bar.set_position((slowest * 1000.0) as u64);
    }
    let volumes: Vec<String> = (runners.iter().zip(titles))
        .map(|((r, s), t)| match s {
            Status::Running => format!("{t} {:.1}%", r.sim.state.volume_percent()),
            Status::Failed { .. } => format!("{t} stopped"),
        })
        .collect();
    bar.set_message(volumes.join("  "));
}
