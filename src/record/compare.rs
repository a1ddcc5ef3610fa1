//! `cellflip compare`'s recording: several runs of one scene in one recording and one window.
//!
//! Each run is drawn by its own [`RunLog`] under its label (`flip/world/particles`,
//! `ccp/metrics/volume_percent`; every path of docs/recordings.md under `<label>/`), on the one
//! `sim_time` timeline. The layout ([`layout::compare_layout`]) puts the worlds in a grid, each
//! titled with its run, and the volume, the kinetic energy and the obstacles' heights beside
//! them, a line per run in its method's colour. Each world carries a label,
//! `<label>/world/label`, with the run's simulated time and volume at that frame, or why and
//! when it stopped.

use super::canvas::PointLook;
use super::layout::{self, Compared, RunFacts};
use super::RecordError;
use super::{Drawing, Output, RunLog, Sink, Stream};
use crate::draw::legend;
use crate::draw::Log;
use crate::grid::Vector;
use crate::scene::Scene;
use crate::step::{Simulation, StepReport};

/// One run of a comparison, as the recording names and colours it.
pub struct ComparedRun<'a> {
    /// A path part: the method's name, with its obstacle mode when given (`flip-naive`).
    pub label: String,
    /// The world view's title (`flip (naive)`).
    pub title: String,
    pub scene: &'a Scene,
    /// The method's colour in the report's plots.
    pub color: [u8; 3],
    /// 3D: draw the liquid's surface.
    pub surface: bool,
}

/// A comparison being recorded.
pub struct Comparison {
    output: Output,
    runs: Vec<(String, RunLog)>,
}

impl Comparison {
    /// Opens the recording with its layout, legend and each run's line colours; fails (naming
    /// the file or the viewer) before anything is simulated.
    pub fn create(sink: &Sink, name: &str, runs: &[ComparedRun<'_>]) -> Result<Self, RecordError> {
        let output = Output::open(sink, name, None)?;
        let rec = &output.rec;
        let cannot = |e: rerun::RecordingStreamError| RecordError::sink(sink, e);
        let compared: Vec<Compared<'_>> = runs.iter().map(compared).collect();
        let first = runs.first().ok_or(RecordError::NoRun)?.scene;
        let obstacles: Vec<String> = first.file.obstacle.iter().map(|o| o.name.clone()).collect();
        let root = layout::compare_layout(&compared, &obstacles);
        super::blueprint::send(rec, &root, "sim_time").map_err(cannot)?;
        let deep = compared.iter().any(|c| c.facts.shows("world/grid/depth"));
        let legend = legend::markdown(first.file.simulation.max_speed, deep);
        rec.log_static("legend", &rerun::TextDocument::from_markdown(legend))
            .map_err(cannot)?;
        let mut logs = vec![];
        for r in runs {
            let out = Stream::new(rec.clone(), &r.label);
            let mut series = vec!["metrics/volume_percent", "metrics/kinetic_energy"]
                .into_iter()
                .map(String::from)
                .collect::<Vec<_>>();
            series.extend(
                obstacles
                    .iter()
                    .map(|o| format!("metrics/obstacle/{o}/height")),
            );
            for s in series {
                let line = rerun::SeriesLines::new()
                    .with_colors([r.color])
                    .with_names([r.title.as_str()]);
                out.log_static(s, &line).map_err(cannot)?;
            }
            let run = RunLog::new(out, r.scene, r.drawing(), true);
            logs.push((r.title.clone(), run));
        }
        Ok(Self { output, runs: logs })
    }

    /// Run `i`'s static data (see [`RunLog::log_setup`]).
    pub fn log_setup<const D: usize>(&self, i: usize, sim: &Simulation<D>) {
        self.runs[i].1.log_setup(sim);
    }

    /// Run `i` after a step (or at the start, without `rep`): its metrics and kinetic energy,
    /// and when `frame`, its particles, cells, obstacles and label.
    pub fn log_step<const D: usize>(
        &self,
        i: usize,
        sim: &Simulation<D>,
        rep: Option<&StepReport<D>>,
        frame: bool,
    ) -> Result<(), RecordError> {
        let (title, run) = &self.runs[i];
        run.log_step(sim, rep, frame);
        let s = &sim.state;
        let mut c = run.canvas(sim);
        c.scalar("metrics/kinetic_energy", sim.liquid_motion().kinetic_energy);
        if frame {
            let text = format!(
                "{title}: V = {:.1}% of V*, t = {:.3} s",
                s.volume_percent(),
                s.time_secs
            );
            label(&mut c, sim, text);
        }
        run.report(c.result);
        self.output.step_logged(rep.is_some())
    }

    /// Run `i`'s surface sink (see [`RunLog::surface_sink`]).
    pub fn surface_sink(
        &self,
        i: usize,
    ) -> Option<(crate::frames::FrameSink, crate::frames::FrameNeeds)> {
        self.runs[i].1.surface_sink()
    }

    /// Run `i` stopped on an error: its label and its log say why and when.
    pub fn failed<const D: usize>(&self, i: usize, sim: &Simulation<D>, why: &str) {
        let (title, run) = &self.runs[i];
        run.error(sim, why);
        let mut c = run.canvas(sim);
        let text = format!(
            "{title}: stopped at t = {:.3} s: {why}",
            sim.state.time_secs
        );
        label(&mut c, sim, text);
        run.report(c.result);
    }

    /// See [`Output::finish`].
    pub fn finish(self) -> Result<Option<super::Served>, RecordError> {
        self.output.finish()
    }

    /// See [`Output::abandon`].
    pub fn abandon(self) {
        self.output.abandon();
    }

    /// See [`Output::finisher`].
    pub fn finisher(&self) -> impl FnOnce() -> Result<(), RecordError> + Send + 'static {
        self.output.finisher()
    }
}

impl ComparedRun<'_> {
    /// How the run is drawn: worlds only (no slice), with or without the surface.
    fn drawing(&self) -> Drawing {
        Drawing {
            surface: self.surface,
            ..Drawing::default()
        }
    }
}

/// What the layout needs of a run.
fn compared<'a>(r: &ComparedRun<'a>) -> Compared<'a> {
    Compared {
        label: r.label.clone(),
        title: r.title.clone(),
        facts: RunFacts::of(r.scene, &r.drawing()),
    }
}

/// The world's label, centred on the tank's top: in its top row in 2D, above it in 3D.
fn label<const D: usize>(c: &mut super::Canvas<'_, D>, sim: &Simulation<D>, text: String) {
    let dims = sim.state.grid.dims;
    let at = Vector::<D>::from_fn(|k, _| match (k, D) {
        (1, 2) => dims[1] as f64 - 0.5,
        (1, _) => dims[1] as f64 + 1.0,
        _ => dims[k] as f64 / 2.0,
    });
    let look = PointLook {
        radius: 0.01,
        order: 30.0,
        labels: Some(vec![text]),
    };
    c.points("world/label", &[at], vec![[255, 255, 255]], look);
}
