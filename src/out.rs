//! Standard output that never panics: `println!` panics when the output is a closed pipe
//! (`cellflip list | head -1`) or a full device. [`outln!`](crate::outln) drops what cannot be
//! written instead; a failure other than a closed pipe is reported once on stderr. What the
//! run writes to files (recordings, reports) is unaffected.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

/// An error of a caller's callback (a frame sink, a finisher), whatever its type.
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// An error and its causes, one after the other (`a: b: c`), as `anyhow`'s `{:#}` prints them.
pub fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let causes = std::iter::successors(Some(e), |e| e.source());
    causes
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(": ")
}

static FAILED: AtomicBool = AtomicBool::new(false);
static TO_STDERR: AtomicBool = AtomicBool::new(false);

/// From now on, what [`line`] writes goes to standard error: standard output carries the
/// recording (`--stdout`).
pub fn to_stderr() {
    TO_STDERR.store(true, Ordering::Relaxed);
}

/// Writes one line to standard output (see the module doc).
pub fn line(args: std::fmt::Arguments) {
    if TO_STDERR.load(Ordering::Relaxed) {
        let _ = writeln!(std::io::stderr(), "{args}");
        return;
    }
    if FAILED.load(Ordering::Relaxed) {
        return;
    }
    if let Err(e) = writeln!(std::io::stdout().lock(), "{args}") {
        FAILED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            let _ = writeln!(
                std::io::stderr(),
                "warning: cannot write to standard output: {e}"
            );
        }
    }
}

/// `println!` through [`line`].
#[macro_export]
macro_rules! outln {
    () => {
        $crate::out::line(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::out::line(format_args!($($arg)*))
    };
}
