//! Coupling with solids (paper sec. 7): obstacles under ccp never overlap a particle and still
//! get through the fluid; the baselines' options lose volume (`ignore`) or halt (`naive`).
//! Every step checks the invariants inside `step` (no particle in a solid, cell bounds after
//! the correction, counts conserved, all finite).

use crate::common::{self, load};
use cellflip::grid::Vector;
use cellflip::methods::ccp::BandMode;
use cellflip::methods::ccp::CcpReport;
use cellflip::methods::MethodFlags;
use cellflip::methods::MethodKind;
use cellflip::runner::Limit;
use cellflip::scene::{Overrides, Scene};
use cellflip::stages::solids::{Obstacle, ObstacleMode, Solids};
use cellflip::step::Simulation;

pub(crate) struct Run {
    pub(crate) volume_min: f64,
    /// Lowest point of the first obstacle at the end, cells.
    pub(crate) bottom: f64,
    pub(crate) blocked_steps: usize,
    pub(crate) steps: usize,
}

/// Runs `scene` to its end. With the band, every step checks that the band correction met its
/// constraint and that the interface always had room for the deep's excess.
pub(crate) fn run<const D: usize>(scene: &Scene) -> (Run, Simulation<D>) {
    let mut blocked_steps = 0;
    let runner = common::run::<D>(scene, None, |sim, rep| {
        let at = format!("{} step {}", scene.name(), sim.state.steps);
        assert!(rep.volume_percent.is_finite(), "{at}");
        if let Some(r) = rep.method_report::<CcpReport<D>>() {
            if let Some(b) = &r.correction.band {
                assert!(b.failure.is_none(), "{at}: {:?}", b.failure);
            }
            if let Some(x) = r.deep {
                assert_eq!(x.unplaced, 0, "{at}");
            }
        }
        blocked_steps += rep.blocked.first().copied().unwrap_or(false) as usize;
    });
    let r = Run {
        volume_min: runner.summary.volume_min,
        bottom: runner.sim.state.solids.obstacles[0].bottom(),
        blocked_steps,
        steps: runner.summary.steps as usize,
    };
    (r, runner.sim)
}

fn scene(name: &str, method: MethodKind, obstacle: Option<ObstacleMode>) -> Scene {
    let o = Overrides {
        method: Some(method),
        obstacle,
        ..Default::default()
    };
    load(name, &o)
}

#[test]
fn ccp_compresses_exactly_to_mu_per_cell_and_the_baselines_do_not() {
    let (ccp, sim) = run::<2>(&scene("compress-2d", MethodKind::Ccp, None));
    assert!(
        ccp.volume_min >= 100.0 - 1e-9,
        "ccp volume fell to {}%",
        ccp.volume_min
    );
    // Maximum compression: the particles fill whole rows below the lid, mu per cell.
    let mu = sim.state.config.mu() as usize;
    let width = sim.state.grid.dims[0];
    let rows = sim.state.total_particles / (mu * width);
    assert_eq!(rows * mu * width, sim.state.total_particles);
    assert!(
        ccp.bottom > rows as f64 - 0.5 && ccp.bottom <= rows as f64 + 0.5,
        "the lid stopped at {} cells, full rows end at {rows}",
        ccp.bottom
    );
    for c in 0..sim.state.grid.num_cells() {
        if sim.state.grid.cell_coords(c)[1] < rows {
            assert_eq!(
                sim.state.markings.count[c] as usize,
                mu,
                "cell {:?}",
                sim.state.grid.cell_coords(c)
            );
        }
    }
    flip_loses_volume_or_halts("compress-2d", 50.0);
}

