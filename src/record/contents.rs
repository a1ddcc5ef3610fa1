//! What a saved recording holds, read before it is shown (`cellflip view`): a file that is not
//! a Rerun recording is refused, and one cut short (a run killed mid-write, a copy that
//! stopped) is shown as far as it can be read, with a warning that says how far that is.
//!
//! Rerun's own decoder reads the file from its start, message by message, as the viewer would,
//! without keeping them. It does not fail on a file cut short: at a message cut in two it
//! waits for bytes that never come and ends as at a whole file's end. So the bytes it left
//! and the footer a finished file ends with tell the two apart.

use super::RecordError;
use crate::out::BoxError;
use rerun::external::re_log_encoding::{Decodable, DecoderApp, StreamFooter, StreamHeader};
use rerun::external::re_log_types::TimestampFormat;
use rerun::log::{Chunk, LogMsg};
use rerun::time::{TimeCell, TimeType};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// A recording file, read through: how many of its messages can be read, what its data spans
/// on each timeline, and why the rest cannot be read when it is cut short.
#[derive(Debug)]
pub struct Contents {
    pub path: PathBuf,
    /// Messages read whole, from the start: what the viewer is given.
    pub messages: usize,
    /// Each timeline's type and first and last time point, over the recording's data (the
    /// blueprint's left out).
    timelines: BTreeMap<String, (TimeType, i64, i64)>,
    /// Why the rest of the file could not be read; `None` for a whole file.
    pub cut: Option<String>,
}

impl Contents {
    /// Reads `path` through. Fails, naming the file and the reason, on one that cannot be
    /// opened, one that is not a Rerun recording, and one cut short before any of its data.
    pub fn read(path: &Path) -> Result<Self, RecordError> {
        let cannot = |error: BoxError| RecordError::Read {
            path: path.into(),
            error,
        };
        let open = |error| RecordError::Open {
            path: path.into(),
            error,
        };
        let mut file = File::open(path).map_err(open)?;
        let len = file.metadata().map_err(open)?.len();
        let writer = writer_version(&mut file)
            .map_err(|why| cannot(format!("it is not a Rerun recording ({why})").into()))?;
        file.rewind().map_err(|e| cannot(e.into()))?;
        let mut c = Self {
            path: path.into(),
            messages: 0,
            timelines: BTreeMap::new(),
            cut: None,
        };
        let mut decoder = DecoderApp::decode_lazy(BufReader::new(&file));
        c.cut = loop {
            match decoder.next() {
                None => break None,
                Some(Ok(msg)) => match c.take(&msg) {
                    Ok(()) => c.messages += 1,
                    Err(why) => break Some(why),
                },
                Some(Err(e)) => break Some(e.to_string()),
            }
        };
        let left = len.saturating_sub(decoder.num_bytes_processed());
        drop(decoder);
        c.cut = c.cut.or_else(|| match left {
            0 => unfinished(&mut file, len, writer),
            n => Some(format!("it stops {n} bytes into a message")),
        });
        match (&c.cut, c.timelines.is_empty()) {
            (Some(why), true) => Err(cannot(
                format!("it is cut short before any of its data ({why})").into(),
            )),
            _ => Ok(c),
        }
    }

    /// Notes the time points of a message of the recording's data; why not, for a chunk that
    /// cannot be read.
    fn take(&mut self, msg: &LogMsg) -> Result<(), String> {
        let LogMsg::ArrowMsg(store, arrow) = msg else {
            return Ok(());
        };
        if store.kind() != rerun::StoreKind::Recording {
            return Ok(());
        }
        let chunk = Chunk::from_arrow_msg(arrow)
            .map_err(|e| format!("message {} is not a chunk Rerun reads: {e}", self.messages))?;
        for (name, column) in chunk.timelines() {
            let range = column.time_range();
            let (min, max) = (range.min().as_i64(), range.max().as_i64());
            let typ = column.timeline().typ();
            let span = self.timelines.entry(name.to_string());
            let (_, lo, hi) = span.or_insert((typ, min, max));
            (*lo, *hi) = ((*lo).min(min), (*hi).max(max));
        }
        Ok(())
    }

    /// How far the data goes, on the recording's `step` timeline (a run's), or else on its
    /// `sim_time` (a comparison's, the report's), or else on its first timeline:
    /// `steps 0..=41`, `simulated time 0.000..=1.250 s`.
    pub fn span(&self) -> String {
        let first = self.timelines.keys().next();
        let name = ["step", "sim_time"]
            .into_iter()
            .find(|n| self.timelines.contains_key(*n))
            .or(first.map(String::as_str));
        let Some(name) = name else {
            return "no data on a timeline".into();
        };
        let (typ, lo, hi) = self.timelines[name];
        let what = match name {
            "step" => "steps".to_string(),
            "sim_time" => "simulated time".into(),
            other => format!("'{other}'"),
        };
        match typ {
            TimeType::Sequence => format!("{what} {lo}..={hi}"),
            TimeType::DurationNs => format!("{what} {:.3}..={:.3} s", secs(lo), secs(hi)),
            TimeType::TimestampNs => {
                let utc = |t| TimeCell::new(typ, t).format(TimestampFormat::utc());
                format!("{what} {}..={}", utc(lo), utc(hi))
            }
        }
    }

    /// The warning for a file cut short, naming it, how far it goes and why the rest cannot
    /// be read.
    pub fn warning(&self) -> Option<String> {
        let why = self.cut.as_ref()?;
        Some(format!(
            "warning: '{}' is cut short: it holds {} (the rest could not be read: {why})",
            self.path.display(),
            self.span()
        ))
    }
}

