//! Where a run's drawings go in a recording: its entity paths under a prefix.
//!
//! A run's own recording uses the paths of docs/recordings.md as they are (an empty prefix);
//! `cellflip compare` puts each method's run under its label (`flip/world/particles`,
//! `ccp/metrics/volume_percent`), so that several runs share one recording and one window.

use rerun::{AsComponents, RecordingStream, RecordingStreamResult};

/// A recording stream whose entity paths all start with `prefix`.
#[derive(Clone)]
pub struct Stream {
    pub(super) rec: RecordingStream,
    prefix: String,
}

impl Stream {
    /// `prefix` is empty, or a path part without slashes (a method's label in a comparison).
    pub fn new(rec: RecordingStream, prefix: &str) -> Self {
        let prefix = match prefix {
            "" => String::new(),
            p => format!("{p}/"),
        };
        Self { rec, prefix }
    }

    /// The full path of `path`.
    fn path(&self, path: &str) -> String {
        format!("{}{path}", self.prefix)
    }

    pub fn log<A: ?Sized + AsComponents>(
        &self,
        path: impl AsRef<str>,
        what: &A,
    ) -> RecordingStreamResult<()> {
        self.rec.log(self.path(path.as_ref()), what)
    }

    pub fn log_static<A: ?Sized + AsComponents>(
        &self,
        path: impl AsRef<str>,
        what: &A,
    ) -> RecordingStreamResult<()> {
        self.rec.log_static(self.path(path.as_ref()), what)
    }
}