/// FLIP moving a lid regardless loses volume under it (below `ignore_keeps_below` percent);
/// FLIP waiting for free cells halts again and again, and still loses volume (it packs
/// particles more densely than mu).
fn flip_loses_volume_or_halts(name: &str, ignore_keeps_below: f64) {
    let (ignore, _) = run::<2>(&scene(name, MethodKind::Flip, Some(ObstacleMode::Ignore)));
    assert!(
        ignore.volume_min < ignore_keeps_below,
        "{name}: ignore kept {}%",
        ignore.volume_min
    );
    assert_eq!(ignore.blocked_steps, 0);
    let (naive, _) = run::<2>(&scene(name, MethodKind::Flip, Some(ObstacleMode::Naive)));
    assert!(
        naive.volume_min < 95.0,
        "{name}: naive kept {}%",
        naive.volume_min
    );
    assert!(
        naive.blocked_steps * 10 > naive.steps,
        "{name}: naive halted on {} steps",
        naive.blocked_steps
    );
}

#[test]
fn ccp_squeezes_the_water_through_the_spiral_until_every_cell_holds_mu() {
    let (ccp, sim) = run::<2>(&scene("spiral-2d", MethodKind::Ccp, None));
    assert!(
        ccp.volume_min >= 100.0 - 1e-9,
        "ccp volume fell to {}%",
        ccp.volume_min
    );
    // Maximum compression: every open cell below the lid, the whole channel included, holds
    // mu particles, except in the row right under the lid.
    let mu = sim.state.config.mu();
    let below: Vec<usize> = (0..sim.state.grid.num_cells())
        .filter(|&c| {
            !sim.state.solids.solid[c]
                && (sim.state.grid.cell_coords(c)[1] as f64 + 1.0) < ccp.bottom
        })
        .collect();
    let short: Vec<_> = below
        .iter()
        .filter(|&&c| sim.state.markings.count[c] < mu)
        .map(|&c| sim.state.grid.cell_coords(c))
        .collect();
    assert!(short.is_empty(), "cells below the lid not full: {short:?}");
    let width = sim.state.grid.dims[0];
    assert!(
        below.len() * mu as usize + width * mu as usize >= sim.state.total_particles,
        "the lid stopped at {} cells with room for {} more rows below it",
        ccp.bottom,
        (sim.state.total_particles - below.len() * mu as usize) / (width * mu as usize)
    );
    // The water could go only as fast as the channel let it: the lid had to stay on most
    // steps.
    assert!(
        ccp.blocked_steps * 2 > ccp.steps,
        "stayed {} of {}",
        ccp.blocked_steps,
        ccp.steps
    );
    flip_loses_volume_or_halts("spiral-2d", 60.0);
}

#[test]
fn obstacles_come_to_rest_on_static_solids_and_on_each_other_2d_and_3d() {
    fn check<const D: usize>() {
        let v = |x, y, z| point(D, x, y, z);
        // A box falls onto a shelf, a ball onto the box; water lies on the floor.
        let text = format!(
            "name = \"rest\"\ndim = {D}\n[domain]\nsize = {}\ncells = 20\n\
             [simulation]\nmethod = \"ccp\"\nduration = 0.8\nppc = {}\nmax_dt = 0.02\n\
             [[fluid]]\nshape = \"box\"\nmin = {}\nmax = {}\n\
             [[solid]]\nshape = \"box\"\nmin = {}\nmax = {}\n\
             [[obstacle]]\nname = \"box\"\nshape = \"box\"\nmin = {}\nmax = {}\n\
             velocity = {}\nmotion = \"falling\"\nterminal_speed = 0.5\n\
             [[obstacle]]\nname = \"ball\"\nshape = \"ball\"\ncenter = {}\nradius = 0.08\n\
             velocity = {}\nmotion = \"falling\"\nterminal_speed = 0.5\n",
            v(1.0, 1.0, 1.0),
            1 << D,
            v(0.0, 0.0, 0.0),
            v(1.0, 0.1, 1.0),
            v(0.1, 0.3, 0.0),
            v(0.9, 0.4, 1.0),
            v(0.35, 0.55, 0.3),
            v(0.65, 0.7, 0.7),
            v(0.0, 0.0, 0.0),
            v(0.5, 0.85, 0.5),
            v(0.0, 0.0, 0.0),
        );
        let scene = Scene::parse("rest scene", &text, &Overrides::default()).unwrap();
        let (sim, last) = run_apart::<D>(&scene);
        // Shelf top at 8 cells; the box is 3 cells tall.
        let (b, ball) = (
            sim.state.solids.obstacles[0].bottom(),
            sim.state.solids.obstacles[1].bottom(),
        );
        assert!((7.5..=8.5).contains(&b), "{D}D: the box rests at {b}");
        assert!(
            (b + 2.5..=b + 3.5).contains(&ball),
            "{D}D: the ball rests at {ball}, box at {b}"
        );
        // At rest: nothing moved over the last ten steps, and they say so.
        assert!(last.len() > 10);
        let end = last.len() - 1;
        assert!(
            last[end - 10..].iter().all(|x| x == &last[end]),
            "{D}D: still moving"
        );
        for o in &sim.state.solids.obstacles {
            assert_eq!(o.velocity.norm(), 0.0, "{D}D: {} at rest", o.name);
        }
    }
    check::<2>();
    check::<3>();
}

