//! Every built-in scene runs with its invariants intact (checked inside every step), in 2D and
//! 3D; emitters reach their target; runs are deterministic.

use cellflip::scene::{Overrides, Scene, BUILT_IN};
use cellflip::sim::Simulation;

fn run<const D: usize>(name: &str, overrides: &Overrides, steps: u64) -> Simulation<D> {
    let scene = Scene::load(name, overrides).unwrap();
    let mut sim = Simulation::<D>::new(scene.config::<D>());
    sim.check_invariants().unwrap();
    for _ in 0..steps {
        let rep = sim
            .step()
            .unwrap_or_else(|e| panic!("{name} step {}: {e}", sim.steps + 1));
        assert!(rep.volume_percent.is_finite() && rep.dt_secs > 0.0);
        assert!(
            rep.pcg.converged,
            "{name} step {}: {:?}",
            sim.steps, rep.pcg
        );
        // Nothing moves more than one cell per axis per step (sec. grid_move).
        assert!(rep.max_speed * rep.dt_secs <= sim.config.cfl * (1.0 + 1e-12));
    }
    sim
}

#[test]
fn every_2d_scene_keeps_its_invariants() {
    for (name, _) in BUILT_IN {
        let scene = Scene::load(name, &Overrides::default()).unwrap();
        if scene.dim() == 2 {
            run::<2>(name, &Overrides::default(), 60);
        }
    }
}

#[test]
fn every_3d_scene_keeps_its_invariants() {
    for (name, _) in BUILT_IN {
        let scene = Scene::load(name, &Overrides::default()).unwrap();
        if scene.dim() == 3 {
            // 20 cells along the shortest axis.
            let (lo, hi) = (
                scene.dims.iter().min().unwrap(),
                scene.dims.iter().max().unwrap(),
            );
            let small = Overrides {
                cells: Some(20 * hi / lo),
                ..Default::default()
            };
            let sim = run::<3>(name, &small, 40);
            assert!(sim.particles.len() > 1000);
        }
    }
}

#[test]
fn dam_2d_emitter_fills_exactly_half_the_tank() {
    let scene = Scene::load("dam-2d", &Overrides::default()).unwrap();
    let mut sim = Simulation::<2>::new(scene.config::<2>());
    let seeded = sim.particles.len();
    while sim.time_secs < scene.duration_secs() {
        sim.step().unwrap();
    }
    let cells = sim.grid.num_cells();
    assert_eq!(sim.particles.len(), 4 * cells / 2);
    assert!(sim.particles.len() > seeded);
    assert!((sim.target_volume - cells as f64 / 2.0).abs() < 1e-9);
}

#[test]
fn same_seed_gives_bit_identical_particles() {
    let a = run::<2>("dam-2d", &Overrides::default(), 80);
    let b = run::<2>("dam-2d", &Overrides::default(), 80);
    assert_eq!(a.particles, b.particles);
    let other = Overrides {
        seed: Some(99),
        ..Default::default()
    };
    let c = run::<2>("dam-2d", &other, 80);
    assert_ne!(a.particles.pos, c.particles.pos);
    let d3a = run::<3>(
        "drop-3d",
        &Overrides {
            cells: Some(16),
            ..Default::default()
        },
        20,
    );
    let d3b = run::<3>(
        "drop-3d",
        &Overrides {
            cells: Some(16),
            ..Default::default()
        },
        20,
    );
    assert_eq!(d3a.particles, d3b.particles);
}

#[test]
fn thread_count_does_not_change_the_result() {
    let overrides = Overrides {
        cells: Some(20),
        ..Default::default()
    };
    let with_threads = |n| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap();
        pool.install(|| run::<3>("dam-3d", &overrides, 15).particles)
    };
    assert_eq!(with_threads(1), with_threads(3));
}

#[test]
fn a_non_finite_state_stops_the_step_with_an_error_not_a_panic() {
    for method in ["flip", "ccp"] {
        let scene = Scene::load(
            "drop-2d",
            &Overrides {
                method: Some(method.into()),
                ..Default::default()
            },
        )
        .unwrap();
        let mut sim = Simulation::<2>::new(scene.config::<2>());
        sim.step().unwrap();
        sim.particles.vel[7][0] = f64::NAN;
        let err = sim.step().expect_err("a NaN velocity must not pass");
        assert!(err.0.contains("not finite"), "{method}: {err}");
    }
}
