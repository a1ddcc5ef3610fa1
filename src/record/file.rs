//! The `.rrd` file a recording goes to: our own rerun sink rather than rerun's file sink, so
//! that a failed write (a full disk, a vanished directory) stops the run at once with the OS
//! error and the file's name, and what was written before stays a readable recording.
//!
//! - Every message is written whole or not at all: a write that fails is cut back to the last
//!   whole message, and nothing is written after it but the footer (which may not fit either:
//!   the file is then readable but has no footer).
//! - The file is first written beside its final name (`.NAME.partial`) and takes the name once
//!   the run's first step is recorded ([`RrdFile::commit`]), so a run that fails before that
//!   leaves an earlier recording of the same name alone. Special files (`/dev/null`, a pipe)
//!   are written directly.
//! - A run resumed from a checkpoint goes on with the file ([`RrdFile::continue_from`]): its
//!   first bytes, up to the length the checkpoint noted (every step up to it, nothing after),
//!   are decoded and written again into the new file, whose stream then goes on. So the file
//!   stays one stream with one footer indexing all of it (`rerun rrd verify` passes), and
//!   the earlier file is replaced only once the continuation records its first step.

use super::RecordError;
use rerun::external::re_log_encoding::{EncodeError, Encoder, EncodingOptions};
use rerun::log::LogMsg;
use rerun::sink::{LogSink, SinkFlushError};
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

/// A file that takes each `write_all` whole or, failing, cuts itself back to where it was.
struct WholeWrites {
    file: File,
    /// Bytes in the file (shared with [`RrdFile::bytes_written`]).
    len: Arc<AtomicU64>,
}

impl WholeWrites {
    fn len(&self) -> u64 {
        self.len.load(Ordering::SeqCst)
    }
}

impl Write for WholeWrites {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.write_all(buf).map(|()| buf.len())
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        match self.file.write_all(buf) {
            Ok(()) => {
                self.len.fetch_add(buf.len() as u64, Ordering::SeqCst);
                Ok(())
            }
            Err(e) => {
                // Best effort: special files cannot be cut.
                let _ = self.file.set_len(self.len());
                let _ = self.file.seek(SeekFrom::Start(self.len()));
                Err(e)
            }
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

struct State {
    encoder: Option<Encoder<WholeWrites>>,
    /// The first failure, in words; nothing is written after it.
    error: Option<String>,
    /// Where the file is until [`RrdFile::commit`] renames it (`None`: written in place).
    partial: Option<PathBuf>,
}

/// One recording's file: the sink rerun writes to, and the run's handle on it (clones share).
#[derive(Clone)]
pub struct RrdFile {
    path: PathBuf,
    state: Arc<Mutex<State>>,
    len: Arc<AtomicU64>,
}

impl RrdFile {
    /// Creates the file (beside `path` until committed) and writes the stream's header.
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        let special = std::fs::metadata(path).is_ok_and(|m| !m.is_file());
        let partial = (!special).then(|| partial_path(path));
        let at = partial.as_deref().unwrap_or(path);
        let file = File::create(at).map_err(|e| cannot_write(path, e))?;
        Self::encode(path, file, partial)
    }

    /// A new recording at `path` that starts with the messages in the first `at` bytes of the
    /// recording there now (what a checkpoint noted: what lies after is left out); the run
    /// logs on after them. The file there is replaced at [`RrdFile::commit`].
    pub fn continue_from(path: &Path, at: u64) -> Result<Self, RecordError> {
        let f = Self::create(path)?;
        if let Err(e) = replay(path, at, &f).and_then(|()| f.check()) {
            f.discard();
            return Err(e);
        }
        Ok(f)
    }

    /// The stream's header written to `file`.
    fn encode(path: &Path, file: File, partial: Option<PathBuf>) -> Result<Self, RecordError> {
        let version = rerun::build_info().version;
        let len = Arc::new(AtomicU64::new(0));
        let writer = WholeWrites {
            file,
            len: Arc::clone(&len),
        };
        let encoder = Encoder::new_eager(version, EncodingOptions::PROTOBUF_COMPRESSED, writer)
            .map_err(|e| {
                let _ = partial.as_deref().map(std::fs::remove_file);
                cannot_write(path, os_error(e))
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            state: Arc::new(Mutex::new(State {
                encoder: Some(encoder),
                error: None,
                partial,
            })),
            len,
        })
    }

    /// Bytes written to the file so far (whole messages only).
    pub fn bytes_written(&self) -> u64 {
        self.len.load(Ordering::SeqCst)
    }

    /// The file, at its final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Fails, naming the file and the OS error, once a write has failed or the file is gone
    /// (its directory removed: writes to an unlinked file succeed but are lost).
    pub fn check(&self) -> Result<(), RecordError> {
        let s = self.lock();
        if let Some(e) = &s.error {
            return Err(cannot_write(&self.path, e.clone()));
        }
        let at = s.partial.as_deref().unwrap_or(&self.path);
        if s.encoder.is_some() && !at.exists() {
            let why = "the file (or its directory) was removed during the run";
            return Err(cannot_write(&self.path, why));
        }
        Ok(())
    }

    /// Gives the file its name (once; later calls do nothing).
    pub fn commit(&self) -> Result<(), RecordError> {
        let mut s = self.lock();
        if let Some(partial) = s.partial.take() {
            std::fs::rename(&partial, &self.path).map_err(|error| RecordError::Rename {
                from: partial,
                to: self.path.clone(),
                error,
            })?;
        }
        Ok(())
    }

    /// Writes the footer and closes the file; then [`check`](Self::check)s. Idempotent.
    pub fn finish(&self) -> Result<(), RecordError> {
        {
            let mut s = self.lock();
            if let Some(mut encoder) = s.encoder.take() {
                if let Err(e) = encoder.finish().and_then(|()| encoder.flush_blocking()) {
                    s.error
                        .get_or_insert(format!("{} (the file has no footer)", os_error(e)));
                }
            }
        }
        self.check()
    }

    /// Closes the file and removes it if it never took its name (a run that failed before
    /// its first step).
    pub fn discard(&self) {
        let mut s = self.lock();
        s.encoder = None;
        if let Some(partial) = s.partial.take() {
            let _ = std::fs::remove_file(partial);
        }
    }
}

impl LogSink for RrdFile {
    fn send(&self, msg: LogMsg) {
        let mut s = self.lock();
        if s.error.is_some() {
            return;
        }
        if let Some(Err(e)) = s.encoder.as_mut().map(|enc| enc.append(&msg)) {
            s.error = Some(os_error(e));
        }
    }

