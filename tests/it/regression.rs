//! Tests named after the bug they pin: each failed before the commit named in its comment
//! fixed it. They came from the topic modules named above each group, where the rest of their
//! history is (`git log --follow`).

use crate::common::{self, cellflip, load, run_sim, scratch_dir, simulation};
use crate::scene_refusals::{rejects, GOOD};
use crate::solids::{point, run, run_apart};
use cellflip::grid::{Grid, Vector};
use cellflip::methods::ccp::correct::{self, CorrectionSettings};
use cellflip::methods::MethodKind;
use cellflip::runner::Limit;
use cellflip::scene::{ErrorKind, Overrides, Scene};
use cellflip::stages::markings::Markings;
use std::path::Path;
use std::process::Command;

// The command line as a process (cli_process).

/// A recording that reads back whole: every message decodes, the stream ends with its footer
/// (what `rerun rrd verify` checks), and it holds particles and the log.
fn assert_valid_recording(path: &Path, what: &str) {
    let got = common::logged_entities(path);
    assert!(
        got.contains("world/particles") && got.contains("log"),
        "{what}: {got:?}"
    );
    let bytes = std::fs::read(path).unwrap();
    let tail = &bytes[bytes.len().saturating_sub(256)..];
    assert!(
        tail.windows(8).any(|w| w == b"RRF2FOOT"),
        "{what}: the recording has no footer"
    );
}

/// Starts a long dam run recording to `out`; returns once it has recorded some steps.
fn start_long_run(out: &Path) -> std::process::Child {
    let child = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(["run", "dam-2d", "--duration", "1000", "-q", "--out"])
        .arg(out)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while std::fs::metadata(out).map(|m| m.len()).unwrap_or(0) < 50_000 {
        assert!(t0.elapsed().as_secs() < 60, "the run wrote nothing");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    child
}

/// Fixed in 7a25295: Ctrl-C (SIGINT) exited 0, and SIGTERM or SIGHUP left a broken
/// recording. Each signal now finishes the recording and exits with 128 + its number.
#[test]
fn sigint_exited_0_and_sigterm_or_sighup_broke_the_recording() {
    let dir = scratch_dir("signals");
    for (signal, status) in [("INT", 130), ("TERM", 143), ("HUP", 129)] {
        let out = dir.join(format!("dam-{signal}.rrd"));
        let child = start_long_run(&out);
        let kill = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(status), "SIG{signal}: {err}");
        assert!(!err.contains("panicked"), "SIG{signal}: {err}");
        assert_valid_recording(&out, &format!("SIG{signal}"));
    }
}

/// Fixed in 7a25295: on a full disk or past a file size limit the run went on, ended with
/// 'File-writer thread shut down prematurely' and left an invalid file. It now stops at that
/// step naming the file and the OS error, and what was written stays readable.
#[test]
fn a_full_device_let_the_run_go_on_and_left_an_invalid_recording() {
    // At creation: nothing can be written.
    let o = cellflip(&["run", "dam-2d", "--steps", "3", "-q", "--out", "/dev/full"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !err.contains("panicked"), "{err}");
    assert!(
        err.contains("'/dev/full'") && err.contains("No space left on device"),
        "{err}"
    );
    // Mid-run: a file size limit (RLIMIT_FSIZE; the program ignores SIGXFSZ, which would kill
    // it) fails a later write with EFBIG; the run stops at once, and what was written stays
    // readable.
    let dir = scratch_dir("fsize");
    let out = dir.join("dam.rrd");
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -f 400; exec '{}' run dam-2d --duration 1000 -q --out '{}'",
            env!("CARGO_BIN_EXE_cellflip"),
            out.display()
        ))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&format!("'{}'", out.display())), "{err}");
    assert!(err.contains("File too large"), "{err}");
    assert!(!common::logged_entities(&out).is_empty());
}

/// Fixed in 7a25295: printing to a closed pipe or a full device panicked.
#[test]
fn a_closed_or_full_standard_output_panicked() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .arg("list")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && err.is_empty(), "closed pipe: {err}");
    let o = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(["run", "dam-2d", "--steps", "2", "--no-record"])
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && !err.contains("panicked"),
        "full: {err}"
    );
    assert!(
        err.contains("cannot write to standard output"),
        "full: {err}"
    );
}

