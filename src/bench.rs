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
        "scene {}, {} measured steps per resolution after 1 warm-up step, {} threads",
        args.scene,
        args.steps,
        rayon::current_num_threads()
    );
    for &res in &args.res {
        let overrides = Overrides {
            cells: Some(res),
            method: args.method.clone(),
            ..Default::default()
        };
        let scene = Scene::load(&args.scene, &overrides)?;
        match scene.dim() {
            2 => bench_dim::<2>(&scene, args.steps)?,
            _ => bench_dim::<3>(&scene, args.steps)?,
        }
    }
    Ok(())
}

fn bench_dim<const D: usize>(scene: &Scene, steps: u64) -> Result<()> {
    let mut sim = Simulation::<D>::new(scene.config::<D>());
    sim.step()?;
    let mut per_stage: Vec<Vec<Duration>> = vec![vec![]; Stage::ALL.len()];
    let mut totals = vec![];
    let mut iters = vec![];
    for _ in 0..steps {
        let rep = sim.step()?;
        for s in Stage::ALL {
            per_stage[s as usize].push(rep.times.get(s));
        }
        totals.push(rep.times.total());
        iters.push(rep.pcg.iterations);
    }
    iters.sort();
    println!(
        "\n{} at {:?} cells ({}), {} particles, {} fluid cells, median PCG iterations {}",
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
    println!(
        "  {:<10} {:>12.2}",
        "step",
        median(totals).as_secs_f64() * 1e3
    );
    if let Some(m) = peak_memory_mib() {
        println!("  peak memory (process so far): {m:.0} MiB");
    }
    Ok(())
}
