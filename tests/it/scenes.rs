//! Every built-in scene runs with its invariants intact (checked inside every step), in 2D and
//! 3D; emitters reach their target; runs are deterministic.

use crate::common::{load, run};
use cellflip::methods::MethodKind;
use cellflip::scene::{Overrides, Scene, BUILT_IN};
use cellflip::step::Simulation;

/// Runs a built-in scene, checking every step: a finite volume, a positive time step, a
/// converged pressure solve, and nothing moving more than `cfl` cells (sec. grid_move).
fn run_checked<const D: usize>(name: &str, overrides: &Overrides, steps: u64) -> Simulation<D> {
    let scene = load(name, overrides);
    let sim = Simulation::<D>::new(scene.config::<D>(), &scene.method);
    sim.check_invariants().unwrap();
    run::<D>(&scene, Some(steps), |sim, rep| {
        let at = format!("{name} step {}", sim.state.steps);
        assert!(rep.volume_percent.is_finite() && rep.dt_secs > 0.0, "{at}");
        assert!(rep.pcg.converged, "{at}: {:?}", rep.pcg);
        let cfl = sim.state.config.cfl;
        assert!(rep.max_speed * rep.dt_secs <= cfl * (1.0 + 1e-12), "{at}");
    })
    .sim
}

#[test]
fn every_2d_scene_keeps_its_invariants() {
    for (name, _) in BUILT_IN {
        if load(name, &Overrides::default()).dim() == 2 {
            run_checked::<2>(name, &Overrides::default(), 60);
        }
    }
}

#[test]
fn every_3d_scene_keeps_its_invariants() {
    for (name, _) in BUILT_IN {
        let scene = load(name, &Overrides::default());
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
            let sim = run_checked::<3>(name, &small, 40);
            assert!(sim.state.particles.len() > 1000);
        }
    }
}

#[test]
fn dam_2d_emitter_fills_exactly_half_the_tank() {
    let scene = load("dam-2d", &Overrides::default());
    let seeded = Simulation::<2>::new(scene.config::<2>(), &scene.method)
        .state
        .particles
        .len();
    let s = run::<2>(&scene, None, |_, _| {}).sim.state;
    let cells = s.grid.num_cells();
    assert_eq!(s.particles.len(), 4 * cells / 2);
    assert!(s.particles.len() > seeded);
    assert!((s.target_volume - cells as f64 / 2.0).abs() < 1e-9);
}

#[test]
fn same_seed_gives_bit_identical_particles() {
    let dam = |seed| {
        let o = Overrides {
            seed,
            ..Default::default()
        };
        run_checked::<2>("dam-2d", &o, 80).state.particles
    };
    let a = dam(None);
    assert_eq!(a, dam(None));
    assert_ne!(a.pos, dam(Some(99)).pos);
    let drop = || {
        let o = Overrides {
            cells: Some(16),
            ..Default::default()
        };
        run_checked::<3>("drop-3d", &o, 20).state.particles
    };
    assert_eq!(drop(), drop());
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
        pool.install(|| run_checked::<3>("dam-3d", &overrides, 15).state.particles)
    };
    assert_eq!(with_threads(1), with_threads(3));
}

#[test]
fn every_method_runs_every_built_in_scene_for_a_few_steps() {
    for (name, _) in BUILT_IN {
        for &method in MethodKind::ALL {
            let three = load(name, &Overrides::default()).dim() == 3;
            let o = Overrides {
                method: Some(method),
                // 3D at 24 cells along the longest axis (whole cells for every 3D tank).
                cells: three.then_some(24),
                ..Default::default()
            };
            let scene =
                Scene::load(name, &o).unwrap_or_else(|e| panic!("{name}, {method:?}: {e:#}"));
            // Every figure a step reports is one its method registers: a report job's
            // checkpoint keeps the figures by name and a resume looks them up there.
            let registered = |names: Vec<(&str, f64)>| {
                for (name, _) in names {
                    let known = method.info().figures.contains(&name);
                    assert!(known, "{method:?} reports figure {name}, not registered");
                }
            };
            match three {
                false => drop(run::<2>(&scene, Some(5), |_, r| {
                    registered(r.method.figures())
                })),
                true => drop(run::<3>(&scene, Some(3), |_, r| {
                    registered(r.method.figures())
                })),
            }
        }
    }
}
