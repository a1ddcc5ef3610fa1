//! Rerun recordings: the only module that imports `rerun`.
//!
//! [`Recorder`] writes a run: its identity (application `cellflip`, a recording name and
//! properties), its default layout ([`layout`]), its legend ([`legend`]) and, step by step, what
//! the [`Canvas`] draws. Entity paths are listed in docs/recordings.md.
//!
//! Methods log their own reports through the drawing vocabulary's [`Log`] trait
//! ([`crate::draw`]), which the [`Canvas`] implements.

mod blueprint;
mod canvas;
mod compare;
mod contents;
mod file;
pub mod layout;
mod output;
mod run_log;
mod serve;
mod stream;

pub use canvas::{Canvas, Plane};
pub use compare::{ComparedRun, Comparison};
pub use contents::Contents;
pub use file::RrdFile;
pub use output::{Output, Resumed, Sink};
pub use run_log::RunLog;
pub use serve::{parse_memory_limit, serve_files, Served, WebServe};
pub use stream::Stream;

use crate::draw::legend;
use crate::out::BoxError;
use crate::scene::Scene;
use crate::step::{Simulation, StepReport};
use layout::RunFacts;
use rerun::blueprint::{Blueprint, Tabs, TimeSeriesView, Vertical};
use std::path::Path;
use std::path::PathBuf;

/// How the correction's moves are drawn (`--moves`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Moves {
    /// From `x_hat` (after advection) to `x` (after the correction): the exact displacement,
    /// often a small fraction of a cell (the moved particles are highlighted).
    #[default]
    Arrows,
    /// From the centre of the cell the particle was advected into to the centre of the cell
    /// the correction put it in: every move at least one cell long.
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

/// Writes one run: its recording ([`Output`]) with the run drawn in it ([`RunLog`]).
pub struct Recorder {
    output: Output,
    run: RunLog,
    /// It goes on with a recording file that has its static data already.
    continued: bool,
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

impl Recorder {
    /// Opens the recording with the run's identity, layout and scene; fails (naming the file
    /// or the viewer) before anything is simulated; a run resumed from a checkpoint goes on
    /// with its recording as `resumed` says.
    pub fn create(
        sink: &Sink,
        scene: &Scene,
        drawing: Drawing,
        resumed: Option<&Resumed>,
    ) -> Result<Self, RecordError> {
        let output = Output::open(sink, &recording_name(scene), resumed)?;
        let rec = &output.rec;
        let cannot = |e: rerun::RecordingStreamError| RecordError::sink(sink, e);
        let facts = RunFacts::of(scene, &drawing);
        let run = RunLog::new(Stream::new(rec.clone(), ""), scene, drawing, false);
        // A recording that goes on in its own file has its layout and static data already: sent
        // again (a second blueprint, new chunks of the same static data), the viewer drew the
        // markings without their class colours.
        let continued = resumed.is_some_and(|r| r.append_at.is_some());
        if continued {
            return Ok(Self {
                output,
                run,
                continued,
            });
        }
        blueprint::send(rec, &layout::layout(&facts), "step").map_err(cannot)?;
        rec.send_property("run", &run_properties(scene))
            .map_err(cannot)?;
        rec.log_static(
            "scene",
            &rerun::TextDocument::from_markdown(scene_markdown(scene)),
        )
        .map_err(cannot)?;
        let legend = legend::markdown(
            scene.file.simulation.max_speed,
            facts.shows("world/grid/depth"),
        );
        rec.log_static("legend", &rerun::TextDocument::from_markdown(legend))
            .map_err(cannot)?;
        Ok(Self {
            output,
            run,
            continued,
        })
    }

    /// Static data: the class colours, the domain, the view coordinates, the method's layers.
    pub fn log_setup<const D: usize>(&self, sim: &Simulation<D>) {
        if !self.continued {
            self.run.log_setup(sim);
        }
    }

    /// The state after a step (or at the start, step 0, without `rep`; see
    /// [`RunLog::log_step`]). Fails when the file cannot be written (checked every step,
    /// flushed every two seconds); the first step recorded gives the file its name.
    pub fn log_step<const D: usize>(
        &self,
        sim: &Simulation<D>,
        rep: Option<&StepReport<D>>,
        full: bool,
    ) -> Result<(), RecordError> {
        self.run.log_step(sim, rep, full);
        self.output.step_logged(rep.is_some())
    }

