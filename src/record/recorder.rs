//! [`Recorder`]: one run's recording, its identity (application `cellflip`, a recording name
//! and properties), its default layout, its legend and scene panel, and each step drawn.

use super::layout::{self, RunFacts};
use super::{blueprint, Drawing, Output, RecordError, Resumed, RunLog, Served, Sink, Stream};
use crate::draw::legend;
use crate::scene::Scene;
use crate::step::{Simulation, StepReport};

/// Writes one run: its recording ([`Output`]) with the run drawn in it ([`RunLog`]).
pub struct Recorder {
    output: Output,
    run: RunLog,
    /// It goes on with a recording file that has its static data already.
    continued: bool,
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
