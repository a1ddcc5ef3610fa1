//! `cellflip bench`: median per-stage step times and peak memory of a scene at several
//! resolutions. A measurement to read, never a pass/fail test.

use crate::cli::BenchArgs;
use crate::metrics::Stage;
use crate::scene::{Overrides, Scene};
use crate::sim::Simulation;
use anyhow::Result;
use std::time::Duration;

/// Peak resident memory of this process so far (Linux `VmHWM`), in MiB.
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

pub fn bench(args: &BenchArgs) -> Result<()> {
    println!(
        "scene {}, {} measured steps per resolution after {} warm-up steps, {} threads",
        args.scene,
        args.steps,
        args.warmup,
        rayon::current_num_threads()
    );
    let bands: Vec<Option<String>> = if args.band.is_empty() {
        vec![None]
    } else {
        args.band.iter().cloned().map(Some).collect()
    };
    for &res in &args.res {
        let mut results: Vec<(String, Measured)> = vec![];
        for band in &bands {
            let overrides = Overrides {
                cells: Some(res),
                method: args.method.clone(),
                band: band.clone(),
                ..Default::default()
            };
            let scene = Scene::load(&args.scene, &overrides)?;
            let m = match scene.dim() {
                2 => bench_dim::<2>(&scene, args)?,
                _ => bench_dim::<3>(&scene, args)?,
            };
            let name = scene.band.map_or("none", |b| b.variant.name()).to_string();
            results.push((name, m));
        }
        if let Some(((first, base), rest)) = results.split_first().filter(|(_, r)| !r.is_empty()) {
            println!(
                "
  at {res} cells, relative to band {first}:"
            );
            for (name, m) in rest {
                println!(
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
    config.correction.cross_check = args.cross_check;
    let mut sim = Simulation::<D>::new(config);
    for _ in 0..args.warmup {
        sim.step()?;
    }
    let mut solver_times = vec![];
    let mut other_times = vec![];
    let mut per_stage: Vec<Vec<Duration>> = vec![vec![]; Stage::ALL.len()];
    let mut totals = vec![];
    let mut iters = vec![];
    let mut band_gaps: Vec<(&str, Vec<f64>)> = vec![];
    let mut second_times = vec![];
    for _ in 0..args.steps {
        let rep = sim.step()?;
        if let Some(c) = &rep.correction {
            solver_times.push(c.solver_time);
            if let Some(t) = c.cross_check_time {
                other_times.push(t);
            }
            if let Some(b) = &c.band {
                second_times.push(b.second_time);
                for (v, o) in &b.other_objectives {
                    let gap = o.as_ref().map_or(f64::NAN, |o| {
                        (o - b.objective) / b.objective.abs().max(1e-12)
                    });
                    match band_gaps.iter_mut().find(|(n, _)| *n == v.name()) {
                        Some((_, g)) => g.push(gap),
                        None => band_gaps.push((v.name(), vec![gap])),
                    }
                }
            }
        }
        for s in Stage::ALL {
            per_stage[s as usize].push(rep.times.get(s));
        }
        totals.push(rep.times.total());
        iters.push(rep.pcg.iterations);
    }
    iters.sort();
    let band = match sim.band() {
        Some(b) => format!(
            ", band {} (R = {}): n_deep {} ({:.1}% of the fluid's particles held)",
            b.variant.name(),
            b.r,
            sim.n_deep,
            100.0 * sim.particles.len() as f64 / (sim.particles.len() + sim.n_deep).max(1) as f64
        ),
        None => String::new(),
    };
    println!(
        "\n{} at {:?} cells ({}), {} particles, {} fluid cells, median PCG iterations {}{band}",
        scene.name(),
        sim.grid.dims,
        scene.method.name(),
        sim.particles.len(),
        sim.markings.fluid_cells(),
        iters[iters.len() / 2]
    );
    println!("  {:<10} {:>12}", "stage", "median ms");
    for s in Stage::ALL {
        println!(
            "  {:<10} {:>12.2}",
            s.name(),
            median(per_stage[s as usize].clone()).as_secs_f64() * 1e3
        );
    }
    let step = median(totals.clone());
    println!("  {:<10} {:>12.2}", "step", step.as_secs_f64() * 1e3);
    let correct = &per_stage[Stage::Correct as usize];
    if !solver_times.is_empty() {
        let mut share: Vec<f64> = correct
            .iter()
            .zip(&totals)
            .map(|(c, t)| c.as_secs_f64() / t.as_secs_f64())
            .collect();
        share.sort_by(f64::total_cmp);
        let share = if other_times.is_empty() {
            format!(
                "; correction stage {:.1}% of the step (median of per-step shares)",
                100.0 * share[share.len() / 2]
            )
        } else {
            String::new() // the stage also timed the cross-check
        };
        println!(
            "  correction: {} solver median {:.2} ms{share}",
            scene.correction.solver.name(),
            median(solver_times.clone()).as_secs_f64() * 1e3,
        );
    }
    if !other_times.is_empty() {
        let mut ratios: Vec<f64> = other_times
            .iter()
            .zip(&solver_times)
            .map(|(o, s)| o.as_secs_f64() / s.as_secs_f64().max(1e-9))
            .collect();
        ratios.sort_by(f64::total_cmp);
        println!(
            "  same problems, other solver: median {:.2} ms; ratio other / {} median {:.0}x (min {:.0}x, max {:.0}x)",
            median(other_times).as_secs_f64() * 1e3,
            scene.correction.solver.name(),
            ratios[ratios.len() / 2],
            ratios[0],
            ratios[ratios.len() - 1]
        );
    }
    if !second_times.is_empty() && band_gaps.is_empty() {
        println!(
            "  band second step (one-way solve or path search): median {:.2} ms",
            median(second_times).as_secs_f64() * 1e3
        );
    }
    let variant = sim.band().map_or("", |b| b.variant.name());
    for (v, mut g) in band_gaps {
        let failed = g.iter().filter(|x| x.is_nan()).count();
        g.retain(|x| !x.is_nan());
        g.sort_by(f64::total_cmp);
        match (g.first(), g.last()) {
            (Some(lo), Some(hi)) => println!(
                "  band {v} on the same problems: objective {:+.3}% .. {:+.3}% (median {:+.3}%) relative to {variant}; failed on {failed} of {} steps",
                100.0 * lo,
                100.0 * hi,
                100.0 * g[g.len() / 2],
                g.len() + failed
            ),
            _ => println!("  band {v} on the same problems: failed on all {failed} steps"),
        }
    }
    if let Some(m) = peak_memory_mib() {
        println!("  peak memory (process so far): {m:.0} MiB");
    }
    Ok(Measured {
        step,
        particles: sim.particles.len(),
    })
}
