//! The one step loop: every command (`run`, `bench`, `validate`, `report`) and the tests step a
//! simulation through [`Runner::run`], with an observer called after each step, and read what
//! happened from one [`Summary`], printed in one place ([`Summary::print`]). The files a step
//! hands over (ccp's `--export-lp`) are written by an observer, through [`Exports`].

use crate::metrics::{median, Stage, StageTimes};
use crate::stages::StepError;
use crate::step::{Simulation, StepReport};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// When a run ends.
#[derive(Clone, Copy, Debug)]
pub enum Limit {
    Steps(u64),
    SimSeconds(f64),
}

impl Limit {
    fn reached<const D: usize>(self, sim: &Simulation<D>) -> bool {
        match self {
            Limit::Steps(n) => sim.state.steps >= n,
            Limit::SimSeconds(t) => sim.state.time_secs >= t,
        }
    }
}

/// What a run did: the figures every method has. The method's own are its summary lines.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Steps run (from `first_step`: a run resumed from a checkpoint counts on from it).
    pub steps: u64,
    pub first_step: u64,
    pub sim_secs: f64,
    pub wall: Duration,
    /// Stage times of every step.
    pub step_times: Vec<StageTimes>,
    pub volume_min: f64,
    pub volume_max: f64,
    /// Particles held at the end, and the fewest and most after a step.
    pub particles: usize,
    pub particles_range: (usize, usize),
    pub emitted: usize,
    pub pcg_iterations: Vec<usize>,
    pub dt_shortened: u64,
    /// Stopped by the `stop` callback (Ctrl-C).
    pub interrupted: bool,
    /// Per obstacle: its name, lowest point at the end (m), and steps it had to stay.
    pub obstacles: Vec<(String, f64, u64)>,
    /// What the method says about the run.
    pub method_lines: Vec<String>,
    /// The files written for the steps ([`Exports`]), one line each.
    pub written: Vec<String>,
}

impl Summary {
    fn new<const D: usize>(sim: &Simulation<D>) -> Self {
        let s = &sim.state;
        let v = s.volume_percent();
        let n = s.particles.len();
        Self {
            first_step: s.steps,
            volume_min: v,
            volume_max: v,
            particles: n,
            particles_range: (n, n),
            obstacles: s
                .solids
                .obstacles
                .iter()
                .map(|o| (o.name.clone(), 0.0, 0))
                .collect(),
            ..Default::default()
        }
    }

    fn add<const D: usize>(&mut self, sim: &Simulation<D>, rep: &StepReport<D>) {
        self.steps += 1;
        self.step_times.push(rep.times);
        self.volume_min = self.volume_min.min(rep.volume_percent);
        self.volume_max = self.volume_max.max(rep.volume_percent);
        let n = sim.state.particles.len();
        self.particles_range = (self.particles_range.0.min(n), self.particles_range.1.max(n));
        self.pcg_iterations.push(rep.pcg.iterations);
        self.emitted += rep.emitted;
        self.dt_shortened += rep.dt_shortened as u64;
        for (o, &b) in self.obstacles.iter_mut().zip(&rep.blocked) {
            o.2 += b as u64;
        }
    }

    fn finish<const D: usize>(&mut self, sim: &Simulation<D>) {
        let s = &sim.state;
        self.sim_secs = s.time_secs;
        self.particles = s.particles.len();
        for (o, ob) in self.obstacles.iter_mut().zip(&s.solids.obstacles) {
            o.1 = ob.bottom() * s.config.cell_size_m;
        }
        self.method_lines = sim.summary.lines();
    }

    /// Total time of a stage over the run.
    pub fn stage_total(&self, stage: Stage) -> Duration {
        self.step_times.iter().map(|t| t.get(stage)).sum()
    }

    /// Median time of a stage over the steps.
    pub fn stage_median(&self, stage: Stage) -> Duration {
        let v: Vec<Duration> = self.step_times.iter().map(|t| t.get(stage)).collect();
        median(&v).unwrap_or_default()
    }

    /// Median time of a whole step.
    pub fn step_median(&self) -> Duration {
        let v: Vec<Duration> = self.step_times.iter().map(|t| t.total()).collect();
        median(&v).unwrap_or_default()
    }

