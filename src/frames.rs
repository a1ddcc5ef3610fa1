//! A drawn frame's heavy outputs, made on a thread of their own while the simulation goes on:
//! the liquid's surface in 3D ([`crate::surface`], drawn in the recording) and the files
//! `--export-frames` writes ([`crate::cmd::export`]).
//!
//! **Why a thread.** Reconstructing a surface takes about a third of a second at dam-3d 64^3,
//! a fifth of a run's wall time when done between the steps. The simulation keeps the two
//! cores busy only part of the time (about 1.4 of 2 on that run: the correction and MIC(0)'s
//! triangular solves are sequential), so the reconstruction runs beside it, on a thread pool of
//! its own with one thread ([`THREADS`]), and takes the idle time instead of the simulation's.
//!
//! **Order and back-pressure.** Frames are handed over in order through a channel that holds
//! one: the simulation waits only when the worker is a whole frame behind, so at most three
//! frames' copies are alive at once (one being drawn, one waiting, one being handed over). Each frame carries its step and simulated time, and the
//! recording logs it at those times, so drawing it late changes nothing in the viewer.
//!
//! **Errors.** A sink's error (an export file that cannot be written) stops the worker; the
//! next [`FrameWorker::submit`] or [`FrameWorker::finish`] returns it, naming the file.

use crate::out::BoxError;
use crate::step::Simulation;
use crate::surface::{Liquid, SurfaceMesh};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

/// The reconstruction's threads: one, so that it fills the core the simulation leaves idle
/// rather than competing with the simulation's own parallel loops for both.
pub const THREADS: usize = 1;

/// One drawn frame, in grid units (cells, cells per second; 2D points have `z = 0`).
pub struct Frame {
    /// The frames handed over before this one (0 for the first).
    pub index: u64,
    pub step: u64,
    pub time_secs: f64,
    /// The particles' positions and velocities, when a sink asked for them.
    pub positions: Vec<[f64; 3]>,
    pub velocities: Vec<[f64; 3]>,
    /// The liquid's surface (3D), when a sink asked for it.
    pub surface: Option<SurfaceMesh>,
}

/// What receives the frames, on the worker's thread, with the caller's error.
pub type FrameSink = Box<dyn FnMut(&Frame) -> Result<(), BoxError> + Send>;

/// Why the frame worker stopped, or could not start.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("cannot start the frame worker")]
    Start(#[source] BoxError),
    /// A sink failed; nothing was written after it.
    #[error(transparent)]
    Sink(BoxError),
    #[error("the frame worker panicked")]
    Panicked,
    #[error("the frame worker had already stopped")]
    Stopped,
}

/// What the sinks need made for each frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameNeeds {
    pub particles: bool,
    pub surface: bool,
}

/// What the worker gets of a frame: copies of the simulation's state.
struct Job {
    frame: Frame,
    liquid: Option<Liquid>,
}

/// What the worker is handed: a frame, or a request to say when every frame before it is done.
enum Work {
    Frame(Box<Job>),
    Done(SyncSender<()>),
}

/// The worker thread and its channel.
pub struct FrameWorker {
    tx: Option<SyncSender<Work>>,
    thread: Option<JoinHandle<Result<(), BoxError>>>,
    needs: FrameNeeds,
    submitted: u64,
}

impl FrameWorker {
    /// A worker feeding `sinks`, or `None` when there is none; its first frame is numbered
    /// `first` (a run resumed from a checkpoint numbers on).
    pub fn start(
        sinks: Vec<(FrameSink, FrameNeeds)>,
        first: u64,
    ) -> Result<Option<Self>, FrameError> {
        if sinks.is_empty() {
            return Ok(None);
        }
        let needs = sinks
            .iter()
            .fold(FrameNeeds::default(), |a, (_, n)| FrameNeeds {
                particles: a.particles || n.particles,
                surface: a.surface || n.surface,
            });
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(THREADS)
            .thread_name(|i| format!("cellflip-frames-{i}"))
            .build()
            .map_err(|e| FrameError::Start(Box::new(e)))?;
        let (tx, rx) = sync_channel::<Work>(1);
        let sinks = sinks.into_iter().map(|(s, _)| s).collect();
        let thread = std::thread::Builder::new()
            .name("cellflip-frames".into())
            .spawn(move || work(rx, sinks, &pool))
            .map_err(|e| FrameError::Start(Box::new(e)))?;
        Ok(Some(Self {
            tx: Some(tx),
            thread: Some(thread),
            needs,
            submitted: first,
        }))
    }

    /// Hands the simulation's current state over as the next frame. Fails with a sink's
    /// error from an earlier frame.
    pub fn submit<const D: usize>(&mut self, sim: &Simulation<D>) -> Result<(), FrameError> {
        let s = &sim.state;
        let lift =
            |v: &crate::grid::Vector<D>| std::array::from_fn(|k| if k < D { v[k] } else { 0.0 });
        let (positions, velocities) = match self.needs.particles {
            true => (
                s.particles.pos.iter().map(lift).collect(),
                s.particles.vel.iter().map(lift).collect(),
            ),
            false => (vec![], vec![]),
        };
        let job = Job {
            frame: Frame {
                index: self.submitted,
                step: s.steps,
                time_secs: s.time_secs,
                positions,
                velocities,
                surface: None,
            },
            liquid: (self.needs.surface && D == 3).then(|| Liquid::of(sim)),
        };
        self.submitted += 1;
        self.send(Work::Frame(Box::new(job)))
    }

    /// Frames handed over so far (with the `first` it started from).
    pub fn submitted(&self) -> u64 {
        self.submitted
    }

    /// Waits until every frame handed over is done (a checkpoint notes the recording's length
    /// with them in it).
    pub fn wait(&mut self) -> Result<(), FrameError> {
        let (done, finished) = sync_channel(1);
        self.send(Work::Done(done))?;
        match finished.recv() {
            Ok(()) => Ok(()),
            Err(_) => self.join(),
        }
    }

    fn send(&mut self, work: Work) -> Result<(), FrameError> {
        match self.tx.as_ref().is_some_and(|tx| tx.send(work).is_ok()) {
            true => Ok(()),
            // The worker stopped on an error: say which.
            false => self.join(),
        }
    }

    /// Waits for the frames handed over to be done; a sink's error if there was one.
    pub fn finish(mut self) -> Result<(), FrameError> {
        self.join()
    }

    fn join(&mut self) -> Result<(), FrameError> {
        self.tx = None;
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(r)) => r.map_err(FrameError::Sink),
            Some(Err(_)) => Err(FrameError::Panicked),
            None => Err(FrameError::Stopped),
        }
    }
}

impl Drop for FrameWorker {
    /// A run that ends on an error still waits for its frames (their files stay whole).
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.join();
        }
    }
}

/// The worker's loop: each frame's surface, then every sink, until the channel closes or a
/// sink fails.
fn work(
    rx: Receiver<Work>,
    mut sinks: Vec<FrameSink>,
    pool: &rayon::ThreadPool,
) -> Result<(), BoxError> {
    for work in rx {
        let mut job = match work {
            Work::Frame(job) => job,
            Work::Done(done) => {
                let _ = done.send(());
                continue;
            }
        };
        if let Some(liquid) = &job.liquid {
            job.frame.surface = Some(pool.install(|| liquid.surface()));
        }
        for sink in &mut sinks {
            sink(&job.frame)?;
        }
    }
    Ok(())
}
