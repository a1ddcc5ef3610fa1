//! `cellflip bench`: median per-stage step times and peak memory of a scene at several
//! resolutions (and band settings), through the one runner. A measurement to read, never a
//! pass/fail test.

use crate::cli::BenchArgs;
use crate::methods::MethodOption;
use crate::metrics::{median, Stage};
use crate::runner::{Limit, Runner};
use crate::scene::{Overrides, Scene};
use crate::sim::correct::band::BandMode;
use crate::sim::Simulation;
use anyhow::{bail, Result};
use std::time::Duration;

/// Peak resident memory of this process so far (Linux `VmHWM`), in MiB.
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

pub fn bench(args: &BenchArgs) -> Result<()> {
    if args.steps == 0 {
        bail!("--steps: must be at least 1");
    }
    crate::outln!(
        "scene {}, {} measured steps per resolution after {} warm-up steps, {} threads",
        args.scene,
        args.steps,
        args.warmup,
        rayon::current_num_threads()
    );
    let bands: Vec<Option<BandMode>> = match args.band.is_empty() {
        true => vec![None],
        false => args.band.iter().map(|b| Some(*b)).collect(),
    };
    for &res in &args.res {
        let mut results: Vec<(&str, Measured)> = vec![];
        for band in &bands {
            let overrides = Overrides {
                cells: Some(res),
                method: args.method,
                band: *band,
                ..Default::default()
            };
            let scene = Scene::load(&args.scene, &overrides)?;
            scene.ensure_fits_in_memory()?;
            let given = [
                (MethodOption::Band, band.is_some()),
                (MethodOption::CrossCheck, args.cross_check),
            ];
            let given: Vec<_> = given.iter().filter(|g| g.1).map(|g| g.0).collect();
            scene
                .method
                .check_given(&given)
                .map_err(anyhow::Error::msg)?;
            let m = match scene.dim() {
                2 => bench_dim::<2>(&scene, args)?,
                _ => bench_dim::<3>(&scene, args)?,
            };
            results.push((scene.method.band.name(), m));
        }
        print_band_ratios(res, &results);
    }
    Ok(())
}

/// What one measurement found.
struct Measured {
    /// Median step time.
    step: Duration,
    /// Particles held at the end (band particles with the band).
    particles: usize,
}

fn bench_dim<const D: usize>(scene: &Scene, args: &BenchArgs) -> Result<Measured> {
    let mut config = scene.config::<D>();
    config.method.cross_check = args.cross_check;
    let mut runner = Runner::new(Simulation::<D>::new(config));
    runner.run(Limit::Steps(args.warmup), || false, |_, _| Ok(()))?;
    runner.reset_summary();
    runner.run(
        Limit::Steps(args.warmup + args.steps),
        || false,
        |_, _| Ok(()),
    )?;
    let (sim, s) = (&runner.sim.state, &runner.summary);
    crate::outln!(
        "\n{} at {:?} cells ({}), {} particles, {} fluid cells, median PCG iterations {}",
        scene.name(),
        sim.grid.dims,
        scene.method.kind.name(),
        sim.particles.len(),
        sim.markings.fluid_cells(),
        median(&s.pcg_iterations).unwrap_or(0)
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
            if args.cross_check {
                "; includes the cross-check"
            } else {
                ""
            }
        );
    }
    s.method_lines.iter().for_each(|l| crate::outln!("  {l}"));
    if let Some(m) = peak_memory_mib() {
        crate::outln!("  peak memory (process so far): {m:.0} MiB");
    }
    Ok(Measured {
        step,
        particles: sim.particles.len(),
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