    /// The summary: the run, the volume, the pressure solve, obstacles, the method's lines and
    /// the stage times.
    pub fn print(&self, title: &str) {
        let per_step = |d: Duration| d.as_secs_f64() * 1e3 / self.steps.max(1) as f64;
        let stopped = if self.interrupted {
            " [stopped by a signal]"
        } else {
            ""
        };
        let resumed = match self.first_step {
            0 => String::new(),
            k => format!(" after step {k} (resumed)"),
        };
        crate::outln!(
            "{title}: {} steps{resumed}, {:.3} s simulated in {:.2} s wall ({:.2} ms/step){stopped}",
            self.steps,
            self.sim_secs,
            self.wall.as_secs_f64(),
            per_step(self.wall),
        );
        crate::outln!(
            "particles {} at the end ({} .. {} after a step; {} emitted); volume {:.2}% .. {:.2}% of V*",
            self.particles, self.particles_range.0, self.particles_range.1, self.emitted, self.volume_min, self.volume_max
        );
        let its: usize = self.pcg_iterations.iter().sum();
        crate::outln!(
            "pressure: {:.1} PCG iterations per step (max {}); steps shortened after projection: {}",
            its as f64 / self.steps.max(1) as f64,
            self.pcg_iterations.iter().max().unwrap_or(&0),
            self.dt_shortened
        );
        for (name, bottom, blocked) in &self.obstacles {
            crate::outln!(
                "obstacle {name}: lowest point at {bottom:.3} m at the end; had to stay on {blocked} of {} steps",
                self.steps
            );
        }
        self.method_lines.iter().for_each(|l| crate::outln!("{l}"));
        self.written.iter().for_each(|l| crate::outln!("{l}"));
        let total: Duration = self.step_times.iter().map(|t| t.total()).sum();
        crate::outln!(
            "{:<10} {:>10} {:>12} {:>8}",
            "stage",
            "total s",
            "ms/step",
            "share"
        );
        for st in Stage::ALL {
            let d = self.stage_total(st);
            let share = 100.0 * d.as_secs_f64() / total.as_secs_f64().max(1e-12);
            crate::outln!(
                "{:<10} {:>10.3} {:>12.3} {:>7.1}%",
                st.name(),
                d.as_secs_f64(),
                per_step(d),
                share
            );
        }
    }
}

/// Steps a simulation and keeps its summary.
pub struct Runner<const D: usize> {
    pub sim: Simulation<D>,
    pub summary: Summary,
}

/// A step that failed: which, and why.
#[derive(Debug, thiserror::Error)]
#[error("step {step}")]
pub struct StepFailed {
    pub step: u64,
    #[source]
    pub error: StepError,
}

impl<const D: usize> Runner<D> {
    pub fn new(sim: Simulation<D>) -> Self {
        let summary = Summary::new(&sim);
        Self { sim, summary }
    }

    /// Steps until `limit`, until `stop()` says so (the summary then says interrupted), or
    /// until a step or the observer fails; `observe` sees the simulation after each step and
    /// its report. The summary covers every step run so far. A failed step's error names it
    /// ([`StepFailed`]).
    pub fn run<E: From<StepFailed>>(
        &mut self,
        limit: Limit,
        stop: impl Fn() -> bool,
        mut observe: impl FnMut(&Simulation<D>, &StepReport<D>) -> Result<(), E>,
    ) -> Result<(), E> {
        let t0 = Instant::now();
        let result = loop {
            if limit.reached(&self.sim) {
                break Ok(());
            }
            if stop() {
                self.summary.interrupted = true;
                break Ok(());
            }
            let rep = match self.sim.step() {
                Ok(rep) => rep,
                Err(error) => {
                    let step = self.sim.state.steps + 1;
                    break Err(StepFailed { step, error }.into());
                }
            };
            self.summary.add(&self.sim, &rep);
            if let Err(e) = observe(&self.sim, &rep) {
                break Err(e);
            }
        };
        self.summary.wall += t0.elapsed();
        self.summary.finish(&self.sim);
        result
    }

    /// Steps until `limit`, observing nothing.
    pub fn run_to(&mut self, limit: Limit) -> Result<(), StepFailed> {
        self.run(limit, || false, |_, _| Ok(()))
    }

    /// Forgets what was measured so far, the method's totals too (after a warm-up).
    pub fn reset_summary(&mut self) {
        self.summary = Summary::new(&self.sim);
        self.sim.reset_summary();
    }
}

/// Writes the files steps hand over ([`MethodReport::exports`]: ccp's `--export-lp N`, the
/// problem its correction solved), for an observer of [`Runner::run`] to call after each step,
/// and keeps a line for the summary of each ([`Summary::written`]).
///
/// [`MethodReport::exports`]: crate::methods::MethodReport::exports
#[derive(Debug, Default)]
pub struct Exports {
    pub written: Vec<String>,
}

/// A file a step handed over that could not be written: the step, the file and why.
#[derive(Debug, thiserror::Error)]
#[error("step {step}: cannot write '{}'", .path.display())]
pub struct ExportFailed {
    pub step: u64,
    pub path: PathBuf,
    #[source]
    pub error: std::io::Error,
}

impl Exports {
    /// Writes the files of `rep`, the report of `sim`'s last step.
    pub fn write<const D: usize>(
        &mut self,
        sim: &Simulation<D>,
        rep: &StepReport<D>,
    ) -> Result<(), ExportFailed> {
        for e in rep.method.exports() {
            std::fs::write(e.path, e.text).map_err(|error| ExportFailed {
                step: sim.state.steps,
                path: e.path.to_path_buf(),
                error,
            })?;
            self.written
                .push(format!("wrote {} to {}", e.what, e.path.display()));
        }
        Ok(())
    }
}
