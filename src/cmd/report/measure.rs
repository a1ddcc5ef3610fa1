//! One run of the report's matrix, measured: the errors and costs of [`COLUMNS`] and the time
//! series the plots and the comparison recording show. Each error's formula is in docs/report.md
//! (section "The figures").

pub use super::measured::{Gathered, Measured};
use super::saved::{restore_progress, save_result, Progress, RunCheckpoints, RunFiles};
use super::RunSpec;
use crate::checkpoint::{self, Opened};
use crate::methods::MethodKind;
use crate::metrics::{median, Stage};
use crate::record::ComparisonSeries;
use crate::runner::{Limit, Runner};
use crate::scene::{peak_memory_mib, Scene};
use crate::snapshot::SnapshotError;
use crate::step::{Simulation, StepReport};
use crate::validation::{MartinMoyceProbe, COLUMN_WIDTH_M};
use std::cell::Cell;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

/// The columns of `report.csv` that every run has, with what they hold. Each method adds
/// `<figure>_median` and `<figure>_mean` for the figures it lists
/// ([`crate::methods::MethodInfo::figures`]).
pub const COLUMNS: &[(&str, &str)] = &[
    ("scene", "the scene (or variant) as the tables name it"),
    ("method", "the fluid method"),
    ("res", "cells along the longest axis"),
    ("seed", "random seed"),
    ("tables", "accuracy, stability or both"),
    ("status", "ok, interrupted, failed: step N: why, or not run: why"),
    ("build", "the build of cellflip that ran it: its version and a CRC-32 of its executable"),
    ("machine", "the kind of machine that ran it (that finished it, when resumed): CPU model, cores and worker threads; empty for a run kept before runs recorded it. Compare timings between runs of one kind"),
    ("copy_gb_s", "that machine's memory copy bandwidth as the process that ran it measured it (once, before its first run), GB/s"),
    ("dim", "2 or 3"),
    ("particles", "particles held at the end"),
    ("grid_cells", "cells of the grid, every axis's count multiplied"),
    ("steps", "steps run"),
    ("n_mean", "particles in the scene, a band method's imaginary ones included, mean over the steps (the paper's n)"),
    ("held_mean", "particles the method holds, mean over the steps (the paper's band, for a band method)"),
    ("sim_s", "simulated seconds"),
    ("volume_min", "lowest V/V* over the run, % (eq. volume)"),
    ("volume_max", "highest V/V*, %"),
    ("volume_error", "mean over the steps of |V/V* - 1|, %"),
    ("volume_end", "V/V* at the end, %"),
    ("front_error", "martin-moyce-2d: mean relative error of the surge front against experiment, %"),
    ("column_error", "martin-moyce-2d: mean relative error of the column height, %"),
    ("rest_speed", "hydrostatic-2d: the liquid's top speed at the end (particles and deep cells), m/s"),
    ("rest_ke", "hydrostatic-2d: kinetic energy per unit mass at the end, m^2/s^2"),
    ("obstacle_bottom", "first obstacle's lowest point at the end, m"),
    ("obstacle_lowest", "the lowest it can reach, m: the floor, or for a lid as wide as the tank the height the fluid fills at mu per cell"),
    ("obstacle_held", "share of steps the first obstacle had to stay"),
    ("in_solids", "particles inside solid cells at the end"),
    ("compression", "largest particle count of a cell over mu, over the run"),
    ("ke_max", "largest kinetic energy per unit mass over the run, m^2/s^2"),
    ("ke_end", "kinetic energy per unit mass at the end, m^2/s^2"),
    ("ms_per_step", "median wall time of a step (all stages), ms"),
    ("ms_per_sim_s", "wall time of the stages per simulated second, ms"),
    ("peak_mib", "peak resident memory during the run, MiB"),
    ("pcg_median", "median PCG iterations of the pressure solve"),
    ("pressure_ms_mean", "mean wall time of the pressure solve per step, ms (the paper's Poisson)"),
    ("correct_ms_mean", "mean wall time of the position correction per step, ms (the paper's LP and MCFP together)"),
    ("share_emit", "share of the stage in the step time, %"),
    ("share_p2g", "share of particles-to-grid, %"),
    ("share_forces", "share of forces, %"),
    ("share_pressure", "share of the pressure solve, %"),
    ("share_g2p", "share of grid-to-particles, %"),
    ("share_advect", "share of advection, %"),
    ("share_correct", "share of the position correction (ccp, idp), %"),
    ("share_markings", "share of the markings, %"),
];