// What the command line refuses (scene_refusals).

/// Fixed in 623ab48: `--export-lp` for a step the run never reached wrote nothing and said
/// nothing. It is now refused up front, and a run limited by time fails at its end, its
/// recording complete.
#[test]
fn export_lp_for_a_step_never_reached_silently_wrote_nothing() {
    let dir = scratch_dir("export-late");
    let out = dir.join("x.rrd");
    let run = |extra: &[&str]| {
        let args = [
            "run",
            "dam-2d",
            "--res",
            "24",
            "--out",
            out.to_str().unwrap(),
        ];
        let o = cellflip(&[&args[..], extra].concat());
        assert!(!o.status.success(), "{extra:?} accepted");
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    // Up front, before anything is written.
    let err = run(&["--steps", "3", "--export-lp", "5"]);
    assert!(
        err.contains("--export-lp 5") && err.contains("only 3 steps"),
        "{err}"
    );
    let err = run(&["--steps", "3", "--export-lp", "0"]);
    assert!(
        err.contains("--export-lp 0") && err.contains("from 1"),
        "{err}"
    );
    assert!(!out.exists(), "wrote a recording");
    // A run limited by time fails at its end, its recording complete.
    let err = run(&["--duration", "0.02", "--export-lp", "1000", "-q"]);
    assert!(err.contains("step 1000 was never reached"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(common::logged_entities(&out).contains("world/particles"));
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(files.len(), 1, "{files:?}");
}

/// Values that used to panic, abort, hang, write outside `recordings/` or never end are
/// refused up front, naming the key.
///
/// Fixed in 27799c5 (the test came with 7a25295).
#[test]
fn hostile_scene_values_panicked_aborted_hung_or_wrote_outside_recordings() {
    use ErrorKind::{Geometry, Range};
    let good = |from: &str, to: &str| {
        assert!(GOOD.contains(from), "{from}");
        GOOD.replacen(from, to, 1)
    };
    let cases = [
        (
            "name-path",
            good("name = \"tiny\"", "name = \"../x\""),
            "name",
            Range,
        ),
        (
            "name-control",
            good("name = \"tiny\"", "name = \"a\\u0007b\""),
            "name",
            Range,
        ),
        (
            "cells-2-32",
            good("cells = 8", "cells = 4294967296"),
            "domain.cells",
            Range,
        ),
        (
            "cells-max",
            good("cells = 8", "cells = 9223372036854775807"),
            "domain.cells",
            Range,
        ),
        (
            "ppc-wrap",
            good("duration = 0.05", "ppc = 8589934593"),
            "simulation.ppc",
            Range,
        ),
        (
            "max-dt",
            good("duration = 0.05", "max_dt = 1e-300"),
            "simulation.max_dt",
            Range,
        ),
        (
            "cfl",
            good("duration = 0.05", "cfl = 1e-300"),
            "simulation.cfl",
            Range,
        ),
        (
            "gravity",
            good("duration = 0.05", "gravity = [0.0, -1e300]"),
            "simulation.gravity",
            Range,
        ),
        (
            "tolerance",
            good("duration = 0.05", "pressure_tolerance = 1e-200"),
            "simulation.pressure_tolerance",
            Range,
        ),
        (
            "thin-fluid",
            good("max = [0.5, 0.5]", "max = [0.01, 0.5]"),
            "fluid[0]",
            Geometry,
        ),
    ];
    for (test, text, key, kind) in &cases {
        rejects(test, text, key, *kind);
    }
    let emitter = format!(
        "{GOOD}[[emitter]]\nmin = [0.5, 0.6]\nmax = [0.7, 0.8]\nvelocity = [0.0, -1e300]\n"
    );
    rejects("emitter-speed", &emitter, "emitter[0].velocity", Range);
    let o = cellflip(&[
        "run",
        "dam-2d",
        "--seed",
        "9223372036854775808",
        "--steps",
        "1",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !err.contains("panicked"), "{err}");
    assert!(err.contains("simulation.seed"), "{err}");
    // flip, whose footprint is dense: ccp's band counts the active cells since issue 57, and
    // its estimate at 580^3 fits in this machine's memory.
    let o = cellflip(&[
        "run",
        "dam-3d",
        "--res",
        "580",
        "--method",
        "flip",
        "--steps",
        "1",
        "--no-record",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("domain.cells") && err.contains("available"),
        "{err}"
    );
    let o = cellflip(&["bench", "--scene", "dam-2d", "--steps", "0"]);
    assert!(!o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("panicked"));
}

/// Fixed in the stop of issue 58: `bench` took every method flag, `--export-lp` among them, and
/// wrote nothing (it has no recording to put the file beside).
#[test]
fn bench_took_export_lp_and_wrote_nothing() {
    let args = [
        "bench",
        "--scene",
        "dam-2d",
        "--res",
        "24",
        "--steps",
        "1",
        "--export-lp",
        "1",
    ];
    let o = cellflip(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("--export-lp") && err.contains("cellflip run"),
        "{err}"
    );
}

// The correction step (correction).

/// Fixed in 1a53a1a: when the flow solver failed, the exported problem still began
/// 'optimal objective', offering the previous cells' cost as an optimum to check solvers
/// against.
#[test]
fn a_failed_solve_was_exported_as_an_optimal_objective() {
    // The markings of a closed 3x3 box full at mu = 1 (every cell inner: it keeps its
    // particle) with one particle gone: no assignment meets the bounds, the flow solver fails
    // and every particle keeps its cell.
    let g = Grid::new([3, 3]);
    let full: Vec<Vector<2>> = (0..9).map(|c| g.center(g.cell_coords(c))).collect();
    let solid = vec![false; 9];
    let prev = Markings::compute(&g, &full, &solid);
    let x_bar = full[1..].to_vec();
    let mut pos = x_bar.clone();
    let settings = CorrectionSettings::default();
    let mut memory = correct::PriceMemory::default();
    let rep = correct::correct(
        &g,
        &x_bar,
        &mut pos,
        &prev,
        &solid,
        1,
        &settings,
        None,
        None,
        true,
        &mut memory,
    )
    .unwrap();
    let why = rep.fallback.expect("the solver failed");
    assert!(
        matches!(
            why,
            correct::Fallback {
                solver: "flow",
                why: correct::SolveError::Flow(_)
            }
        ),
        "{why:?}"
    );
    assert!(why.to_string().starts_with("flow solver failed"), "{why}");
    let mps = rep.mps.unwrap();
    let first = format!("* fallback objective {:.17e} ({why})\n", 0.0);
    assert!(mps.starts_with(&first), "{mps}");
    assert!(!mps.contains("optimal"), "{mps}");
    assert_eq!(pos, x_bar);
}

/// The dam's front (the largest particle x, cells) after `seconds` of `method` at `cfl`.
fn dam_front(method: MethodKind, cfl: f64, seconds: f64) -> f64 {
    let mut scene = load("dam-2d", &common::with(method, None));
    scene.file.simulation.cfl = cfl;
    let runner = run_sim(
        simulation::<2>(&scene, false),
        Limit::SimSeconds(seconds),
        |_, _| {},
    );
    let pos = &runner.sim.state.particles.pos;
    pos.iter().map(|x| x[0]).fold(f64::MIN, f64::max)
}

/// Eq. best_cell_pos moves only the components where the target lies outside the cell, so a
/// particle that moves less than the margin per step still reaches and crosses its cell's
/// faces. Clamping every component to the margin pinned small steps: at cfl 0.01 the front
/// stayed in its starting cell. Now, at 0.15 s (before the front reaches the far wall), the
/// ccp dam's front is flip's at every step size, and its spread over cfl 0.05..1 is a few
/// percent. (Below that flip's own front slows: its PIC share damps once per step.)
///
/// Fixed in 667943b.
#[test]
fn best_cell_pos_clamped_every_component_and_pinned_the_dam_front_at_small_steps() {
    let (seconds, start) = (0.15, 0.3 * 50.0);
    let front = |cfl: f64| {
        let (ccp, flip) = (
            dam_front(MethodKind::Ccp, cfl, seconds),
            dam_front(MethodKind::Flip, cfl, seconds),
        );
        assert!(
            flip > start + 5.0,
            "cfl {cfl}: flip's front {flip} barely moved"
        );
        let rel = (ccp - flip).abs() / (flip - start);
        assert!(rel < 0.03, "cfl {cfl}: ccp's front {ccp}, flip's {flip}");
        ccp
    };
    front(0.01);
    let fronts = [0.05, 0.2, 1.0].map(front);
    let (lo, hi) = fronts
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &f| (a.min(f), b.max(f)));
    assert!(
        (hi - lo) / hi < 0.05,
        "fronts at cfl 0.05, 0.2, 1: {fronts:?}"
    );
}

// Built-in scenes (scenes).

/// Fixed in 1871271: max_abs let a NaN through when a later value was larger (f64::max drops
/// NaN), and advection panicked. The step now fails with an error saying what is not finite.
#[test]
fn a_nan_velocity_slipped_past_max_abs_and_panicked_in_advection() {
    for method in [MethodKind::Flip, MethodKind::Ccp] {
        let scene = load("drop-2d", &common::with(method, None));
        let mut sim = simulation::<2>(&scene, false);
        sim.step().unwrap();
        sim.state.particles.vel[7][0] = f64::NAN;
        let err = sim.step().expect_err("a NaN velocity must not pass");
        assert!(
            format!("{err:#}").contains("not finite"),
            "{method:?}: {err:#}"
        );
    }
}

// Coupling with solids (solids).

/// Fixed in 4b4d833: at an inexact cell size a lid flush with both walls starts an ulp past
/// the right wall; the wall clamp panicked (min > max), and without the panic the lid froze,
/// every position counting as leaving the tank.
#[test]
fn a_lid_an_ulp_past_the_wall_panicked_in_the_clamp_or_froze() {
    // At 49 cells, 1 m / (1 m / 49) = 49.00000000000001 cells: the lid starts an ulp past
    // the right wall. It used to panic in the wall clamp, or to freeze on every axis.
    let scene = Scene::load(
        "compress-2d",
        &Overrides {
            cells: Some(49),
            duration: Some(0.2),
            ..Default::default()
        },
    )
    .unwrap();
    let (r, sim) = run::<2>(&scene);
    let top = sim.state.solids.obstacles[0].shape.bounds().0[1];
    assert!(
        r.bottom < top - 1.0,
        "the lid stayed at {} of {top}",
        r.bottom
    );
}

/// Fixed in 4416a2d: two obstacles could move into the same free cell in one step (targets
/// were checked only against the cells obstacles held, not those others were moving into).
#[test]
fn obstacles_moving_head_on_claimed_the_same_free_cell_2d_and_3d() {
    fn check<const D: usize>() {
        let v = |x, y, z| point(D, x, y, z);
        // Two boxes a cell apart (0.05 m) close in on each other at 1 m/s each, in the air.
        let boxes = |name: &str, x0: f64, x1: f64, vx: f64| {
            format!(
                "[[obstacle]]\nname = \"{name}\"\nshape = \"box\"\nmin = {}\nmax = {}\n\
                 velocity = {}\n",
                v(x0, 0.5, 0.3),
                v(x1, 0.7, 0.7),
                v(vx, 0.0, 0.0)
            )
        };
        let text = format!(
            "name = \"head-on\"\ndim = {D}\n[domain]\nsize = {}\ncells = 20\n\
             [simulation]\nmethod = \"ccp\"\nduration = 0.3\nppc = {}\nmax_dt = 0.02\n\
             [[fluid]]\nshape = \"box\"\nmin = {}\nmax = {}\n{}{}",
            v(1.0, 1.0, 1.0),
            1 << D,
            v(0.0, 0.0, 0.0),
            v(1.0, 0.1, 1.0),
            boxes("a", 0.2, 0.4, 1.0),
            boxes("b", 0.45, 0.65, -1.0),
        );
        let scene = Scene::parse("head-on scene", &text, &Overrides::default()).unwrap();
        let (sim, _) = run_apart::<D>(&scene);
        // They met: no free cell is left between their cells.
        let columns = |k: usize| {
            let o = &sim.state.solids.obstacles[k];
            let x: Vec<usize> = o
                .cells_at(&sim.state.grid, &o.offset)
                .into_iter()
                .map(|c| sim.state.grid.cell_coords(c)[0])
                .collect();
            (*x.iter().min().unwrap(), *x.iter().max().unwrap())
        };
        let ((_, a_right), (b_left, _)) = (columns(0), columns(1));
        assert_eq!(a_right + 1, b_left, "{D}D: columns between them stay free");
    }
    check::<2>();
    check::<3>();
}