/// Runs `scene`, checking after every step that no obstacle covers a cell of a static solid
/// or of another obstacle, and that the solid cells, their velocities, the moving ones and
/// each line's hull of them, kept up as the obstacles move, are those of rasterising the box
/// with the obstacles where they are; returns the simulation and the obstacles' offsets after
/// each step.
pub(crate) fn run_apart<const D: usize>(scene: &Scene) -> (Simulation<D>, Vec<Vec<Vector<D>>>) {
    let mut offsets = vec![];
    let runner = common::run::<D>(scene, None, |sim, _| {
        let s = &sim.state;
        let (c, at) = (&s.config, format!("{D}D step {}", s.steps));
        let mut whole = Solids::new(&s.grid, &c.solids, &c.obstacles, c.obstacle_mode);
        let placed = |f: fn(&Obstacle<D>) -> Vector<D>| s.solids.obstacles.iter().map(f);
        let (at_now, speeds): (Vec<_>, Vec<_>) = (
            placed(|o| o.offset).collect(),
            placed(|o| o.velocity).collect(),
        );
        whole.place(&s.grid, &at_now, &speeds);
        assert!(whole.solid == s.solids.solid, "{at}: solid cells");
        assert!(
            whole.velocity == s.solids.velocity,
            "{at}: solid velocities"
        );
        assert!(whole.moving == s.solids.moving, "{at}: moving cells");
        assert!(whole.cells().lines == s.solids.cells().lines, "{at}: lines");
        let mut owner = vec![usize::MAX; s.grid.num_cells()];
        for (k, o) in s.solids.obstacles.iter().enumerate() {
            for c in o.cells_at(&s.grid, &o.offset) {
                assert!(!s.solids.fixed[c], "{at}: {} in a static solid", o.name);
                assert_eq!(owner[c], usize::MAX, "{at}: overlap");
                owner[c] = k;
            }
        }
        offsets.push(s.solids.obstacles.iter().map(|o| o.offset).collect());
    });
    (runner.sim, offsets)
}

/// A point or size in scene-file syntax: `[x, y]` in 2D, `[x, y, z]` in 3D.
pub(crate) fn point(dim: usize, x: f64, y: f64, z: f64) -> String {
    if dim == 2 {
        format!("[{x}, {y}]")
    } else {
        format!("[{x}, {y}, {z}]")
    }
}

/// A scene with water `depth` deep and one obstacle, in 2D or 3D, at `cells` per axis.
fn obstacle_scene(dim: usize, cells: usize, depth: f64, obstacle: &str, duration: f64) -> Scene {
    let v = |x, y, z| point(dim, x, y, z);
    let text = format!(
        "name = \"test\"\ndim = {dim}\n[domain]\nsize = {}\ncells = {cells}\n\
         [simulation]\nmethod = \"ccp\"\nduration = {duration}\nppc = {}\nmax_dt = 0.02\nmax_speed = 3.0\n\
         [[fluid]]\nshape = \"box\"\nmin = {}\nmax = {}\n\
         [[obstacle]]\nname = \"o\"\n{obstacle}\n",
        v(1.0, 1.0, 1.0),
        if dim == 2 { 4 } else { 8 },
        v(0.0, 0.0, 0.0),
        v(1.0, depth, 1.0),
    );
    Scene::parse("test scene", &text, &Overrides::default()).unwrap()
}