/// Runs and measures one spec; a scene that cannot load is a row that says why. With `files`
/// the run goes on from its checkpoint if it has one, checkpoints as it goes, and is kept
/// once it ends ([`super::saved`]).
pub fn run(
    spec: &RunSpec,
    stop: &dyn Fn() -> bool,
    files: Option<&RunFiles>,
    resumed: Option<Opened>,
) -> Measured {
    let mut m = Measured::new(spec);
    match super::load(spec) {
        Err(e) => m.status = one_line(&format!("not run: {e:#}")),
        Ok(scene) => {
            m.res = scene.file.domain.cells;
            m.seed = scene.file.simulation.seed;
            m.dim = scene.dim();
            match scene.dim() {
                2 => measure::<2>(&scene, stop, &mut m, files, resumed),
                _ => measure::<3>(&scene, stop, &mut m, files, resumed),
            }
        }
    }
    m
}

/// A message on one line (for CSV rows and table cells): runs of whitespace, line breaks
/// included, become one space.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn measure<const D: usize>(
    scene: &Scene,
    stop: &dyn Fn() -> bool,
    m: &mut Measured,
    files: Option<&RunFiles>,
    resumed: Option<Opened>,
) {
    crate::machine::reset_peak_memory();
    let mut g = Gathered {
        probe: (scene.name() == "martin-moyce-2d").then(MartinMoyceProbe::default),
        ..Default::default()
    };
    let started =
        begin::<D>(scene, resumed.as_ref(), m, &mut g).and_then(|(runner, lowest, spent)| {
            let saves = files
                .map(|f| RunCheckpoints::new(f, scene, resumed.as_ref()))
                .transpose()?;
            Ok((runner, lowest, spent, saves))
        });
    let (mut runner, lowest, spent, mut saves) = match started {
        Ok(s) => s,
        Err(e) => {
            m.status = one_line(&format!("failed: {e:#}"));
            return;
        }
    };
    // The checkpoint file's copy of the state is not kept for the whole run.
    drop(resumed);
    let mu = runner.sim.state.config.mu() as f64;
    let limit = Limit::SimSeconds(scene.duration_secs());
    let t0 = std::time::Instant::now();
    let budget = m.spec.budget.unwrap_or(f64::INFINITY);
    let over = || (spent + t0.elapsed()).as_secs_f64() > budget;
    // Pauses every `files.every` for a checkpoint, then goes on.
    let every = files.map_or(Duration::MAX, |f| f.every);
    let result = loop {
        let pause = std::time::Instant::now().checked_add(every);
        // At least one step between two checkpoints.
        let (stepped, paused) = (Cell::new(false), Cell::new(false));
        let pause_now = || {
            let due = pause.is_some_and(|p| std::time::Instant::now() >= p);
            paused.set(stepped.get() && due);
            paused.get()
        };
        let result = runner.run(
            limit,
            || stop() || over() || pause_now(),
            |sim, rep| {
                observe(sim, rep, mu, &mut g, m);
                stepped.set(true);
                Ok(())
            },
        );
        // Only a pause goes on; the run stopped by itself, a signal or its budget ends.
        if result.is_err() || !paused.get() {
            break result;
        }
        runner.summary.interrupted = false;
        let p = progress(m, &g, &runner, lowest, spent + t0.elapsed());
        if let Some(Err(e)) = saves.as_mut().map(|s| s.save(&runner.sim, &p)) {
            break Err(e);
        }
    };
    m.status = match (&result, runner.summary.interrupted) {
        (Err(e), _) => one_line(&format!("failed: {e:#}")),
        (Ok(()), true) if !stop() => format!(
            "over budget: stopped after {budget} s wall at t = {:.3} of {} s",
            runner.sim.state.time_secs,
            scene.duration_secs()
        ),
        (Ok(()), true) => "interrupted".into(),
        (Ok(()), false) => "ok".into(),
    };
    let stopped = m.status == "interrupted";
    if let (true, Some(s)) = (stopped, saves.as_mut()) {
        let p = progress(m, &g, &runner, lowest, spent + t0.elapsed());
        if let Err(e) = s.save(&runner.sim, &p) {
            eprintln!("warning: {e:#}: the run will start again from its beginning");
        }
    }
    finish(&runner, &g, lowest, m);
    if let (false, Some(f), Some(s)) = (stopped, files, saves) {
        match save_result(f, m) {
            Ok(()) => s.remove(),
            Err(e) => eprintln!("warning: {e:#}: the run will be run again"),
        }
    }
}

