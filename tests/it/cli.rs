//! The command line as a user meets it: listing, bad input (a clear error naming the file,
//! the key and the reason; non-zero exit; no panic; no output file) and a recording that reads
//! back with the documented entities.

use crate::common;
use cellflip::scene::{ErrorKind, Overrides, Scene, SceneError};
use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Command, Output};

fn cellflip(args: &[&str]) -> Output {
    cellflip_in(Path::new("."), args)
}

/// `cellflip args` run from the folder `dir`.
fn cellflip_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(args)
        .current_dir(dir)
        .env_remove("RERUN")
        .output()
        .expect("the binary runs")
}

fn scratch_dir(test: &str) -> common::Scratch {
    common::Scratch::new("test", test)
}

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
fn unwritable_out_is_rejected() {
    let o = cellflip(&[
        "run",
        "hydrostatic-2d",
        "--steps",
        "2",
        "--out",
        "/nonexistent-dir/x.rrd",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("/nonexistent-dir/x.rrd"), "{err}");
}

#[test]
fn list_names_every_built_in_scene() {
    let o = cellflip(&["list"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    for (name, _) in cellflip::scene::BUILT_IN {
        assert!(
            text.lines().any(|l| l.starts_with(name)),
            "{name} missing from:\n{text}"
        );
    }
}

/// Runs `cellflip run <scene> --steps <steps> <extra>` into `dir` and returns the entities
/// its recording holds.
fn record(dir: &Path, scene: &str, steps: &str, extra: &[&str]) -> BTreeSet<String> {
    let out = dir.join(format!("{scene}-{}.rrd", extra.join("")));
    let mut args = vec![
        "run",
        scene,
        "--steps",
        steps,
        "-q",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    let o = cellflip(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    common::logged_entities(&out)
}

#[test]
fn recordings_log_exactly_the_documented_entities() {
    // Between them these runs log everything: flip in 2D, ccp with the solver cross-check and
    // an exported problem, the band in 2D (all variants' objectives) and 3D (with its slice),
    // obstacles, idp in 2D and 3D (its slice), nbflip and powerpic in 3D.
    let dir = scratch_dir("record");
    let mut logged = BTreeSet::new();
    logged.extend(record(&dir, "hydrostatic-2d", "3", &[]));
    logged.extend(record(
        &dir,
        "dam-2d",
        "4",
        &["--cross-check", "--export-lp", "3"],
    ));
    let band = [
        "--band",
        "paths",
        "--band-r",
        "2",
        "--res",
        "24",
        "--cross-check",
    ];
    let band_2d = record(&dir, "dam-2d", "30", &band);
    assert!(band_2d.contains("metrics/band/objective/full"));
    assert!(band_2d.contains("metrics/band/objective/one-way"));
    logged.extend(band_2d);
    logged.extend(record(&dir, "drop-3d", "30", &["--res", "12"]));
    logged.extend(record(&dir, "compress-2d", "20", &[]));
    logged.extend(record(&dir, "dam-2d", "5", &["--method", "idp"]));
    let every_step = ["--record-every", "1", "--res", "12"];
    logged.extend(record(
        &dir,
        "dam-3d",
        "2",
        &[&every_step[..], &["--method", "idp"]].concat(),
    ));
    logged.extend(record(
        &dir,
        "dam-3d",
        "3",
        &["--method", "nbflip", "--res", "12"],
    ));
    logged.extend(record(
        &dir,
        "dam-3d",
        "2",
        &[&every_step[..], &["--method", "powerpic"]].concat(),
    ));
    let documented = common::documented_entities();
    assert!(documented.len() > 30, "the README's table: {documented:?}");
    let undocumented: Vec<&String> = logged
        .iter()
        .filter(|l| !documented.iter().any(|d| common::matches(d, l)))
        .collect();
    assert!(
        undocumented.is_empty(),
        "logged but not in the README: {undocumented:?}"
    );
    let missing: Vec<&String> = documented
        .iter()
        .filter(|d| !logged.iter().any(|l| common::matches(d, l)))
        .collect();
    assert!(
        missing.is_empty(),
        "in the README but never logged: {missing:?}"
    );
    let mps = std::fs::read_to_string(dir.join("dam-2d-ccp-50x50-ppc4-seed1-step3.mps")).unwrap();
    assert!(
        mps.starts_with("* optimal objective ")
            && mps.contains("\nROWS\n")
            && mps.ends_with("ENDATA\n")
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

/// `cellflip solve FILE --solver flow,simplex` finds the file's recorded optimum with both, and
/// reports the flow solver's work.
fn solves_to_the_recorded_optimum(file: &std::path::Path) {
    let args = ["solve", file.to_str().unwrap(), "--solver", "flow,simplex"];
    let o = cellflip(&[&args[..], &["--repeat", "1"]].concat());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let gaps: Vec<f64> = text
        .lines()
        .filter_map(|l| {
            l.split(" from the recorded optimum")
                .next()?
                .rsplit(", ")
                .next()
        })
        .filter_map(|g| g.parse().ok())
        .collect();
    assert!(gaps.len() == 2 && gaps.iter().all(|&g| g <= 1e-9), "{text}");
    let flow = text.lines().find(|l| l.trim_start().starts_with("flow"));
    assert!(flow.is_some_and(|l| l.contains(" nodes settled")), "{text}");
}

#[test]
fn exact_paths_exports_its_second_step_with_its_optimum() {
    // dam-2d at 50^2 moves particles across the band interface at step 40.
    let dir = scratch_dir("export-second");
    let args = ["run", "dam-2d", "--band", "exact-paths", "--steps", "40"];
    let more = ["--export-lp", "40", "--no-record"];
    let o = cellflip_in(&dir, &[&args[..], &more[..]].concat());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let name = "dam-2d-ccp-band-exact-paths-r6-50x50-ppc4-seed1-step40-second.mps";
    assert!(text.contains(name), "the summary names the file: {text}");
    let file = dir.join("recordings").join(name);
    let mps = std::fs::read_to_string(&file).unwrap();
    assert!(mps.contains("exact-paths: the band method's second step"));
    solves_to_the_recorded_optimum(&file);
}

#[test]
fn exported_problems_are_named_after_the_run_beside_the_recording_or_in_recordings() {
    let dir = scratch_dir("export-names");
    let out = dir.join("run.rrd");
    let args = [
        "run",
        "dam-3d",
        "--res",
        "12",
        "--steps",
        "2",
        "--export-lp",
        "2",
        "-q",
    ];
    let o = cellflip(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mps =
        std::fs::read_to_string(dir.join("dam-3d-ccp-band-paths-r6-12x12x12-ppc8-seed1-step2.mps"));
    assert!(mps.unwrap().contains("\nROWS\n"));
    // Without a recording, in recordings/ of the working folder, which need not exist yet.
    let args = [
        "run",
        "dam-2d",
        "--res",
        "24",
        "--steps",
        "1",
        "--export-lp",
        "1",
    ];
    let o = cellflip_in(&dir, &[&args[..], &["--no-record", "-q"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let file = dir.join("recordings/dam-2d-ccp-24x24-ppc4-seed1-step1.mps");
    let mps = std::fs::read_to_string(&file);
    assert!(mps.unwrap().starts_with("* optimal objective "));
    // `cellflip solve` reads it back and finds the recorded optimum with both solvers.
    solves_to_the_recorded_optimum(&file);
    // A file it cannot read is named with the line and the reason.
    let bad = dir.join("bad.mps");
    std::fs::write(&bad, "NAME t\nROWS\n G bin0\n").unwrap();
    let o = cellflip(&["solve", bad.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("bad.mps: line 3"),
        "{err}"
    );
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

#[test]
fn signals_stop_the_run_with_their_exit_status_and_a_valid_recording() {
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

#[test]
fn a_full_device_stops_the_run_naming_the_file_and_the_os_error() {
    // At creation: nothing can be written.
    let o = cellflip(&["run", "dam-2d", "--steps", "3", "-q", "--out", "/dev/full"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !err.contains("panicked"), "{err}");
    assert!(
        err.contains("'/dev/full'") && err.contains("No space left on device"),
        "{err}"
    );
    // Mid-run: a file size limit (RLIMIT_FSIZE, with SIGXFSZ ignored) fails a later write
    // with EFBIG; the run stops at once, and what was written stays readable.
    let dir = scratch_dir("fsize");
    let out = dir.join("dam.rrd");
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f 400; exec '{}' run dam-2d --duration 1000 -q --out '{}'",
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

#[test]
fn a_closed_or_full_standard_output_does_not_panic() {
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
