//! Running a scene: the step loop with its progress bar, recording, Ctrl-C handling and the
//! summary at the end.

use crate::cli::RunArgs;
use crate::metrics::{Stage, StageTimes};
use crate::record::Recorder;
use crate::scene::{Overrides, Scene};
use crate::sim::{Method, Simulation, StepReport};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// When a run ends.
#[derive(Clone, Copy, Debug)]
pub enum Limit {
    Steps(u64),
    SimSeconds(f64),
}

/// What a run did, for the summary.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub steps: u64,
    pub sim_secs: f64,
    pub wall: Duration,
    pub stages: StageTimes,
    pub volume_min: f64,
    pub volume_max: f64,
    pub particles: usize,
    pub emitted: usize,
    pub pcg_iterations: u64,
    pub pcg_iterations_max: usize,
    pub dt_shortened: u64,
    pub interrupted: bool,
    /// Correction step (method ccp): particles sent to another cell, the most over-full cells
    /// before one correction, solver fallbacks, and the largest cross-check difference.
    pub corrections: u64,
    pub moved: u64,
    pub overfull_max: usize,
    pub fallbacks: u64,
    pub cross_check_max: Option<f64>,
    /// Band method: its variant and `R`, `n_deep` at the end, the fewest and most band
    /// particles after a step, paths applied, steps whose band correction failed, excess
    /// particles the interface had no room for, and per other variant (cross-check) the
    /// largest and median relative objective gap to the variant run.
    pub band: Option<(String, u32)>,
    pub n_deep: usize,
    pub band_particles: (usize, usize),
    pub band_paths: u64,
    pub band_moves: u64,
    pub band_failures: u64,
    pub unplaced: u64,
    pub band_gaps: Vec<(String, Vec<f64>)>,
    /// Per obstacle: its name, lowest point at the end (m), and steps it had to stay.
    pub obstacles: Vec<(String, f64, u64)>,
}

impl Summary {
    fn new(volume: f64) -> Self {
        Self {
            volume_min: volume,
            volume_max: volume,
            ..Default::default()
        }
    }

    fn add<const D: usize>(&mut self, rep: &StepReport<D>) {
        self.steps += 1;
        for s in Stage::ALL {
            self.stages.add(s, rep.times.get(s));
        }
        self.volume_min = self.volume_min.min(rep.volume_percent);
        self.volume_max = self.volume_max.max(rep.volume_percent);
        self.pcg_iterations += rep.pcg.iterations as u64;
        self.pcg_iterations_max = self.pcg_iterations_max.max(rep.pcg.iterations);
        self.emitted += rep.emitted;
        self.dt_shortened += rep.dt_shortened as u64;
        if let Some(c) = &rep.correction {
            self.corrections += 1;
            self.moved += c.moves.len() as u64;
            self.overfull_max = self.overfull_max.max(c.overfull_before);
            self.fallbacks += c.fallback.is_some() as u64;
            if let Some(Ok(d)) = c.cross_check {
                self.cross_check_max = Some(self.cross_check_max.unwrap_or(0.0).max(d));
            }
            if let Some(b) = &c.band {
                self.band_paths += b.paths_applied as u64;
                self.band_moves += b.n_move as u64;
                self.band_failures += b.failure.is_some() as u64;
                for (v, o) in &b.other_objectives {
                    let gap = match o {
                        Ok(o) => (o - b.objective) / b.objective.abs().max(1e-12),
                        Err(_) => f64::NAN,
                    };
                    match self.band_gaps.iter_mut().find(|(n, _)| n == v.name()) {
                        Some((_, g)) => g.push(gap),
                        None => self.band_gaps.push((v.name().to_string(), vec![gap])),
                    }
                }
            }
        }
        if let Some(x) = &rep.deep {
            self.unplaced += x.unplaced as u64;
        }
        for (o, &b) in self.obstacles.iter_mut().zip(&rep.blocked) {
            o.2 += b as u64;
        }
    }

    /// Records the band particles after a step.
    fn add_band_particles(&mut self, n: usize) {
        self.band_particles = if self.steps <= 1 {
            (n, n)
        } else {
            (self.band_particles.0.min(n), self.band_particles.1.max(n))
        };
    }
}