/// The simulation at the run's start and what it measured so far: new, or restored from its
/// checkpoint; the first obstacle's lowest possible point (from the run's start, m) and the
/// wall time it took so far.
fn begin<const D: usize>(
    scene: &Scene,
    resumed: Option<&Opened>,
    m: &mut Measured,
    g: &mut Gathered,
) -> anyhow::Result<(Runner<D>, f64, Duration)> {
    let Some(c) = resumed else {
        let sim = Simulation::<D>::new(scene.config::<D>(), &scene.method);
        let lowest = obstacle_lowest(&sim) * sim.state.config.cell_size_m;
        return Ok((Runner::new(sim), lowest, Duration::ZERO));
    };
    let bad = |e: SnapshotError| anyhow::anyhow!("checkpoint '{}': {e}", c.path.display());
    let sim = Simulation::<D>::restore(scene.config::<D>(), &scene.method, &c.reader);
    let mut runner = Runner::new(sim.map_err(bad)?);
    let (lowest, spent) = restore_progress(&c.reader, m, g, &mut runner.summary).map_err(bad)?;
    Ok((runner, lowest, spent))
}

/// The newest complete checkpoint in `dir`, if the run has one.
pub fn resumable(dir: &Path) -> Option<Opened> {
    if !dir.is_dir() {
        return None;
    }
    let opened = checkpoint::open(dir)
        .map_err(anyhow::Error::from)
        .and_then(|c| match c.reader.meta("program") {
            Ok(p) if p == checkpoint::build() => Ok(c),
            _ => anyhow::bail!("'{}' was written by another build", c.path.display()),
        });
    opened
        .inspect_err(|e| eprintln!("warning: {e:#}; the run starts again from its beginning"))
        .ok()
}

fn progress<'a, const D: usize>(
    m: &'a Measured,
    g: &'a Gathered,
    runner: &'a Runner<D>,
    lowest: f64,
    spent: Duration,
) -> Progress<'a> {
    Progress {
        measured: m,
        gathered: g,
        summary: &runner.summary,
        lowest,
        spent,
    }
}

fn observe<const D: usize>(
    sim: &Simulation<D>,
    rep: &StepReport<D>,
    mu: f64,
    g: &mut Gathered,
    m: &mut Measured,
) {
    let s = &sim.state;
    m.volume.push((s.time_secs, rep.volume_percent));
    m.ke.push((s.time_secs, sim.liquid_motion().kinetic_energy));
    let most = s.markings.count.iter().max().copied().unwrap_or(0) as f64;
    g.compression = g.compression.max(most / mu);
    g.held += rep.blocked.first().copied().unwrap_or(false) as u64;
    let held = s.particles.len() as f64;
    g.particles_held += held;
    g.particles_all += held + sim.method.particles_not_held() as f64;
    for (name, v) in rep.method.figures() {
        g.figures.entry(name).or_default().push(v);
    }
    if let (Some(p), Some(sim2)) = (&mut g.probe, as_2d(sim)) {
        p.observe(sim2);
    }
}

/// The simulation as a 2D one, when it is.
fn as_2d<const D: usize>(sim: &Simulation<D>) -> Option<&Simulation<2>> {
    (sim as &dyn std::any::Any).downcast_ref::<Simulation<2>>()
}

/// The lowest the first obstacle can get, cells: the floor, or for a lid as wide as the tank
/// the height the fluid fills at `mu` per cell.
fn obstacle_lowest<const D: usize>(sim: &Simulation<D>) -> f64 {
    let s = &sim.state;
    let Some(o) = s.solids.obstacles.first() else {
        return f64::NAN;
    };
    let (lo, hi) = o.region_at(&o.offset).bounds();
    let wide = (0..D)
        .filter(|&k| k != 1)
        .all(|k| lo[k] <= 0.5 && hi[k] >= s.grid.dims[k] as f64 - 0.5);
    if !wide {
        return 0.0;
    }
    let across: usize = (0..D).filter(|&k| k != 1).map(|k| s.grid.dims[k]).product();
    s.target_volume / across as f64
}

