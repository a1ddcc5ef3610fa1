//! `cellflip bench`: median per-stage step times and peak memory of a scene at several
//! resolutions (and band settings), through the one runner. A measurement to read, never a
//! pass/fail test.

use crate::cmd::cli::BenchArgs;
use crate::methods::ccp::BandMode;
use crate::metrics::{median, Stage};
use crate::runner::{Limit, Runner};
use crate::scene::{peak_memory_mib, MemoryEstimate, Overrides, Scene};
use crate::solvers::pcg::Preconditioner;
use crate::step::Simulation;
use anyhow::{bail, Result};
use std::time::Duration;

pub fn bench(args: &BenchArgs) -> Result<()> {
    if args.steps == 0 {
        bail!("--steps: must be at least 1");
    }
    crate::outln!(
        "scene {}, {} measured steps per resolution after {} warm-up steps, {}, on {}",
        args.scene,
        args.steps,
        args.warmup,
        crate::stages::transfer::grid_to_particles_mode(),
        crate::machine::Machine::here(rayon::current_num_threads()),
    );
    let bands: Vec<Option<BandMode>> = match args.band.is_empty() {
        true => vec![None],
        false => args.band.iter().map(|b| Some(*b)).collect(),
    };
    let mut scaling = vec![];
    for &res in &args.res {
        let mut results: Vec<(&str, Measured)> = vec![];
        for band in &bands {
            let flags = match band {
                Some(b) => args.methods.clone().with("band", b),
                None => args.methods.clone(),
            };
            let overrides = Overrides {
                cells: Some(res),
                method: args.method,
                pressure: args.pressure.preconditioner.map(Into::into),
                flags,
                ..Default::default()
            };
            let scene = Scene::load(&args.scene, &overrides)?;
            scene.method.check_flags(&overrides.flags)?;
            // A flag that asks for a file (`--export-lp`) has no file to go beside here.
            if let Some(f) = scene.method.clone().files(std::path::Path::new("")).first() {
                bail!(
                    "--{}: cellflip bench writes no files; use cellflip run",
                    f.flag
                );
            }
            let estimate = scene.ensure_fits_in_memory(false)?;
            let m = match scene.dim() {
                2 => bench_dim::<2>(&scene, &estimate, args)?,
                _ => bench_dim::<3>(&scene, &estimate, args)?,
            };
            let band = scene.method.band().map_or("none", |b| b.variant);
            results.push((band, m));
        }
        print_band_ratios(res, &results);
        scaling.extend(results.into_iter().next().map(|(_, m)| (res, m)));
    }
    print_scaling(&scaling);
    Ok(())
}

/// What one measurement found.
struct Measured {
    /// Median step time.
    step: Duration,
    /// Median time of each stage, in [`Stage::ALL`] order.
    stages: Vec<Duration>,
    /// Particles held at the end (band particles with the band).
    particles: usize,
    fluid_cells: usize,
}

fn bench_dim<const D: usize>(
    scene: &Scene,
    e: &MemoryEstimate,
    args: &BenchArgs,
) -> Result<Measured> {
    let mut runner = Runner::new(Simulation::<D>::new(scene.config::<D>(), &scene.method));
    let started = peak_memory_mib();
    runner.run_to(Limit::Steps(args.warmup))?;
    runner.reset_summary();
    runner.run_to(Limit::Steps(args.warmup + args.steps))?;
    let (sim, s) = (&runner.sim.state, &runner.summary);
    crate::outln!(
        "\n{} at {:?} cells ({}), {} particles, {} fluid cells, median PCG iterations {} ({})",
        scene.name(),
        sim.grid.dims,
        scene.method.kind.name(),
        sim.particles.len(),
        sim.markings.fluid_cells(),
        median(&s.pcg_iterations).unwrap_or(0),
        preconditioner_shown(
            sim.config.pressure_preconditioner,
            sim.grid.dims.len(),
            sim.markings.fluid_cells()
        )
    );
    crate::outln!("  {:<10} {:>12}", "stage", "median ms");
    for st in Stage::ALL {
        crate::outln!(
            "  {:<10} {:>12.2}",
            st.name(),
            s.stage_median(st).as_secs_f64() * 1e3
        );
    }
    let step = s.step_median();
    crate::outln!("  {:<10} {:>12.2}", "step", step.as_secs_f64() * 1e3);
    let shares: Vec<f64> = s
        .step_times
        .iter()
        .map(|t| t.get(Stage::Correct).as_secs_f64() / t.total().as_secs_f64())
        .collect();
    if s.stage_total(Stage::Correct) > Duration::ZERO {
        crate::outln!(
            "  correction stage: {:.1}% of the step (median of per-step shares{})",
            100.0 * median(&shares).unwrap_or(0.0),
            if scene.method.cross_checks() {
                "; includes the cross-check"
            } else {
                ""
            }
        );
    }
    s.method_lines.iter().for_each(|l| crate::outln!("  {l}"));
    if let (Some(m), Some(started)) = (peak_memory_mib(), started) {
        crate::outln!(
            "  peak memory (process so far): {m:.0} MiB ({started:.0} after seeding and the \
             method's start); estimated up front {:.0} MiB (from {} cells{}, {} seeded fluid \
             cells, {:.0} particles seeded, {:.0} held, up to {:.0} once the liquid settles)",
            e.mib(),
            e.cells,
            e.active_cells
                .map_or(String::new(), |a| format!(" ({a} active)")),
            e.fluid_cells,
            e.particles,
            e.held,
            e.held_most
        );
    }
    Ok(Measured {
        step,
        stages: Stage::ALL.iter().map(|&st| s.stage_median(st)).collect(),
        particles: sim.particles.len(),
        fluid_cells: sim.markings.fluid_cells(),
    })
}