    fn flush_blocking(&self, _timeout: Duration) -> Result<(), SinkFlushError> {
        let mut s = self.lock();
        if let Some(Err(e)) = s.encoder.as_mut().map(|enc| enc.flush_blocking()) {
            s.error.get_or_insert(os_error(e));
        }
        match &s.error {
            Some(e) => Err(SinkFlushError::failed(e.clone())),
            None => Ok(()),
        }
    }
}

fn cannot_write(path: &Path, error: impl Into<crate::out::BoxError>) -> RecordError {
    RecordError::File {
        path: path.into(),
        error: error.into(),
    }
}

/// The OS error of a failed write as the OS says it ("No space left on device (os error 28)").
fn os_error(e: EncodeError) -> String {
    match e {
        EncodeError::Write(io) => io.to_string(),
        e => e.to_string(),
    }
}

/// Sends the messages in the first `at` bytes of the recording at `path` to `sink`, in order:
/// what a checkpoint noted of a recording to go on with (what lies after is left out).
pub fn replay(path: &Path, at: u64, sink: &dyn LogSink) -> Result<(), RecordError> {
    use rerun::external::re_log_encoding::DecoderApp;
    use std::io::Read;
    let fail = |error: crate::out::BoxError| RecordError::Continue {
        path: path.into(),
        error,
    };
    let old = File::open(path).map_err(|e| fail(e.into()))?;
    let len = old.metadata().map_err(|e| fail(e.into()))?.len();
    if len < at {
        return Err(fail(
            format!(
                "it has {len} bytes, fewer than the {at} the checkpoint recorded up to (record \
                 to a new file with --save PATH)"
            )
            .into(),
        ));
    }
    for msg in DecoderApp::decode_lazy(std::io::BufReader::new(old.take(at))) {
        sink.send(msg.map_err(|e| fail(e.into()))?);
    }
    Ok(())
}

/// `dir/.NAME.partial` for `dir/NAME`.
fn partial_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "recording".into(), |n| n.to_string_lossy());
    path.with_file_name(format!(".{name}.partial"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_earlier_recording_is_replaced_only_once_a_step_is_committed() {
        let dir = std::env::temp_dir().join(format!("cellflip-rrdfile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("run.rrd");
        std::fs::write(&path, b"earlier").unwrap();
        // A run that fails before its first step: the earlier file stays, no partial is left.
        let f = RrdFile::create(&path).unwrap();
        assert!(partial_path(&path).exists());
        f.discard();
        assert_eq!(std::fs::read(&path).unwrap(), b"earlier");
        assert!(!partial_path(&path).exists());
        // A run that records a step: the new file takes the name and ends with its footer.
        let f = RrdFile::create(&path).unwrap();
        f.commit().unwrap();
        f.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(b"RRF2"), "not an rrd stream");
        let tail = &bytes[bytes.len().saturating_sub(256)..];
        assert!(tail.windows(8).any(|w| w == b"RRF2FOOT"), "no footer");
        assert!(!partial_path(&path).exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