fn finish<const D: usize>(runner: &Runner<D>, g: &Gathered, lowest: f64, m: &mut Measured) {
    let (s, sum) = (&runner.sim.state, &runner.summary);
    let h = s.config.cell_size_m;
    let mut v: BTreeMap<String, f64> = BTreeMap::new();
    let mut put = |k: &str, x: f64| {
        v.insert(k.to_string(), x);
    };
    let steps = sum.steps.max(1) as f64;
    put("particles", s.particles.len() as f64);
    put("grid_cells", s.grid.dims.iter().product::<usize>() as f64);
    put("steps", sum.steps as f64);
    put("n_mean", g.particles_all / steps);
    put("held_mean", g.particles_held / steps);
    put("sim_s", s.time_secs);
    put("volume_min", sum.volume_min);
    put("volume_max", sum.volume_max);
    let err: f64 = m.volume.iter().map(|(_, x)| (x - 100.0).abs()).sum();
    put("volume_error", err / steps);
    put("volume_end", m.volume.last().map_or(f64::NAN, |x| x.1));
    if let Some(p) = &g.probe {
        let c = p.compare(0.0, sum.steps, COLUMN_WIDTH_M / h);
        put("front_error", 100.0 * c.front_mean_relative_error());
        put("column_error", 100.0 * c.height_mean_relative_error());
        m.front = c.front.iter().map(|r| (r.time, r.simulated)).collect();
    }
    if m.spec.label == "hydrostatic-2d" {
        put("rest_speed", runner.sim.liquid_motion().top_speed);
        put("rest_ke", m.ke.last().map_or(f64::NAN, |x| x.1));
    }
    if let Some(o) = s.solids.obstacles.first() {
        put("obstacle_bottom", o.bottom() * h);
        put("obstacle_lowest", lowest);
        put("obstacle_held", g.held as f64 / steps);
    }
    let inside = s
        .particles
        .pos
        .iter()
        .filter(|x| s.solids.solid[s.grid.cell_index_of(x)])
        .count();
    put("in_solids", inside as f64);
    put("compression", g.compression);
    put("ke_max", m.ke.iter().map(|x| x.1).fold(f64::NAN, f64::max));
    put("ke_end", m.ke.last().map_or(f64::NAN, |x| x.1));
    costs(runner, &mut v);
    m.values = v;
    for (name, xs) in &g.figures {
        m.values
            .insert(format!("{name}_median"), median(xs).unwrap_or(f64::NAN));
        m.values.insert(format!("{name}_mean"), mean(xs));
    }
}

/// Median step, wall per simulated second, peak memory, PCG, stage shares.
fn costs<const D: usize>(runner: &Runner<D>, v: &mut BTreeMap<String, f64>) {
    let sum = &runner.summary;
    let total: f64 = Stage::ALL
        .iter()
        .map(|&st| sum.stage_total(st).as_secs_f64())
        .sum();
    let time = runner.sim.state.time_secs.max(1e-12);
    let pcg = median(&sum.pcg_iterations).map_or(f64::NAN, |x| x as f64);
    for (k, x) in [
        ("ms_per_step", sum.step_median().as_secs_f64() * 1e3),
        ("ms_per_sim_s", 1e3 * total / time),
        ("peak_mib", peak_memory_mib().unwrap_or(f64::NAN)),
        ("pcg_median", pcg),
    ] {
        v.insert(k.to_string(), x);
    }
    let steps = sum.step_times.len() as f64;
    for (k, st) in [
        ("pressure_ms_mean", Stage::Pressure),
        ("correct_ms_mean", Stage::Correct),
    ] {
        v.insert(
            k.to_string(),
            1e3 * sum.stage_total(st).as_secs_f64() / steps,
        );
    }
    for st in Stage::ALL {
        let share = 100.0 * sum.stage_total(st).as_secs_f64() / total.max(1e-12);
        v.insert(share_column(st), share);
    }
}

/// The column of a stage's share: `share_<stage name>`.
pub fn share_column(st: Stage) -> String {
    format!("share_{}", st.name())
}

/// Every method figure column, in registration order.
pub fn figure_columns() -> Vec<String> {
    MethodKind::ALL
        .iter()
        .flat_map(|k| k.info().figures.iter())
        .flat_map(|f| [format!("{f}_median"), format!("{f}_mean")])
        .collect()
}

/// The mean of `xs` (NaN when empty).
fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// The runs' time series for the comparison recording.
pub fn comparison_series(results: &[Measured]) -> Vec<ComparisonSeries<'_>> {
    results
        .iter()
        .filter(|m| !m.volume.is_empty())
        .map(|m| ComparisonSeries {
            scene: &m.spec.label,
            method: m.spec.method.name(),
            color: m.spec.method.rgb(),
            res: m.res,
            seed: m.seed,
            volume: &m.volume,
            ke: &m.ke,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_has_its_share_column_documented() {
        for st in Stage::ALL {
            let c = share_column(st);
            assert!(COLUMNS.iter().any(|(name, _)| *name == c), "{c}");
        }
    }
}
