//! What the command line refuses, as a user meets it: a scene file, a scene name or options
//! that cannot run give a clear error naming the file, the key (or option) and the reason;
//! non-zero exit; no panic; no output file. `GOOD`, the scene every refusal edits, runs.

use crate::common::{self, cellflip, scratch_dir};
use cellflip::scene::{ErrorKind, Overrides, Scene, SceneError};

const GOOD: &str = r#"
name = "tiny"
dim = 2
[domain]
size = [1.0, 1.0]
cells = 8
[simulation]
duration = 0.05
[[fluid]]
shape = "box"
min = [0.0, 0.0]
max = [0.5, 0.5]
"#;

/// `text` is refused: the library's error has this `key` and `kind`, and `cellflip run` on
/// the file fails cleanly (no panic, non-zero exit, no output file) naming the file and the
/// key in its message.
fn rejects(test: &str, text: &str, key: &str, kind: ErrorKind) {
    let e = Scene::parse("scene.toml", text, &Overrides::default())
        .expect_err(test)
        .downcast::<SceneError>()
        .unwrap_or_else(|e| panic!("{test}: not a scene error: {e:#}"));
    assert_eq!((e.key.as_str(), e.kind), (key, kind), "{test}: {e}");
    let dir = scratch_dir(test);
    let file = dir.join("scene.toml");
    std::fs::write(&file, text).unwrap();
    let out = dir.join("out.rrd");
    let o = cellflip(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{test}: accepted");
    assert!(!err.contains("panicked"), "{test}: panic: {err}");
    assert!(
        err.contains("scene.toml") && err.contains(key),
        "{test}: file or key not named: {err}"
    );
    assert!(!out.exists(), "{test}: wrote output on bad input");
}

#[test]
fn good_scene_file_runs() {
    let dir = scratch_dir("good");
    let file = dir.join("scene.toml");
    std::fs::write(&file, GOOD).unwrap();
    let o = cellflip(&["run", file.to_str().unwrap(), "--no-record"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        summary.contains("steps") && summary.contains("volume"),
        "{summary}"
    );
}

#[test]
fn malformed_toml_is_rejected() {
    rejects(
        "malformed",
        "name = \"x\"\ndim = 2\n[domain\n",
        "domain",
        ErrorKind::Syntax,
    );
}

#[test]
fn unknown_key_is_rejected() {
    let text = GOOD.replace("duration = 0.05", "duration = 0.05\nviscosity = 1.0");
    rejects(
        "unknown-key",
        &text,
        "simulation.viscosity",
        ErrorKind::Syntax,
    );
}

#[test]
fn too_few_cells_are_rejected() {
    let text = GOOD.replace("cells = 8", "cells = 3");
    rejects("cells", &text, "domain.cells", ErrorKind::Range);
}

#[test]
fn zero_ppc_is_rejected() {
    let text = GOOD.replace("duration = 0.05", "duration = 0.05\nppc = 0");
    rejects("ppc", &text, "simulation.ppc", ErrorKind::Range);
}

#[test]
fn bad_band_settings_are_rejected() {
    let with = |extra: &str| GOOD.replace("duration = 0.05", &format!("duration = 0.05\n{extra}"));
    rejects(
        "band-name",
        &with("band = \"wide\""),
        "simulation.band",
        ErrorKind::Syntax,
    );
    let zero = with("band = \"paths\"\nband_r = 0");
    rejects("band-r", &zero, "simulation.band_r", ErrorKind::Range);
    let moore = with("band = \"paths\"\ndirections = \"moore\"");
    rejects("band-moore", &moore, "simulation.band", ErrorKind::Conflict);
    let method = with("method = \"sph\"");
    rejects(
        "method-name",
        &method,
        "simulation.method",
        ErrorKind::Syntax,
    );
    let couple = with("obstacle = \"couple\"");
    rejects(
        "flip-couple",
        &couple,
        "simulation.obstacle",
        ErrorKind::Conflict,
    );
}

#[test]
fn bad_solids_and_obstacles_are_rejected() {
    let with = |extra: &str| format!("{GOOD}{extra}");
    // At 64 cells, two cells are 3.1 cm.
    let spiral = |keys: &str| {
        with(&format!(
            "[[solid]]\nshape = \"spiral\"\nmin = [0.0, 0.5]\nmax = [1.0, 1.0]\n{keys}\n"
        ))
        .replace("cells = 8", "cells = 64")
    };
    let fluid_spiral = GOOD.replace("shape = \"box\"", "shape = \"spiral\"");
    rejects(
        "spiral-fluid",
        &fluid_spiral,
        "fluid[0].shape",
        ErrorKind::Conflict,
    );
    let keys = spiral("center = [0.5, 0.75]\nradius = 0.2");
    rejects("spiral-keys", &keys, "solid[0]", ErrorKind::Keys);
    let narrow = spiral("center = [0.5, 0.75]\nradius = 0.2\nturns = 0.5\nwidth = 0.02");
    rejects(
        "spiral-narrow",
        &narrow,
        "solid[0].width",
        ErrorKind::Geometry,
    );
    let walls = spiral("center = [0.5, 0.75]\nradius = 0.2\nturns = 1.5\nwidth = 0.08");
    rejects("spiral-walls", &walls, "solid[0]", ErrorKind::Geometry);
    let outside = spiral("center = [0.5, 0.6]\nradius = 0.2\nturns = 0.5\nwidth = 0.05");
    rejects("spiral-outside", &outside, "solid[0]", ErrorKind::Geometry);
    let good_spiral = "center = [0.5, 0.75]\nradius = 0.2\nturns = 0.5\nwidth = 0.05";
    rejects(
        "spiral-3d",
        &spiral(good_spiral)
            .replace("dim = 2", "dim = 3")
            .replace("duration = 0.05", "duration = 0.05\nppc = 8")
            .replace("size = [1.0, 1.0]", "size = [1.0, 1.0, 1.0]")
            .replace("[0.0, 0.0]", "[0.0, 0.0, 0.0]")
            .replace("[0.5, 0.5]", "[0.5, 0.5, 0.5]"),
        "solid[0].shape",
        ErrorKind::Conflict,
    );
    let moving = spiral("center = [0.5, 0.75]\nradius = 0.2").replace(
        "[[solid]]",
        "[[obstacle]]\nname = \"s\"\nvelocity = [0.0, 0.0]",
    );
    rejects(
        "spiral-obstacle",
        &moving,
        "obstacle[0].shape",
        ErrorKind::Conflict,
    );
    let radius =
        with("[[solid]]\nshape = \"box\"\nmin = [0.0, 0.0]\nmax = [1.0, 0.1]\nradius = 0.2\n");
    rejects("box-radius", &radius, "solid[0]", ErrorKind::Keys);
    let obstacle = |name: &str, min: &str, max: &str| {
        format!(
            "[[obstacle]]\nname = \"{name}\"\nshape = \"box\"\nmin = {min}\nmax = {max}\n\
             velocity = [0.0, -1.0]\n"
        )
    };
    let in_solid = with(&format!(
        "[[solid]]\nshape = \"box\"\nmin = [0.0, 0.6]\nmax = [1.0, 0.7]\n{}",
        obstacle("lid", "[0.2, 0.65]", "[0.4, 0.9]")
    ));
    rejects(
        "obstacle-in-solid",
        &in_solid,
        "obstacle[0]",
        ErrorKind::Geometry,
    );
    let overlap = with(&format!(
        "{}{}",
        obstacle("a", "[0.2, 0.6]", "[0.4, 0.8]"),
        obstacle("b", "[0.3, 0.65]", "[0.6, 0.9]")
    ));
    rejects(
        "obstacles-overlap",
        &overlap,
        "obstacle[1]",
        ErrorKind::Geometry,
    );
}

#[test]
fn negative_duration_is_rejected() {
    let text = GOOD.replace("duration = 0.05", "duration = -1.0");
    rejects("duration", &text, "simulation.duration", ErrorKind::Range);
}

#[test]
fn fluid_outside_the_domain_is_rejected() {
    let text = GOOD.replace("max = [0.5, 0.5]", "max = [0.5, 1.5]");
    rejects("outside", &text, "fluid[0].max", ErrorKind::Geometry);
}

#[test]
fn unknown_scene_name_is_rejected() {
    let o = cellflip(&["run", "no-such-scene", "--no-record"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("unknown scene 'no-such-scene'") && err.contains("dam-2d"),
        "{err}"
    );
}

#[test]
fn options_a_method_lacks_are_refused_before_anything_is_written() {
    let dir = scratch_dir("options");
    let out = dir.join("x.rrd");
    for flags in [
        vec!["--export-lp", "1"],
        vec!["--band", "paths"],
        vec!["--band-r", "2"],
        vec!["--solver", "simplex"],
        vec!["--directions", "moore"],
        vec!["--cross-check"],
    ] {
        let mut args = vec!["run", "hydrostatic-2d", "--out", out.to_str().unwrap()];
        args.extend(&flags);
        let o = cellflip(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{flags:?} accepted");
        assert!(
            err.contains(flags[0]) && err.contains("'flip'"),
            "{flags:?}: {err}"
        );
        assert!(!out.exists(), "{flags:?}: wrote a recording");
    }
    let o = cellflip(&[
        "bench",
        "--scene",
        "hydrostatic-2d",
        "--res",
        "16",
        "--band",
        "paths",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--band"));
}

#[test]
fn export_lp_for_a_step_the_run_never_reaches_is_refused() {
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
#[test]
fn hostile_values_are_refused_naming_the_key() {
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
    let o = cellflip(&[
        "run",
        "dam-3d",
        "--res",
        "580",
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