/// `cellflip run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let overrides = Overrides {
        method: args.method.clone(),
        duration: args.duration,
        cells: args.res,
        ppc: args.ppc,
        seed: args.seed,
        solver: args.solver.clone(),
        directions: args.directions.clone(),
        band: args.band.clone(),
        band_r: args.band_r,
        obstacle: args.obstacle.clone(),
    };
    let scene = Scene::load(&args.scene, &overrides)?;
    let limit = match args.steps {
        Some(0) => bail!("--steps: must be at least 1"),
        Some(n) => Limit::Steps(n),
        None => Limit::SimSeconds(scene.duration_secs()),
    };
    let out = if args.no_record {
        None
    } else if let Some(p) = &args.out {
        Some(p.clone())
    } else {
        let dir = PathBuf::from("recordings");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create directory '{}'", dir.display()))?;
        Some(dir.join(format!("{}.rrd", scene.name())))
    };
    let _ = ctrlc::set_handler(|| INTERRUPTED.store(true, Ordering::SeqCst));
    match scene.dim() {
        2 => run_dim::<2>(&scene, limit, out.as_deref(), args),
        3 => run_dim::<3>(&scene, limit, out.as_deref(), args),
        d => unreachable!("scene checks the dimension, got {d}"),
    }
}

fn run_dim<const D: usize>(
    scene: &Scene,
    limit: Limit,
    out: Option<&Path>,
    args: &RunArgs,
) -> Result<()> {
    if args.export_lp.is_some() && scene.method != Method::Ccp {
        bail!(
            "--export-lp: method '{}' has no correction problem (use --method ccp)",
            scene.method.name()
        );
    }
    let recorder = out.map(|p| Recorder::create(p, scene)).transpose()?;
    let mut config = scene.config::<D>();
    config.correction.cross_check = args.cross_check;
    let mut sim = Simulation::<D>::new(config);
    sim.export_problem_at_step = args.export_lp;
    if let Some(r) = &recorder {
        r.log_setup(&sim);
        r.log_step(&sim, None, true);
    }
    if sim.band().is_some() && sim.particles.is_empty() && sim.n_deep > 0 {
        let msg = "the fluid has no free surface, so the band method put every particle in the \
                   deep: the run is grid-only (use --band none)";
        eprintln!("warning: {msg}");
        if let Some(r) = &recorder {
            r.warn(&sim, msg);
        }
    }
    let t0 = Instant::now();
    let bar = progress_bar(limit);
    let mut summary = Summary::new(sim.volume_percent());
    summary.obstacles = sim
        .obstacles
        .iter()
        .map(|o| (o.name.clone(), 0.0, 0))
        .collect();
    let result = loop {
        let done = match limit {
            Limit::Steps(n) => sim.steps >= n,
            Limit::SimSeconds(t) => sim.time_secs >= t,
        };
        if done {
            break Ok(());
        }
        if INTERRUPTED.load(Ordering::SeqCst) {
            summary.interrupted = true;
            if let Some(r) = &recorder {
                r.warn(&sim, "run stopped by Ctrl-C");
            }
            break Ok(());
        }
        match sim.step() {
            Ok(rep) => {
                summary.add(&rep);
                if rep.deep.is_some() {
                    summary.add_band_particles(sim.particles.len());
                }
                if let Some(mps) = rep.correction.as_ref().and_then(|c| c.mps.as_ref()) {
                    let path = mps_path(scene, out, sim.steps);
                    if let Err(e) = std::fs::write(&path, mps) {
                        break Err(anyhow::anyhow!("cannot write '{}': {e}", path.display()));
                    }
                    if !args.quiet {
                        eprintln!(
                            "wrote the correction problem of step {} to {}",
                            sim.steps,
                            path.display()
                        );
                    }
                }
                if let Some(r) = &recorder {
                    let full = sim.steps.is_multiple_of(args.record_every);
                    r.log_step(&sim, Some(&rep), full);
                }
            }
            Err(e) => {
                let msg = format!("step {}: invariant broken: {e}", sim.steps + 1);
                if let Some(r) = &recorder {
                    r.error(&sim, &msg);
                }
                break Err(anyhow::anyhow!(msg));
            }
        }
        if !args.quiet && t0.elapsed() > Duration::from_secs(1) && bar.is_hidden() {
            bar.set_draw_target(ProgressDrawTarget::stderr());
        }
        bar.set_position(match limit {
            Limit::Steps(_) => sim.steps,
            Limit::SimSeconds(_) => (sim.time_secs * 1000.0) as u64,
        });
        bar.set_message(format!(
            "step {}  t = {:.3} s  volume {:.1}%",
            sim.steps,
            sim.time_secs,
            sim.volume_percent()
        ));
    };
    bar.finish_and_clear();
    summary.wall = t0.elapsed();
    summary.sim_secs = sim.time_secs;
    summary.particles = sim.particles.len();
    summary.n_deep = sim.n_deep;
    for (s, o) in summary.obstacles.iter_mut().zip(&sim.obstacles) {
        s.1 = o.bottom() * sim.config.cell_size_m;
    }
    summary.band = sim.band().map(|b| (b.variant.name().to_string(), b.r));
    if let Some(r) = recorder {
        r.finish()
            .with_context(|| format!("cannot finish the recording '{}'", out.unwrap().display()))?;
    }
    if !args.quiet {
        print_summary(scene, &summary, out);
    }
    result
}

