//! Stopping a run cleanly on a signal. SIGINT (Ctrl-C), SIGTERM and SIGHUP set a flag that the
//! step loop polls between steps; the run then finishes its recording and summary (and, with
//! checkpoints on, writes one of the last finished step) and exits with 128 + the signal's
//! number, as a shell expects. A second signal ends the process at once. A step that
//! outlasts the watchdog's grace after the signal (a long solve) is not waited for: the
//! recording is finished from a watchdog thread with the steps completed so far.
//!
//! SIGUSR1, what a batch scheduler sends before a time limit (Slurm's `--signal=B:USR1@N`),
//! asks for a checkpoint after the step under way; the run goes on.

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM, SIGUSR1};
use signal_hook::flag;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, LazyLock};
use std::time::Duration;

/// How long a step may go on after a signal before the watchdog ends the run.
pub const GRACE: Duration = Duration::from_secs(1);

/// The same with checkpoints on: the step under way is let finish so that its checkpoint can
/// be written. 30 s is Slurm's default `KillWait` between its SIGTERM and its SIGKILL.
pub const CHECKPOINT_GRACE: Duration = Duration::from_secs(30);

/// A checkpoint was asked for (SIGUSR1) and not yet written.
static CHECKPOINT: LazyLock<Arc<AtomicBool>> = LazyLock::new(|| Arc::new(AtomicBool::new(false)));

/// The signal received (0: none).
static SIGNAL: LazyLock<Arc<AtomicUsize>> = LazyLock::new(|| Arc::new(AtomicUsize::new(0)));

/// A signal handler that could not be installed.
#[derive(Debug, thiserror::Error)]
#[error("cannot install the handler of {signal}")]
pub struct HandlerError {
    pub signal: String,
    #[source]
    pub error: std::io::Error,
}

/// Installs the handlers (once per process; later calls do nothing).
pub fn install() -> Result<(), HandlerError> {
    static DONE: AtomicBool = AtomicBool::new(false);
    if DONE.swap(true, Ordering::SeqCst) {
        return Ok(());
    }
    let second = Arc::new(AtomicBool::new(false));
    for sig in [SIGINT, SIGTERM, SIGHUP] {
        // Registered first, so it sees the flag as the previous signal left it.
        flag::register_conditional_shutdown(sig, 128 + sig, Arc::clone(&second))
            .and_then(|_| flag::register(sig, Arc::clone(&second)))
            .and_then(|_| flag::register_usize(sig, Arc::clone(&SIGNAL), sig as usize))
            .map_err(|error| HandlerError {
                signal: format!("signal {sig}"),
                error,
            })?;
    }
    flag::register(SIGUSR1, Arc::clone(&CHECKPOINT)).map_err(|error| HandlerError {
        signal: "SIGUSR1".into(),
        error,
    })?;
    Ok(())
}

/// Whether a checkpoint was asked for since the last call (SIGUSR1).
pub fn take_checkpoint_request() -> bool {
    CHECKPOINT.swap(false, Ordering::SeqCst)
}

/// The signal that asked the run to stop, if any.
pub fn signal() -> Option<i32> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s as i32),
    }
}

/// The signal's name, for messages.
pub fn name(sig: i32) -> &'static str {
    match sig {
        SIGINT => "SIGINT (Ctrl-C)",
        SIGTERM => "SIGTERM",
        SIGHUP => "SIGHUP",
        _ => "a signal",
    }
}

/// The exit status of a run stopped by `sig`: 128 + its number (130, 143, 129).
pub fn exit_code(sig: i32) -> i32 {
    128 + sig
}

/// What the watchdog runs before ending the process (finishing a recording), with the
/// caller's error.
pub type Finisher = Box<dyn FnOnce() -> Result<(), crate::out::BoxError> + Send>;

/// `f` (a recording's finisher, with its own error type) as the watchdog takes it.
pub fn finisher<E: Into<crate::out::BoxError>>(
    f: impl FnOnce() -> Result<(), E> + Send + 'static,
) -> Finisher {
    Box::new(move || f().map_err(Into::into))
}

/// Ends the process when a step goes on for `grace` ([`GRACE`], [`CHECKPOINT_GRACE`]) after
/// a signal, after running its finisher; does nothing once [`done`](Self::done).
pub struct Watchdog {
    over: Arc<std::sync::Mutex<bool>>,
}

impl Watchdog {
    pub fn start(finish: Option<Finisher>, grace: Duration) -> Self {
        let over = Arc::new(std::sync::Mutex::new(false));
        let seen = Arc::clone(&over);
        std::thread::spawn(move || {
            let poll = Duration::from_millis(50);
            let mut since = None;
            loop {
                std::thread::sleep(poll);
                let Some(sig) = signal() else { continue };
                let t = *since.get_or_insert_with(std::time::Instant::now);
                if t.elapsed() < grace {
                    continue;
                }
                let over = seen.lock().unwrap_or_else(|p| p.into_inner());
                if *over {
                    return;
                }
                let finished = finish.map_or(Ok(()), |f| f());
                eprintln!(
                    "\nstopped by {}: the step under way did not end within {} s; {}",
                    name(sig),
                    grace.as_secs_f64(),
                    match finished {
                        Ok(()) => "the recording holds the steps completed before it".into(),
                        Err(e) => format!(
                            "the recording could not be finished: {}",
                            crate::out::chain(&*e)
                        ),
                    }
                );
                std::process::exit(exit_code(sig));
            }
        });
        Self { over }
    }

    /// The run is over: the watchdog will not end the process (waits if it is doing so).
    pub fn done(self) {
        *self.over.lock().unwrap_or_else(|p| p.into_inner()) = true;
    }
}
