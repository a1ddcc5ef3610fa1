//! Times the liquid surface reconstruction (`cellflip::surface`) on a 3D scene's frame, to
//! weigh it against the run's step time (issue 38 item 3: the surface adds at most 20% to a
//! run's wall time at the default cadence of one frame per 1/25 s simulated).
//!
//! `cargo run --release --example surface_cost -- [SCENE] [CELLS] [STEPS] [REPEATS]`
//! (defaults dam-3d 64 1 5): seeds the scene as `cellflip run` does, takes STEPS steps (one, so
//! that the band methods have a deep), then reconstructs the surface REPEATS times and prints
//! the median time with the mesh's size, beside the median time of the steps taken.

use cellflip::scene::{Overrides, Scene};
use cellflip::step::Simulation;
use cellflip::surface::reconstruct;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or_else(|| default.into());
    let (name, cells) = (arg(0, "dam-3d"), arg(1, "64").parse::<usize>()?);
    let (steps, repeats) = (arg(2, "1").parse::<usize>()?, arg(3, "5").parse::<usize>()?);
    let scene = Scene::load(
        &name,
        &Overrides {
            cells: Some(cells),
            ..Default::default()
        },
    )?;
    anyhow::ensure!(scene.dims.len() == 3, "{name} is not a 3D scene");
    let mut sim = Simulation::<3>::new(scene.config::<3>(), &scene.method);
    let mut step_secs = Vec::new();
    for _ in 0..steps {
        let t = Instant::now();
        sim.step()?;
        step_secs.push(t.elapsed().as_secs_f64());
    }
    let s = &sim.state;
    let positions: Vec<[f64; 3]> = s.particles.pos.iter().map(|p| [p[0], p[1], p[2]]).collect();
    let deep: Vec<[usize; 3]> = (0..s.grid.num_cells())
        .filter(|&c| sim.method.is_deep(s, c))
        .map(|c| s.grid.cell_coords(c))
        .collect();
    let domain = s.grid.dims;
    let mu = s.config.mu() as usize;
    let mut secs = Vec::new();
    let mut mesh = Default::default();
    for _ in 0..repeats {
        let t = Instant::now();
        mesh = reconstruct(&positions, &deep, domain, mu);
        secs.push(t.elapsed().as_secs_f64());
    }
    let m: &cellflip::surface::SurfaceMesh = &mesh;
    println!(
        "{name} {domain:?} after {steps} step(s): {} particles, {} deep cells, mu {mu}",
        positions.len(),
        deep.len()
    );
    println!(
        "surface: median {:.1} ms over {repeats} (min {:.1}); {} vertices, {} triangles, encloses {:.0} cells",
        1e3 * median(&mut secs),
        1e3 * secs.iter().cloned().fold(f64::INFINITY, f64::min),
        m.vertices.len(),
        m.triangles.len(),
        m.enclosed_volume()
    );
    if !step_secs.is_empty() {
        println!(
            "step: median {:.1} ms over {steps}",
            1e3 * median(&mut step_secs)
        );
    }
    Ok(())
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