/// Runs `s` and checks that its first obstacle reached the floor (within one cell) without
/// the volume dropping below 100%.
fn reaches_the_floor(what: &str, dim: usize, s: &Scene) {
    let r = if dim == 2 {
        run::<2>(s).0
    } else {
        run::<3>(s).0
    };
    assert!(
        r.volume_min >= 100.0 - 1e-9,
        "{what} {dim}D: volume fell to {}%",
        r.volume_min
    );
    assert!(
        r.bottom <= 1.0,
        "{what} {dim}D: stopped {} cells above the floor",
        r.bottom
    );
}

#[test]
fn a_fast_ball_at_the_one_cell_limit_reaches_the_floor_2d_and_3d() {
    // 6 m/s at 24 cells per metre is 7 cells per max_dt step: the time step keeps the ball
    // within one cell per step.
    for dim in [2, 3] {
        let ball = if dim == 2 {
            "shape = \"ball\"\ncenter = [0.5, 0.85]\nradius = 0.1\nvelocity = [0.0, -6.0]"
        } else {
            "shape = \"ball\"\ncenter = [0.5, 0.85, 0.5]\nradius = 0.1\nvelocity = [0.0, -6.0, 0.0]"
        };
        let s = obstacle_scene(dim, if dim == 2 { 24 } else { 16 }, 0.5, ball, 0.6);
        reaches_the_floor("the fast ball", dim, &s);
    }
}

#[test]
fn a_large_obstacle_leaving_one_cell_gaps_reaches_the_floor_2d_and_3d() {
    for dim in [2, 3] {
        let cells = if dim == 2 { 30 } else { 14 };
        let gap = 1.0 / cells as f64;
        let lid = if dim == 2 {
            format!(
                "shape = \"box\"\nmin = [{gap}, 0.6]\nmax = [{}, 0.8]\nvelocity = [0.0, -1.0]",
                1.0 - gap
            )
        } else {
            format!(
                "shape = \"box\"\nmin = [{gap}, 0.6, {gap}]\nmax = [{}, 0.8, {}]\nvelocity = [0.0, -1.0, 0.0]",
                1.0 - gap,
                1.0 - gap
            )
        };
        let s = obstacle_scene(dim, cells, 0.2, &lid, 1.5);
        reaches_the_floor("the large obstacle", dim, &s);
    }
}

#[test]
fn a_lid_compresses_to_the_last_layer_in_3d() {
    let lid = "shape = \"box\"\nmin = [0.0, 0.7, 0.0]\nmax = [1.0, 0.9, 1.0]\nvelocity = [0.0, -1.0, 0.0]";
    let s = obstacle_scene(3, 12, 0.25, lid, 1.0);
    let (r, sim) = run::<3>(&s);
    assert!(
        r.volume_min >= 100.0 - 1e-9,
        "volume fell to {}%",
        r.volume_min
    );
    let layer = sim.state.grid.dims[0] * sim.state.grid.dims[2] * sim.state.config.mu() as usize;
    let rows = sim.state.total_particles.div_ceil(layer);
    assert!(
        (r.bottom - rows as f64).abs() <= 0.5,
        "the lid stopped at {} cells; the particles need {rows} layers",
        r.bottom
    );
}

