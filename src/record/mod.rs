//! Rerun recordings: the only module that imports `rerun`.
//!
//! [`Recorder`] (`recorder.rs`) writes a run: its identity (application `cellflip`, a recording
//! name and properties), its default layout ([`layout`]), its legend (`crate::draw::legend`)
//! and, step by step, what the [`Canvas`] draws. `cellflip compare` writes several runs into
//! one recording ([`Comparison`], `compare.rs`), `cellflip report` its comparison of every
//! run's series ([`write_comparison`], `report.rs`). Entity paths are listed in
//! docs/recordings.md.
//!
//! Methods log their own reports through the drawing vocabulary's [`Log`] trait
//! ([`crate::draw`]), which the [`Canvas`] implements.
//!
//! [`Log`]: crate::draw::Log

mod blueprint;
mod canvas;
mod compare;
mod contents;
mod file;
pub mod layout;
mod output;
mod recorder;
mod report;
mod run_log;
mod serve;
mod stream;

pub use canvas::{Canvas, Plane};
pub use compare::{ComparedRun, Comparison};
pub use contents::Contents;
pub use file::RrdFile;
pub use output::{Output, Resumed, Sink};
pub use recorder::{recording_name, Recorder};
pub use report::{path_part, write_comparison, ComparisonSeries};
pub use run_log::RunLog;
pub use serve::{parse_memory_limit, serve_files, Served, WebServe};
pub use stream::Stream;

use crate::out::BoxError;
use std::path::PathBuf;

/// How the correction's moves are drawn (the command line's `--moves`, `crate::cmd::cli`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Moves {
    /// An arrow `x_hat -> x` per moved particle, the particles highlighted.
    #[default]
    Arrows,
    /// An arrow per moved particle between the centres of its cells before and after the
    /// correction.
    Hops,
}

/// How the command line asks a recording to draw.
#[derive(Clone, Copy, Debug, Default)]
pub struct Drawing {
    pub moves: Moves,
    /// 3D: the slice's axis (0, 1, 2) and position as a fraction of the tank along it.
    pub slice: (usize, f64),
    /// 3D: the liquid's surface as a mesh in every frame, the particles hidden under it.
    pub surface: bool,
}

/// Why a recording could not be written, read or served: what and where, with the cause.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// Writing to a sink (a file, a viewer, standard output, the web viewer's server).
    #[error("cannot write the recording to {sink}")]
    Sink {
        sink: String,
        #[source]
        error: BoxError,
    },
    /// The recording's own file.
    #[error("cannot write recording '{}'", .path.display())]
    File {
        path: PathBuf,
        #[source]
        error: BoxError,
    },
    #[error("cannot rename '{}' to '{}'", .from.display(), .to.display())]
    Rename {
        from: PathBuf,
        to: PathBuf,
        #[source]
        error: std::io::Error,
    },
    /// The recording a resumed run goes on with.
    #[error("cannot go on with recording '{}'", .path.display())]
    Continue {
        path: PathBuf,
        #[source]
        error: BoxError,
    },
    #[error("cannot open recording '{}'", .path.display())]
    Open {
        path: PathBuf,
        #[source]
        error: std::io::Error,
    },
    #[error("cannot read recording '{}'", .path.display())]
    Read {
        path: PathBuf,
        #[source]
        error: BoxError,
    },
    /// A command-line option that cannot be met: the option as given, and why.
    #[error("{option}")]
    Option {
        option: String,
        #[source]
        error: BoxError,
    },
    #[error("cannot hand the recordings to the server")]
    Serve(#[source] BoxError),
    #[error("no run to compare")]
    NoRun,
}

impl RecordError {
    /// A failure writing to `sink`.
    pub(crate) fn sink(sink: &Sink, error: impl Into<BoxError>) -> Self {
        RecordError::Sink {
            sink: sink.describe(),
            error: error.into(),
        }
    }
}
