//! Where a recording goes: our crash-safe file (the default), or live to a viewer (`--spawn`,
//! `--connect`) or to standard output (`--stdout`), the flags of Rerun's own examples
//! (`rerun::clap::RerunArgs`), or served to browsers (`--serve-web`, with or without a file).
//!
//! A live stream that breaks (the viewer closed mid-run) does not stop the simulation: rerun's
//! gRPC sink drops what it cannot send, and the end of the run waits at most
//! [`LIVE_FLUSH_TIMEOUT`] for the rest and then says the stream was lost (see [`end_live`]).

use super::serve::{Served, WebServe};
use super::RecordError;
use super::RrdFile;
use rerun::sink::LogSink;
use rerun::{RecordingStream, RecordingStreamBuilder};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Where a recording goes.
#[derive(Clone, Debug, PartialEq)]
pub enum Sink {
    /// A file, written by [`RrdFile`] (`--save`, or the default under `recordings/`).
    File(PathBuf),
    /// A new viewer process (`rerun` on the `PATH`), fed as the run goes.
    Spawn,
    /// A viewer already running, at this URL (rerun's default when `None`:
    /// `rerun+http://127.0.0.1:9876/proxy`).
    Connect(Option<String>),
    /// Standard output, to pipe into `rerun -`.
    Stdout,
    /// Rerun's web viewer and the recording served to browsers, and a file if `save` says.
    Web {
        serve: WebServe,
        save: Option<PathBuf>,
    },
}

impl Sink {
    /// How the summary names it.
    pub fn describe(&self) -> String {
        match self {
            Sink::File(p) => p.display().to_string(),
            Sink::Spawn => "a new viewer".into(),
            Sink::Connect(url) => {
                format!("the viewer at {}", url.as_deref().unwrap_or(DEFAULT_URL))
            }
            Sink::Stdout => "standard output".into(),
            Sink::Web { serve, save: None } => format!("browsers at {}", serve.url()),
            Sink::Web {
                serve,
                save: Some(p),
            } => format!("{} and browsers at {}", p.display(), serve.url()),
        }
    }

    /// The file the recording is written to, if any.
    pub fn file(&self) -> Option<&Path> {
        match self {
            Sink::File(p) | Sink::Web { save: Some(p), .. } => Some(p),
            _ => None,
        }
    }
}

/// How a run resumed from a checkpoint goes on with its recording: the same recording id,
/// and, to go on with the same file, the length the checkpoint noted.
#[derive(Clone, Debug)]
pub struct Resumed {
    pub id: String,
    pub append_at: Option<u64>,
}

/// rerun's default viewer URL, where `--connect` without one streams.
pub const DEFAULT_URL: &str = "rerun+http://127.0.0.1:9876/proxy";

/// How long the check that a viewer answers waits for it.
pub const REACH_TIMEOUT: Duration = Duration::from_secs(3);

impl Sink {
    /// For a live stream to a viewer already running: fails, naming the URL, when nothing
    /// accepts a connection at its host and port within [`REACH_TIMEOUT`] (rerun's gRPC client
    /// would drop the whole stream silently and the run would end with a warning only).
    pub fn check_reachable(&self) -> Result<(), RecordError> {
        let Sink::Connect(url) = self else {
            return Ok(());
        };
        let url = url.as_deref().unwrap_or(DEFAULT_URL);
        let cannot = |why: &dyn std::fmt::Display| RecordError::Option {
            option: format!("--connect {url}"),
            error: format!(
                "no viewer answers there ({why}); start one with `rerun` (pip install \
                 rerun-sdk==0.36.3), or pass --no-viewer-check to run anyway"
            )
            .into(),
        };
        let rest = url.split_once("://").map_or(url, |(_, r)| r);
        let authority = rest.split('/').next().unwrap_or(rest);
        let addrs = std::net::ToSocketAddrs::to_socket_addrs(authority)
            .map_err(|e| cannot(&format!("cannot resolve '{authority}': {e}")))?;
        let mut last = None;
        for a in addrs {
            match std::net::TcpStream::connect_timeout(&a, REACH_TIMEOUT) {
                Ok(_) => return Ok(()),
                Err(e) => last = Some(e),
            }
        }
        Err(cannot(&last.map_or("no address".into(), |e| e.to_string())))
    }
}

/// How long the end of a run waits for a live stream to drain before saying it was lost.
pub const LIVE_FLUSH_TIMEOUT: Duration = Duration::from_secs(10);

/// A recording being written: the stream and, for a file, our sink's handle on it.
pub struct Output {
    pub(super) rec: RecordingStream,
    file: Option<RrdFile>,
    sink: Sink,
    last_flush: Cell<Instant>,
}