fn secs(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

/// The Rerun version that wrote the stream starting at the file's start, as `(major, minor)`;
/// why not, for a file that is not a Rerun recording (or one of a version Rerun no longer
/// reads).
fn writer_version(file: &mut File) -> Result<(u8, u8), String> {
    let mut head = [0; StreamHeader::ENCODED_SIZE_BYTES];
    file.read_exact(&mut head)
        .map_err(|_| "too short for a recording's header".to_string())?;
    let header = StreamHeader::from_rrd_bytes(&head).map_err(|e| e.to_string())?;
    let (version, _) = header.to_version_and_options().map_err(|e| e.to_string())?;
    Ok((version.major, version.minor))
}

/// Why a file read whole to its last message is unfinished: it lacks the footer that the
/// Rerun of this build (and any later one) writes when it closes a recording, so its writer
/// stopped before that. An older writer's file may have none (nothing is said of it).
fn unfinished(file: &mut File, len: u64, writer: (u8, u8)) -> Option<String> {
    let ours = rerun::build_info().version;
    if writer < (ours.major, ours.minor) {
        return None;
    }
    let mut tail = vec![0; StreamFooter::ENCODED_SIZE_BYTES];
    let footer = len.checked_sub(tail.len() as u64).and_then(|at| {
        file.seek(SeekFrom::Start(at)).ok()?;
        file.read_exact(&mut tail).ok()?;
        StreamFooter::from_rrd_bytes(&tail).ok()
    });
    match footer {
        Some(_) => None,
        None => Some("it ends without the footer a finished recording ends with".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::RrdFile;
    use rerun::external::re_log_encoding::MessageHeader;
    use rerun::sink::LogSink;

    /// A recording of steps 0..=9, a chunk each (flushed every step), written as a run's.
    fn ten_steps(path: &Path) -> Vec<u8> {
        let file = RrdFile::create(path).unwrap();
        let sinks: Vec<Box<dyn LogSink>> = vec![Box::new(file.clone())];
        let rec = rerun::RecordingStreamBuilder::new("cellflip")
            .set_sinks(sinks)
            .unwrap();
        for step in 0..10 {
            rec.set_time_sequence("step", step);
            rec.log("metrics/x", &rerun::Scalars::single(step as f64))
                .unwrap();
            rec.flush_blocking().unwrap();
        }
        file.commit().unwrap();
        file.finish().unwrap();
        std::fs::read(path).unwrap()
    }

    /// A whole recording reads through; cut in a message it holds the steps before the cut;
    /// cut at its last message, before its footer, all of them; either says why it is cut.
    #[test]
    fn a_recording_cut_short_says_up_to_which_step_it_holds() {
        let dir = std::env::temp_dir().join(format!("cellflip-contents-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let whole = dir.join("whole.rrd");
        let bytes = ten_steps(&whole);
        let c = Contents::read(&whole).unwrap();
        assert_eq!((c.cut.as_deref(), c.span()), (None, "steps 0..=9".into()));
        assert_eq!(c.warning(), None);
        let cut = |name: &str, len: usize| {
            let path = dir.join(name);
            std::fs::write(&path, &bytes[..len]).unwrap();
            Contents::read(&path)
        };
        let half = cut("half.rrd", bytes.len() / 2).unwrap();
        let why = half.cut.clone().unwrap();
        assert!(why.starts_with("it stops ") && why.ends_with(" bytes into a message"));
        assert!(half.messages < c.messages, "{half:?}");
        let span = half.span();
        let last: i64 = span.rsplit("..=").next().unwrap().parse().unwrap();
        assert!(span.starts_with("steps 0..=") && last < 9, "{span}");
        let warning = half.warning().unwrap();
        assert!(warning.starts_with(&format!(
            "warning: '{}' is cut short: it holds {span} (the rest could not be read: it stops ",
            dir.join("half.rrd").display()
        )));
        // The stream's end: its last message (the footer's index) and the footer after it.
        let tail = &bytes[bytes.len() - StreamFooter::ENCODED_SIZE_BYTES..];
        let footer = StreamFooter::from_rrd_bytes(tail).unwrap();
        let index = footer.entries[0].rrd_footer_byte_span_from_start_excluding_header;
        let end = index.start as usize - MessageHeader::ENCODED_SIZE_BYTES;
        let unfinished = cut("unfinished.rrd", end).unwrap();
        assert_eq!(
            (unfinished.cut.as_deref(), unfinished.span()),
            (
                Some("it ends without the footer a finished recording ends with"),
                "steps 0..=9".into()
            )
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Text, an empty file and a recording cut before its first step are refused, with why.
    #[test]
    fn a_file_that_is_not_a_recording_or_holds_nothing_is_refused() {
        let dir = std::env::temp_dir().join(format!("cellflip-refused-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bytes = ten_steps(&dir.join("whole.rrd"));
        let header = &bytes[..StreamHeader::ENCODED_SIZE_BYTES];
        for (name, content, why) in [
            (
                "text.rrd",
                &b"plain text, not a recording"[..],
                "it is not a Rerun recording (Not an RRD file",
            ),
            (
                "empty.rrd",
                &[][..],
                "it is not a Rerun recording (too short for a recording's header)",
            ),
            (
                "header.rrd",
                header,
                "it is cut short before any of its data (it ends without the footer",
            ),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, content).unwrap();
            let e = Contents::read(&path).unwrap_err();
            let e = format!("{e}: {}", std::error::Error::source(&e).unwrap());
            let named = format!("cannot read recording '{}': {why}", path.display());
            assert!(e.starts_with(&named), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