#[test]
fn falling_obstacles_reach_the_floor_under_ccp_and_stall_or_trap_under_flip() {
    for name in [
        "falling-obstacle-2d",
        "falling-obstacle-zero-bc-2d",
        "large-obstacle-2d",
    ] {
        reaches_the_floor(name, 2, &scene(name, MethodKind::Ccp, None));
        let (naive, _) = run::<2>(&scene(name, MethodKind::Flip, Some(ObstacleMode::Naive)));
        assert!(
            naive.bottom > 2.0,
            "{name}: FLIP-naive reached {} cells",
            naive.bottom
        );
        let (ignore, _) = run::<2>(&scene(name, MethodKind::Flip, Some(ObstacleMode::Ignore)));
        assert!(
            ignore.bottom <= 1.0,
            "{name}: FLIP-ignore stopped at {}",
            ignore.bottom
        );
        assert!(
            ignore.volume_min < 97.0,
            "{name}: FLIP-ignore kept {}%",
            ignore.volume_min
        );
    }
}

#[test]
fn falling_obstacles_reach_the_floor_in_3d_with_the_band() {
    for name in ["falling-obstacle-3d", "large-obstacle-3d"] {
        let o = Overrides {
            cells: Some(if name == "large-obstacle-3d" { 36 } else { 16 }),
            ..Default::default()
        };
        let s = load(name, &o);
        assert!(s.method.band().is_some());
        reaches_the_floor(name, 3, &s);
    }
}

/// Runs `scene` for `steps` steps and checks after each that the correction's objective and
/// penalty split eq. problem3's objective as documented: both >= 0, a penalty only when the
/// obstacle had to stay (a particle ended in a cell it wanted), and whatever `check` checks.
/// Returns the steps with a penalty.
fn split_objective<const D: usize>(
    scene: &Scene,
    cross_check: bool,
    steps: u64,
    mut check: impl FnMut(&CcpReport<D>, &str),
) -> usize {
    let sim = common::simulation::<D>(scene, cross_check);
    let mut penalised = 0;
    common::run_sim::<D>(sim, Limit::Steps(steps), |sim, rep| {
        let at = format!("{} step {}", scene.name(), sim.state.steps);
        let r = common::ccp(rep);
        let c = &r.correction;
        assert!(c.objective >= 0.0 && c.penalty >= 0.0, "{at}: {c:?}");
        if c.penalty > 0.0 {
            penalised += 1;
            assert!(rep.blocked[0], "{at}: penalty {} but it moved", c.penalty);
        }
        check(r, &at);
    });
    penalised
}

#[test]
fn objective_and_penalty_add_up_to_the_solvers_optimum() {
    // The spiral's lid presses particles into the cells it wants: the simplex's optimum of the
    // same problem (the cross-check) is the flow solver's objective + penalty.
    let o = Overrides {
        cells: Some(48),
        ..Default::default()
    };
    let spiral = load("spiral-2d", &o);
    let penalised = split_objective::<2>(&spiral, true, 32, |r, at| {
        let d = r.correction.cross_check.clone().unwrap();
        let d = d.unwrap_or_else(|e| panic!("{at}: {e}"));
        assert!(
            d <= 1e-9,
            "{at}: objective + penalty is {d:e} off the simplex's"
        );
    });
    assert!(penalised > 0, "no step had a penalty");
}

#[test]
fn objective_and_penalty_split_the_band_correction_alike() {
    // With the band: the displacement of the particles outside the cells the box wants, so the
    // band's objective (every particle's displacement) exactly when no particle is in them.
    let o = Overrides {
        flags: MethodFlags::default().with("band", BandMode::Paths),
        ..Default::default()
    };
    let large = load("large-obstacle-2d", &o);
    let penalised = split_objective::<2>(&large, false, 45, |r, at| {
        let (c, b) = (&r.correction, r.correction.band.as_ref().unwrap());
        if c.penalty == 0.0 {
            assert_eq!(c.objective, b.objective, "{at}");
        } else {
            assert!(
                c.objective <= b.objective,
                "{at}: {} > {}",
                c.objective,
                b.objective
            );
        }
    });
    assert!(penalised > 0, "no step had a penalty");
}