/// Where `--export-lp` writes: beside the recording, or in `recordings/` without one.
fn mps_path(scene: &Scene, out: Option<&Path>, step: u64) -> PathBuf {
    let name = format!("{}-step{step}.mps", scene.name());
    match out {
        Some(p) => p.with_file_name(name),
        None => Path::new("recordings").join(name),
    }
}

fn progress_bar(limit: Limit) -> ProgressBar {
    let (len, unit) = match limit {
        Limit::Steps(n) => (n, "steps"),
        Limit::SimSeconds(t) => ((t * 1000.0).ceil() as u64, "ms"),
    };
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    let style = ProgressStyle::with_template(&format!(
        "{{bar:30}} {{pos}}/{{len}} {unit}  {{msg}}  ETA {{eta}}"
    ))
    .expect("a valid progress template");
    bar.set_style(style);
    bar
}

fn print_summary(scene: &Scene, s: &Summary, out: Option<&Path>) {
    let per_step = |d: Duration| d.as_secs_f64() * 1e3 / s.steps.max(1) as f64;
    println!(
        "{} ({}D, {}): {} steps, {:.3} s simulated in {:.2} s wall ({:.2} ms/step){}",
        scene.name(),
        scene.dim(),
        scene.method.name(),
        s.steps,
        s.sim_secs,
        s.wall.as_secs_f64(),
        per_step(s.wall),
        if s.interrupted {
            " [stopped by Ctrl-C]"
        } else {
            ""
        }
    );
    println!(
        "particles {} ({} emitted); volume {:.2}% .. {:.2}% of V*",
        s.particles, s.emitted, s.volume_min, s.volume_max
    );
    println!(
        "pressure: {:.1} PCG iterations per step (max {}); steps shortened after projection: {}",
        s.pcg_iterations as f64 / s.steps.max(1) as f64,
        s.pcg_iterations_max,
        s.dt_shortened
    );
    if s.corrections > 0 {
        println!(
            "correction: {} particles sent to another cell in all; up to {} over-full cells before one correction; {} solver fallbacks{}",
            s.moved,
            s.overfull_max,
            s.fallbacks,
            s.cross_check_max
                .map(|d| format!("; flow vs simplex objectives differ by at most {d:.2e} (relative)"))
                .unwrap_or_default()
        );
    }
    for (name, bottom, blocked) in &s.obstacles {
        println!(
            "obstacle {name} ({}): lowest point at {bottom:.3} m at the end; had to stay on {blocked} of {} steps",
            scene.obstacle_mode.name(),
            s.steps
        );
    }
    if let Some((variant, r)) = &s.band {
        println!(
            "band ({variant}, R = {r}): {} band particles at the end ({} .. {} after a step) and n_deep = {}: {:.1}% of the {} fluid particles held; {} particles moved across the interface along {} paths; band correction failed on {} steps; {} excess particles found no room in the interface",
            s.particles,
            s.band_particles.0,
            s.band_particles.1,
            s.n_deep,
            100.0 * s.particles as f64 / (s.particles + s.n_deep).max(1) as f64,
            s.particles + s.n_deep,
            s.band_moves,
            s.band_paths,
            s.band_failures,
            s.unplaced
        );
        for (v, gaps) in &s.band_gaps {
            let mut g = gaps.clone();
            let failed = g.iter().filter(|x| x.is_nan()).count();
            g.retain(|x| !x.is_nan());
            g.sort_by(f64::total_cmp);
            if g.is_empty() {
                println!("  {v} on the same problems: failed on all {failed}");
                continue;
            }
            println!(
                "  {v} on the same problems: objective {:+.3}% (median) .. {:+.3}% (max) relative to {variant}; failed on {failed}",
                100.0 * g[g.len() / 2],
                100.0 * g[g.len() - 1]
            );
        }
    }
    println!("{:<10} {:>10} {:>12}", "stage", "total s", "ms/step");
    for st in Stage::ALL {
        let d = s.stages.get(st);
        println!(
            "{:<10} {:>10.3} {:>12.3}",
            st.name(),
            d.as_secs_f64(),
            per_step(d)
        );
    }
    if let Some(p) = out {
        println!(
            "recording: {}  (open with: rerun {})",
            p.display(),
            p.display()
        );
    }
}