    /// See [`RunLog::surface_sink`].
    pub fn surface_sink(&self) -> Option<(crate::frames::FrameSink, crate::frames::FrameNeeds)> {
        self.run.surface_sink()
    }

    pub fn warn<const D: usize>(&self, sim: &Simulation<D>, msg: &str) {
        self.run.warn(sim, msg);
    }

    pub fn error<const D: usize>(&self, sim: &Simulation<D>, msg: &str) {
        self.run.error(sim, msg);
    }

    /// Flushes everything; see [`Output::finish`].
    pub fn finish(self) -> Result<Option<Served>, RecordError> {
        self.output.finish()
    }

    /// After a run that failed; see [`Output::abandon`].
    pub fn abandon(self) {
        self.output.abandon();
    }

    /// See [`RunLog::trails`].
    pub fn trails(&self) -> Vec<Vec<[f32; 3]>> {
        self.run.trails()
    }

    /// See [`RunLog::set_trails`].
    pub fn set_trails(&self, trails: Vec<Vec<[f32; 3]>>) {
        self.run.set_trails(trails);
    }

    /// See [`Output::id`].
    pub fn id(&self) -> String {
        self.output.id()
    }

    /// See [`Output::written`].
    pub fn written(&self) -> Option<(std::path::PathBuf, u64)> {
        self.output.written()
    }

    /// See [`Output::finisher`].
    pub fn finisher(&self) -> impl FnOnce() -> Result<(), RecordError> + Send + 'static {
        self.output.finisher()
    }
}

/// The recording's name in the viewer, [`Scene::run_tags`] (e.g. `dam-3d ccp band-paths r6
/// 50x50x50 ppc8 seed1`), so that runs opened side by side differ.
pub fn recording_name(scene: &Scene) -> String {
    scene.run_tags().join(" ")
}

/// The run's settings as recording properties (`__properties/run`), shown with the
/// recording in the viewer.
fn run_properties(scene: &Scene) -> rerun::AnyValues {
    let cells: Vec<String> = scene.dims.iter().map(usize::to_string).collect();
    let sim = &scene.file.simulation;
    [
        ("scene", scene.name().to_string()),
        ("method", scene.method.kind.name().to_string()),
        (
            "band",
            scene.method.band().map_or("none", |b| b.variant).into(),
        ),
        ("cells", cells.join("x")),
        ("ppc", sim.ppc.to_string()),
        ("seed", sim.seed.to_string()),
        ("version", format!("cellflip {}", env!("CARGO_PKG_VERSION"))),
    ]
    .into_iter()
    .fold(rerun::AnyValues::default(), |v, (key, value)| {
        v.with_component::<rerun::components::Text>(key, [value])
    })
}

/// The `scene` panel: the scene as run.
fn scene_markdown(scene: &Scene) -> String {
    format!(
        "# {}\n\n{}\n\n- source: {}\n- method: {}\n- seed: {}\n- program: cellflip {}\n\n```toml\n{}```\n",
        recording_name(scene),
        scene.file.description,
        scene.source,
        scene.method.kind.name(),
        scene.file.simulation.seed,
        env!("CARGO_PKG_VERSION"),
        scene.resolved_toml()
    )
}

/// One run's time series for the report's comparison recording.
pub struct ComparisonSeries<'a> {
    pub scene: &'a str,
    pub method: &'a str,
    /// The method's line colour (RGB), as in the report's plots.
    pub color: [u8; 3],
    pub res: usize,
    pub seed: u64,
    /// `(simulated seconds, V/V* %)` and `(simulated seconds, kinetic energy per unit mass)`.
    pub volume: &'a [(f64, f64)],
    pub ke: &'a [(f64, f64)],
}

