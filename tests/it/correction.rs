//! The correction step (paper sec. 4-5): the exact flow solver against the simplex on random
//! instances and real steps, the guarantees of eq. problem3 in 2D and 3D, and the paper's
//! volume claims.

use crate::common::{ccp, load, run_sim, simulation};
use cellflip::grid::{Grid, Vector};
use cellflip::methods::ccp::correct::problem;
use cellflip::methods::ccp::{BandMode, Directions};
use cellflip::methods::MethodFlags;
use cellflip::methods::MethodKind;
use cellflip::runner::{ExportFailed, Exports, Limit, Runner};
use cellflip::scene::Overrides;
use cellflip::solvers::{lp, min_cost_flow, mps};
use cellflip::stages::markings::Markings;
use cellflip::step::Simulation;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A random feasible instance: particles in random non-solid cells (at most `mu` per cell,
/// many cells full so that inner cells with lower bounds appear), advected up to one cell per
/// axis. With `lattice`, positions snap to quarter cells so that costs tie.
fn random_instance<const D: usize>(
    rng: &mut StdRng,
    lattice: bool,
) -> (Grid<D>, Vec<Vector<D>>, Vec<Vector<D>>, Vec<bool>, u32) {
    let dims: [usize; D] = std::array::from_fn(|_| rng.random_range(3..if D == 2 { 8 } else { 5 }));
    let g = Grid::new(dims);
    let mu = rng.random_range(1..=8u32);
    let solid: Vec<bool> = (0..g.num_cells())
        .map(|_| rng.random::<f64>() < 0.1)
        .collect();
    let snap = |v: f64| if lattice { (v * 4.0).round() / 4.0 } else { v };
    let mut x_bar = vec![];
    for (c, _) in solid.iter().enumerate().filter(|(_, s)| !**s) {
        let n = match rng.random::<f64>() {
            r if r < 0.45 => mu,
            r if r < 0.75 => rng.random_range(0..=mu),
            _ => 0,
        };
        let cell = g.cell_coords(c);
        for _ in 0..n {
            x_bar.push(Vector::<D>::from_fn(|k, _| {
                cell[k] as f64 + rng.random_range(0.01..0.99)
            }));
        }
    }
    let x_hat = x_bar
        .iter()
        .map(|x| {
            Vector::<D>::from_fn(|k, _| {
                let v = snap(x[k] + rng.random_range(-0.99..0.99));
                v.clamp(0.001, dims[k] as f64 - 0.001)
            })
        })
        .collect();
    (g, x_bar, x_hat, solid, mu)
}

fn agree_on_random_instances<const D: usize>(count: usize, seed: u64) {
    let mut rng = StdRng::seed_from_u64(seed);
    let (mut constrained, mut halved_instances) = (0, 0);
    for n in 0..count {
        let (g, x_bar, x_hat, solid, mu) = random_instance::<D>(&mut rng, n % 2 == 0);
        let prev = Markings::compute(&g, &x_bar, &solid);
        let dirs = if n % 5 == 4 {
            Directions::Moore
        } else {
            Directions::VonNeumann
        };
        let p = problem::build(&g, &x_bar, &x_hat, &prev, &solid, mu, dirs, None, None).unwrap();
        let a = &p.assignment;
        let (flow, stats) = min_cost_flow::solve(a).unwrap_or_else(|e| panic!("instance {n}: {e}"));
        let simplex = lp::solve(a).unwrap_or_else(|e| panic!("instance {n}: {e}"));
        a.check(&flow)
            .unwrap_or_else(|e| panic!("instance {n}, flow: {e}"));
        a.check(&simplex)
            .unwrap_or_else(|e| panic!("instance {n}, simplex: {e}"));
        let (of, os) = (a.objective(&flow), a.objective(&simplex));
        assert!(
            (of - os).abs() <= 1e-9 * os.abs().max(1.0),
            "instance {n} ({D}D, mu {mu}): flow {of} vs simplex {os}"
        );
        // A warm start from any prices (here random, of either sign and up to a few cells^2,
        // so that bins start above and below the sink's price) finds the same optimum.
        let prices: Vec<f64> = (0..a.bins()).map(|_| rng.random_range(-3.0..3.0)).collect();
        let warm = min_cost_flow::solve_warm(a, &prices)
            .unwrap_or_else(|e| panic!("instance {n}, warm: {e}"));
        a.check(&warm.choice)
            .unwrap_or_else(|e| panic!("instance {n}, warm: {e}"));
        let ow = a.objective(&warm.choice);
        assert!(
            (ow - os).abs() <= 1e-9 * os.abs().max(1.0),
            "instance {n} ({D}D, mu {mu}): warm flow {ow} vs simplex {os}"
        );
        // Halved (one or two levels, at any size), the same optimum again.
        let halving = min_cost_flow::Halving {
            levels: 1 + n as u32 % 2,
            min_items: 0,
        };
        let halved = min_cost_flow::solve_halved(a, &prices, halving)
            .unwrap_or_else(|e| panic!("instance {n}, halved: {e}"));
        a.check(&halved.choice)
            .unwrap_or_else(|e| panic!("instance {n}, halved: {e}"));
        let oh = a.objective(&halved.choice);
        assert!(
            (oh - os).abs() <= 1e-9 * os.abs().max(1.0),
            "instance {n} ({D}D, mu {mu}): halved {oh} vs simplex {os}"
        );
        constrained += (stats.augmentations > 0) as usize;
        halved_instances += (halved.stats.halvings > 0) as usize;
    }
    // Most instances must actually exercise the repair and the halving, or the test proves
    // little.
    assert!(
        constrained > count / 2,
        "only {constrained} of {count} instances had conflicts"
    );
    assert!(
        halved_instances > count / 2,
        "only {halved_instances} of {count} instances were halved"
    );
}

/// The collapsing column, where the flow solver is slowest: a column `mu` particles per cell
/// everywhere (its inner cells must keep them), advected down by most of a cell so that its
/// bottom cells overflow. The excess can only leave through the sides at the floor or rise
/// through the full column to its top, one chain of moves per unit.
fn collapsing_column<const D: usize>(width: usize, height: usize, mu: u32) {
    let dims: [usize; D] = std::array::from_fn(|k| if k == D - 1 { height + 2 } else { width + 2 });
    let g = Grid::new(dims);
    let solid = vec![false; g.num_cells()];
    let mut rng = StdRng::seed_from_u64(21);
    let mut x_bar = vec![];
    for c in 0..g.num_cells() {
        let cell = g.cell_coords(c);
        if (0..D).all(|k| cell[k] < if k == D - 1 { height } else { width }) {
            for _ in 0..mu {
                let x = Vector::<D>::from_fn(|k, _| cell[k] as f64 + rng.random_range(0.05..0.95));
                x_bar.push(x);
            }
        }
    }
    let x_hat: Vec<_> = x_bar
        .iter()
        .map(|x| {
            let mut y = *x;
            y[D - 1] = (y[D - 1] - rng.random_range(0.3..0.9)).max(0.01);
            y
        })
        .collect();
    let prev = Markings::compute(&g, &x_bar, &solid);
    let dirs = Directions::VonNeumann;
    let p = problem::build(&g, &x_bar, &x_hat, &prev, &solid, mu, dirs, None, None).unwrap();
    let a = &p.assignment;
    let (flow, stats) = min_cost_flow::solve(a).unwrap();
    let simplex = lp::solve(a).unwrap();
    a.check(&flow).unwrap();
    let (of, os) = (a.objective(&flow), a.objective(&simplex));
    assert!(
        (of - os).abs() <= 1e-9 * os.abs().max(1.0),
        "{D}D column: flow {of} vs simplex {os}"
    );
    // Many units, travelling far: more nodes settled than units times the column's height.
    let units = stats.augmentations;
    assert!(units >= width.pow(D as u32 - 1), "{stats:?}");
    assert!(stats.nodes_settled > units * height, "{stats:?}");
    // From the optimum's own prices a warm start finds the optimum again with a fraction of
    // the work: its start is the optimum but for ties.
    let cold = min_cost_flow::solve_priced(a).unwrap();
    let prices: Vec<f64> = cold.prices.iter().map(|p| p - cold.sink_price).collect();
    let warm = min_cost_flow::solve_warm(a, &prices).unwrap();
    a.check(&warm.choice).unwrap();
    let ow = a.objective(&warm.choice);
    assert!(
        (ow - os).abs() <= 1e-9 * os.abs().max(1.0),
        "{D}D column: warm {ow} vs {os}"
    );
    assert!(
        warm.stats.nodes_settled * 4 < stats.nodes_settled,
        "{D}D column: warm {:?} vs cold {stats:?}",
        warm.stats
    );
    // Halved across the column's floor, where the excess starts, the optimum again.
    let halving = min_cost_flow::Halving {
        levels: 1,
        min_items: 0,
    };
    let halved = min_cost_flow::solve_halved(a, &vec![0.0; a.bins()], halving).unwrap();
    a.check(&halved.choice).unwrap();
    let oh = a.objective(&halved.choice);
    assert!(
        (oh - os).abs() <= 1e-9 * os.abs().max(1.0),
        "{D}D column: halved {oh} vs {os}"
    );
    assert_eq!(halved.stats.halvings, 1, "{D}D column: {:?}", halved.stats);
}

#[test]
fn flow_is_exact_on_a_collapsing_column_2d_and_3d() {
    collapsing_column::<2>(6, 14, 4);
    collapsing_column::<3>(4, 8, 3);
}

#[test]
fn flow_and_simplex_agree_on_600_random_2d_instances() {
    agree_on_random_instances::<2>(600, 11);
}

#[test]
fn flow_and_simplex_agree_on_500_random_3d_instances() {
    agree_on_random_instances::<3>(500, 12);
}

/// Reads back the free-format MPS that `mps::write` writes (N, E, L and G rows, RANGES, UP
/// bounds) with the standard's meaning of each row type and range, and returns the optimum of
/// its LP relaxation by microlp: what any LP solver finds for an exported file.
fn solve_mps(text: &str) -> f64 {
    use microlp::{ComparisonOp, OptimizationDirection, Problem};
    use std::collections::HashMap;
    let mut section = "";
    let mut rows: Vec<(&str, &str)> = vec![];
    let mut columns: Vec<(&str, Vec<(&str, f64)>)> = vec![];
    let (mut rhs, mut range, mut up) = (HashMap::new(), HashMap::new(), HashMap::new());
    for line in text.lines().filter(|l| !l.starts_with('*')) {
        let f: Vec<&str> = line.split_whitespace().collect();
        let num = |s: &str| s.parse::<f64>().unwrap_or_else(|e| panic!("{line}: {e}"));
        if !line.starts_with(' ') {
            section = f[0];
            continue;
        }
        match section {
            "ROWS" => rows.push((f[1], f[0])),
            "COLUMNS" => {
                if columns.last().is_none_or(|(c, _)| *c != f[0]) {
                    columns.push((f[0], vec![]));
                }
                let entries = &mut columns.last_mut().unwrap().1;
                entries.extend(f[1..].chunks(2).map(|e| (e[0], num(e[1]))));
            }
            "RHS" => {
                rhs.insert(f[1], num(f[2]));
            }
            "RANGES" => {
                range.insert(f[1], num(f[2]));
            }
            "BOUNDS" if f[0] == "UP" => {
                up.insert(f[2], num(f[3]));
            }
            _ => panic!("unexpected line in {section}: {line}"),
        }
    }
    let mut lp = Problem::new(OptimizationDirection::Minimize);
    let mut terms: HashMap<&str, Vec<_>> = HashMap::new();
    for (name, entries) in &columns {
        let kind = |row: &str| rows.iter().find(|r| r.0 == row).unwrap().1;
        let cost = entries
            .iter()
            .find(|e| kind(e.0) == "N")
            .map_or(0.0, |e| e.1);
        let v = lp.add_var(cost, (0.0, up.get(name).copied().unwrap_or(f64::INFINITY)));
        for &(row, a) in entries.iter().filter(|e| kind(e.0) != "N") {
            terms.entry(row).or_default().push((v, a));
        }
    }
    for &(row, kind) in rows.iter().filter(|r| r.1 != "N") {
        let (r, span) = (
            rhs.get(row).copied().unwrap_or(0.0),
            range.get(row).copied(),
        );
        let (lo, hi) = match (kind, span) {
            ("E", None) => (r, r),
            ("E", Some(s)) => (r.min(r + s), r.max(r + s)),
            ("L", s) => (r - s.map_or(f64::INFINITY, f64::abs), r),
            ("G", s) => (r, r + s.map_or(f64::INFINITY, f64::abs)),
            _ => panic!("row type {kind}"),
        };
        let t = terms[row].as_slice();
        if lo == hi {
            lp.add_constraint(t, ComparisonOp::Eq, lo);
            continue;
        }
        if lo.is_finite() {
            lp.add_constraint(t, ComparisonOp::Ge, lo);
        }
        if hi.is_finite() {
            lp.add_constraint(t, ComparisonOp::Le, hi);
        }
    }
    let outcome = lp.solve().unwrap();
    assert!(outcome.is_optimal(), "{outcome:?}");
    outcome.solution().unwrap().objective()
}

/// Exported problems mean what the solvers solve: read back from MPS (inner cells that must
/// keep a full count as `E` rows, others as `L` rows with ranges), they have the flow
/// solver's optimum.
fn exported_problems_read_back<const D: usize>(count: usize, seed: u64) -> usize {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut equal_rows = 0;
    for n in 0..count {
        let (g, x_bar, x_hat, solid, mu) = random_instance::<D>(&mut rng, n % 2 == 0);
        let prev = Markings::compute(&g, &x_bar, &solid);
        let dirs = Directions::VonNeumann;
        let p = problem::build(&g, &x_bar, &x_hat, &prev, &solid, mu, dirs, None, None).unwrap();
        let a = &p.assignment;
        let (flow, _) = min_cost_flow::solve(a).unwrap_or_else(|e| panic!("instance {n}: {e}"));
        let mps = mps::write(a, "t", &[]);
        equal_rows += mps.lines().filter(|l| l.starts_with(" E bin")).count();
        let (of, om) = (a.objective(&flow), solve_mps(&mps));
        assert!(
            (of - om).abs() <= 1e-9 * of.abs().max(1.0),
            "instance {n} ({D}D, mu {mu}): flow {of} vs the exported problem {om}"
        );
    }
    equal_rows
}

#[test]
fn exported_problems_have_the_solvers_optimum_2d_and_3d() {
    let equal_rows =
        exported_problems_read_back::<2>(60, 13) + exported_problems_read_back::<3>(30, 14);
    assert!(equal_rows > 0, "no instance had a cell with equal bounds");
}

#[test]
fn flow_work_grows_with_conflicts_not_particles() {
    // 90,000 particles at rest, one per cell (mu = 1), one of them advected into a full
    // neighbour: the repair settles a handful of cells, not the grid.
    let g = Grid::new([300, 300]);
    let x_bar: Vec<Vector<2>> = (0..g.num_cells())
        .map(|c| g.center(g.cell_coords(c)))
        .collect();
    let mut x_hat = x_bar.clone();
    let j = g.cell_index([150, 150]);
    x_hat[j][0] += 0.8;
    let solid = vec![false; g.num_cells()];
    let prev = Markings::compute(&g, &x_bar, &solid);
    let p = problem::build(
        &g,
        &x_bar,
        &x_hat,
        &prev,
        &solid,
        1,
        Directions::VonNeumann,
        None,
        None,
    )
    .unwrap();
    let (choice, stats) = min_cost_flow::solve(&p.assignment).unwrap();
    p.assignment.check(&choice).unwrap();
    assert_eq!(stats.overfull_bins, 1);
    assert!(stats.nodes_settled < 50, "{stats:?}");
    // The particle is blocked: it stays in its cell, at the wall nearest to where it wanted to go.
    assert_eq!(
        g.cell_index_of(&p.position(&g, choice[j] as usize, &x_hat[j])),
        j
    );
}

/// Runs a scene with method ccp; every step checks eq. problem3's guarantees (inside `step`),
/// that no solver failed, and with `cross_check` that flow and simplex found the same optimum.
fn run_ccp<const D: usize>(
    name: &str,
    overrides: Overrides,
    steps: u64,
    cross_check: bool,
) -> Vec<f64> {
    let overrides = Overrides {
        method: Some(MethodKind::Ccp),
        ..overrides
    };
    let sim = simulation::<D>(&load(name, &overrides), cross_check);
    let mut volumes = vec![];
    run_sim::<D>(sim, Limit::Steps(steps), |sim, rep| {
        let at = format!("{name} step {}", sim.state.steps);
        let c = &ccp(rep).correction;
        assert!(c.fallback.is_none(), "{at}: {:?}", c.fallback);
        if cross_check {
            let d = c
                .cross_check
                .clone()
                .unwrap()
                .unwrap_or_else(|e| panic!("{at}: {e}"));
            assert!(d <= 1e-9, "{at}: objectives differ by {d:e}");
        }
        volumes.push(rep.volume_percent);
    });
    volumes
}

#[test]
fn flow_and_simplex_agree_on_real_dam_and_drop_steps() {
    run_ccp::<2>("dam-2d", Overrides::default(), 25, true);
    run_ccp::<2>("drop-2d", Overrides::default(), 25, true);
}

#[test]
fn volume_never_drops_below_100_percent_2d() {
    for name in ["dam-2d", "drop-2d"] {
        let v = run_ccp::<2>(name, Overrides::default(), 300, false);
        let min = v.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(min >= 100.0 - 1e-9, "{name}: volume fell to {min}%");
    }
}

#[test]
fn one_particle_per_cell_keeps_exactly_100_percent() {
    let v = run_ccp::<2>("dam-1ppc-2d", Overrides::default(), 300, false);
    for (step, x) in v.iter().enumerate() {
        assert!((x - 100.0).abs() < 1e-9, "step {}: {x}%", step + 1);
    }
}

#[test]
fn volume_never_drops_below_100_percent_3d() {
    let small = Overrides {
        cells: Some(24),
        ..Default::default()
    };
    let v = run_ccp::<3>("dam-3d", small.clone(), 60, false);
    let min = v.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(min >= 100.0 - 1e-9, "dam-3d: volume fell to {min}%");
    // Without the band: the solver cross-check compares flow and simplex on eq. problem3.
    run_ccp::<3>(
        "drop-3d",
        Overrides {
            cells: Some(12),
            flags: MethodFlags::default().with("band", BandMode::None),
            ..small
        },
        10,
        true,
    );
}

/// A file a step hands over and its observer cannot write: the run fails, naming the step and
/// the file (`ExportFailed`), instead of going on without it.
#[test]
fn an_export_that_cannot_be_written_fails_its_step_naming_the_file() {
    let o = Overrides {
        method: Some(MethodKind::Ccp),
        cells: Some(24),
        flags: MethodFlags::default().with("export-lp", 2u64),
        ..Default::default()
    };
    let scene = load("dam-2d", &o);
    let mut method = scene.method.clone();
    let files = method.files(std::path::Path::new("/nonexistent-cellflip-dir/dam"));
    let path = std::path::PathBuf::from("/nonexistent-cellflip-dir/dam-step2.mps");
    assert_eq!(files.len(), 1);
    assert_eq!(
        (files[0].flag, files[0].step, &files[0].path),
        ("export-lp", 2, &path)
    );
    let sim = Simulation::<2>::new(scene.config::<2>(), &method);
    let mut exports = Exports::default();
    let e = Runner::new(sim)
        .run(
            Limit::Steps(3),
            || false,
            |sim, rep| exports.write(sim, rep).map_err(anyhow::Error::from),
        )
        .unwrap_err();
    let e = e.downcast::<ExportFailed>().expect("the export failed");
    assert_eq!((e.step, &e.path), (2, &path), "{e:?}");
    assert!(exports.written.is_empty());
}