impl Output {
    /// Opens the stream with the recording's `name`; fails, naming the file or the viewer,
    /// before anything is simulated. A run resumed from a checkpoint goes on with its
    /// recording's id and, when `resumed.append_at` says so, its file.
    pub fn open(sink: &Sink, name: &str, resumed: Option<&Resumed>) -> Result<Self, RecordError> {
        let mut builder = RecordingStreamBuilder::new("cellflip").recording_name(name);
        if let Some(r) = resumed {
            builder = builder.recording_id(r.id.as_str());
        }
        let file = match sink.file() {
            Some(path) => Some(match resumed.and_then(|r| r.append_at) {
                Some(at) => RrdFile::continue_from(path, at)?,
                None => RrdFile::create(path)?,
            }),
            None => None,
        };
        let to_file = || file.iter().map(|f| Box::new(f.clone()) as Box<dyn LogSink>);
        let rec = match sink {
            Sink::File(_) => builder.set_sinks(to_file().collect::<Vec<_>>()),
            Sink::Web { serve, save } => {
                let web = serve.start()?;
                // A run that goes on in its file: browsers get the part before, too.
                if let (Some(path), Some(at)) = (save, resumed.and_then(|r| r.append_at)) {
                    super::file::replay(path, at, web.as_ref())?;
                }
                builder.set_sinks(to_file().chain([web]).collect::<Vec<_>>())
            }
            Sink::Spawn => builder.spawn(),
            Sink::Connect(None) => builder.connect_grpc(),
            Sink::Connect(Some(url)) => builder.connect_grpc_opts(url.clone()),
            Sink::Stdout => builder.stdout(),
        }
        .map_err(|e| RecordError::sink(sink, e))?;
        rec.set_log_time_enabled(false);
        Ok(Self {
            rec,
            file,
            sink: sink.clone(),
            last_flush: Cell::new(Instant::now()),
        })
    }

    /// The recording's id.
    pub fn id(&self) -> String {
        (self.rec.store_info()).map_or_else(String::new, |i| i.recording_id().to_string())
    }

    /// Everything logged so far written, the file's path and length (none for a live stream).
    pub fn written(&self) -> Option<(PathBuf, u64)> {
        let file = self.file.as_ref()?;
        let _ = self.rec.flush_blocking();
        Some((file.path().to_path_buf(), file.bytes_written()))
    }

    /// After a step was logged: everything logged more than two seconds ago is on its way;
    /// a file takes its name at the first step (`committed`) and a failed write stops the run.
    pub fn step_logged(&self, committed: bool) -> Result<(), RecordError> {
        if self.last_flush.get().elapsed() > Duration::from_secs(2) {
            let _ = match self.file {
                Some(_) => self.rec.flush_blocking(),
                None => self.rec.flush_async(),
            };
            self.last_flush.set(Instant::now());
        }
        let Some(file) = &self.file else {
            return Ok(());
        };
        if committed {
            file.commit()?;
        }
        file.check()
    }

    /// Flushes everything; a file gets its footer and its name even if no step was recorded
    /// (an interrupted run). A live stream that cannot be drained is reported, not an error:
    /// the run itself went well. A served recording stays served as long as the [`Served`]
    /// returned is held.
    pub fn finish(self) -> Result<Option<Served>, RecordError> {
        if let Some(file) = &self.file {
            let _ = self.rec.flush_blocking();
            file.commit()?;
            file.finish()?;
        }
        match &self.sink {
            Sink::Web { serve, .. } => {
                let _ = self.rec.flush_blocking();
                let url = serve.url();
                return Ok(Some(Served::new(self.rec, url)));
            }
            Sink::Spawn | Sink::Connect(_) | Sink::Stdout => {
                if let Err(e) = end_live(&self.rec) {
                    eprintln!(
                        "warning: the stream to {} was lost ({e}); the run finished",
                        self.sink.describe()
                    );
                }
            }
            Sink::File(_) => {}
        }
        Ok(None)
    }

    /// After a run that failed: a file is finished as far as it goes, or removed if it never
    /// took its name (no step was recorded).
    pub fn abandon(self) {
        match &self.file {
            Some(file) => {
                let _ = self.rec.flush_blocking();
                let _ = file.finish();
                file.discard();
            }
            None => {
                let _ = end_live(&self.rec);
            }
        }
    }

    /// A closure that finishes the recording from another thread with what was logged so far
    /// (the signal watchdog: a step that does not end in time is not waited for).
    pub fn finisher(&self) -> impl FnOnce() -> Result<(), RecordError> + Send + 'static {
        let (rec, file) = (self.rec.clone(), self.file.clone());
        move || match file {
            Some(file) => {
                let _ = rec.flush_blocking();
                file.commit()?;
                file.finish()
            }
            None => {
                let _ = end_live(&rec);
                Ok(())
            }
        }
    }
}

/// Ends a live stream, waiting at most [`LIVE_FLUSH_TIMEOUT`] for each of its two stages.
///
/// Rerun's flush returns once everything is handed to its gRPC client, not once it has been
/// sent: a process that exits then loses the tail of the stream (the live-sink test saw whole
/// series missing). Only dropping the sink waits for the viewer to take the stream's end, and
/// rerun does that in `disconnect`, which blocks without a limit; it runs on a thread of its
/// own so that a viewer that stops reading cannot hang the end of the run.
fn end_live(rec: &RecordingStream) -> Result<(), StreamLost> {
    rec.flush_with_timeout(LIVE_FLUSH_TIMEOUT)
        .map_err(StreamLost::Flush)?;
    let (done, ended) = std::sync::mpsc::channel();
    let rec = rec.clone();
    std::thread::spawn(move || {
        rec.disconnect();
        let _ = done.send(());
    });
    ended
        .recv_timeout(LIVE_FLUSH_TIMEOUT)
        .map_err(|_| StreamLost::End)
}

/// Why a live stream's end may not have reached the viewer.
#[derive(Debug, thiserror::Error)]
enum StreamLost {
    #[error(transparent)]
    Flush(rerun::sink::SinkFlushError),
    #[error("the viewer did not take the end of the stream")]
    End,
}