/// Entity-path (and file-name) part of a scene label: ASCII letters, digits, `-` and `_`,
/// anything else as `_`.
pub fn path_part(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Run `r`'s line colour among `runs`: its method's colour for the coarsest (then lowest-seed)
/// run of that method on its scene, mixed with white up to half way for the others, in order.
fn shade(runs: &[ComparisonSeries<'_>], r: &ComparisonSeries<'_>) -> [u8; 3] {
    let mut same: Vec<(usize, u64)> = (runs.iter())
        .filter(|o| o.scene == r.scene && o.method == r.method)
        .map(|o| (o.res, o.seed))
        .collect();
    same.sort_unstable();
    same.dedup();
    let rank = same.iter().position(|&x| x == (r.res, r.seed)).unwrap_or(0);
    let f = 0.5 * rank as f64 / same.len().saturating_sub(1).max(1) as f64;
    r.color
        .map(|c| (c as f64 + (255.0 - c as f64) * f).round() as u8)
}

/// `cellflip report`'s recording: every run's volume and kinetic energy on the `sim_time`
/// timeline, under `volume/<scene>/<method>/<cells>` and
/// `kinetic_energy/<scene>/<method>/<cells>` (`_s<seed>` appended when a scene runs with
/// several seeds), with one tab per scene comparing the methods.
pub fn write_comparison(path: &Path, runs: &[ComparisonSeries<'_>]) -> Result<(), RecordError> {
    let cannot = |e: BoxError| RecordError::File {
        path: path.into(),
        error: e,
    };
    let mut scenes: Vec<String> = vec![];
    for r in runs {
        let s = path_part(r.scene);
        if !scenes.contains(&s) {
            scenes.push(s);
        }
    }
    // One tab per scene: its volume above its kinetic energy, every run a line.
    let panel = |what: &str, s: &String| -> rerun::blueprint::ContainerLike {
        TimeSeriesView::new(format!("{s}: {what}"))
            .with_origin(format!("{what}/{s}"))
            .into()
    };
    let tabs = scenes.iter().map(|s| {
        Vertical::new([panel("volume", s), panel("kinetic_energy", s)])
            .with_name(s.clone())
            .into()
    });
    let blueprint = Blueprint::new(Tabs::new(tabs));
    let rec = rerun::RecordingStreamBuilder::new("cellflip")
        .recording_name("cellflip report")
        .send_properties(false)
        .with_blueprint(blueprint)
        .save(path)
        .map_err(|e| cannot(e.into()))?;
    rec.set_log_time_enabled(false);
    let several_seeds = |r: &ComparisonSeries<'_>| {
        runs.iter().any(|o| {
            o.scene == r.scene && o.method == r.method && o.res == r.res && o.seed != r.seed
        })
    };
    for r in runs {
        let mut leaf = format!("{}/{}/{}", path_part(r.scene), r.method, r.res);
        if several_seeds(r) {
            leaf += &format!("_s{}", r.seed);
        }
        for (what, series) in [("volume", r.volume), ("kinetic_energy", r.ke)] {
            let entity = format!("{what}/{leaf}");
            // The method's colour in both panels (the viewer would pick one per path), lighter
            // for each further resolution or seed of the same method and scene.
            let line = rerun::SeriesLines::new().with_colors([shade(runs, r)]);
            (rec.log_static(entity.as_str(), &line)).map_err(|e| cannot(e.into()))?;
            for &(t, v) in series {
                rec.set_duration_secs("sim_time", t);
                (rec.log(entity.as_str(), &rerun::Scalars::single(v)))
                    .map_err(|e| cannot(e.into()))?;
            }
        }
    }
    rec.flush_blocking().map_err(|e| cannot(e.into()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A method keeps its colour on every scene; its finer resolutions are lighter, up to half
    /// way to white, and no two runs of one method on one scene share a colour.
    #[test]
    fn comparison_lines_take_their_methods_colour_lighter_per_resolution() {
        let run = |scene, method, res, color| ComparisonSeries {
            scene,
            method,
            color,
            res,
            seed: 1,
            volume: &[],
            ke: &[],
        };
        let (red, blue) = ([200, 20, 40], [30, 110, 180]);
        let runs = [
            run("dam", "ccp", 64, red),
            run("dam", "ccp", 32, red),
            run("dam", "ccp", 16, red),
            run("dam", "flip", 32, blue),
            run("drop", "ccp", 64, red),
        ];
        let c: Vec<[u8; 3]> = runs.iter().map(|r| shade(&runs, r)).collect();
        assert_eq!(c[2], red, "the coarsest run has the method's colour");
        assert_eq!(c[1], [214, 79, 94], "a quarter of the way to white");
        assert_eq!(c[0], [228, 138, 148], "the finest run half way to white");
        assert_eq!(
            (c[3], c[4]),
            (blue, red),
            "alone on its scene: the method's colour"
        );
    }
}