/// Each band setting's step time and particles against the first's.
fn print_band_ratios(res: usize, results: &[(&str, Measured)]) {
    let Some(((first, base), rest)) = results.split_first().filter(|(_, r)| !r.is_empty()) else {
        return;
    };
    crate::outln!("\n  at {res} cells, relative to band {first}:");
    for (name, m) in rest {
        crate::outln!(
            "  band {name}: step time ratio {:.2} ({:.1} / {:.1} ms); particles held {} vs {} ({:.1}%)",
            m.step.as_secs_f64() / base.step.as_secs_f64(),
            m.step.as_secs_f64() * 1e3,
            base.step.as_secs_f64() * 1e3,
            m.particles,
            base.particles,
            100.0 * m.particles as f64 / base.particles.max(1) as f64
        );
    }
}

/// Whether a stage's work grows with the particles or with the fluid cells: the grid stages
/// are quoted per fluid cell, the others per particle.
fn per_fluid_cell(st: Stage) -> bool {
    matches!(st, Stage::Forces | Stage::Pressure)
}

/// Each stage's time per particle or per fluid cell at every resolution, and the log-log slope
/// of the step time against the particle count (1 = linear), between neighbouring resolutions
/// and fitted over all of them.
fn print_scaling(runs: &[(usize, Measured)]) {
    if runs.len() < 2 {
        return;
    }
    crate::outln!("\n  scaling: ns per particle (per fluid cell for stages marked /cell)");
    let mut head = format!("  {:>5} {:>10} {:>10}", "res", "particles", "fluid");
    for st in Stage::ALL {
        let unit = if per_fluid_cell(st) { "/cell" } else { "" };
        head += &format!(" {:>14}", format!("{}{unit}", st.name()));
    }
    crate::outln!("{head} {:>10}", "step");
    for (res, m) in runs {
        let mut row = format!("  {res:>5} {:>10} {:>10}", m.particles, m.fluid_cells);
        for (st, t) in Stage::ALL.iter().zip(&m.stages) {
            let n = if per_fluid_cell(*st) {
                m.fluid_cells
            } else {
                m.particles
            };
            row += &format!(" {:>14.1}", t.as_secs_f64() * 1e9 / n.max(1) as f64);
        }
        crate::outln!(
            "{row} {:>10.1}",
            m.step.as_secs_f64() * 1e9 / m.particles.max(1) as f64
        );
    }
    let points: Vec<(f64, f64)> = runs
        .iter()
        .map(|(_, m)| ((m.particles.max(1) as f64).ln(), m.step.as_secs_f64().ln()))
        .collect();
    for (w, r) in points.windows(2).zip(runs.windows(2)) {
        let slope = (w[1].1 - w[0].1) / (w[1].0 - w[0].0);
        let (from, to) = (r[0].0, r[1].0);
        crate::outln!(
            "  log-log slope of the step time against particles, {from} -> {to}: {slope:.2}"
        );
    }
    if let Some(fit) = least_squares_slope(&points).filter(|_| points.len() > 2) {
        crate::outln!("  fitted over all resolutions: {fit:.2}");
    }
}

/// The slope of the least-squares line through `points`; `None` when every x is the same.
fn least_squares_slope(points: &[(f64, f64)]) -> Option<f64> {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let sxx: f64 = points.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// The preconditioner a bench names: `auto` with what it chose for the last step's fluid
/// cells (the pressure solve's rows), as `auto: multigrid`.
fn preconditioner_shown(p: Preconditioner, dim: usize, rows: usize) -> String {
    match p {
        Preconditioner::Auto => format!("auto: {}", p.for_size(dim, rows).name()),
        p => p.name().to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fitted_slope_of_a_power_law_is_its_exponent() {
        let points: Vec<(f64, f64)> = [1e3, 1e4, 1e5]
            .iter()
            .map(|n: &f64| (n.ln(), (2e-7 * n.powf(1.25)).ln()))
            .collect();
        assert!((least_squares_slope(&points).unwrap() - 1.25).abs() < 1e-12);
        assert_eq!(least_squares_slope(&[(1.0, 2.0), (1.0, 3.0)]), None);
    }
}
