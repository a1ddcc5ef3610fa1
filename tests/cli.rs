//! The command line as a user meets it: listing, bad input (a clear error naming the file,
//! the key and the reason; non-zero exit; no panic; no output file) and a recording that reads
//! back with the documented entities.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn cellflip(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(args)
        .env_remove("RERUN")
        .output()
        .expect("the binary runs")
}

fn scratch_dir(test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("cellflip-test-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
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

/// Runs `cellflip run` on `text` and checks it fails cleanly, mentioning every `needle`.
fn rejects(test: &str, text: &str, needles: &[&str]) {
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
        err.contains("scene.toml"),
        "{test}: the file is not named: {err}"
    );
    for n in needles {
        assert!(err.contains(n), "{test}: '{n}' missing from: {err}");
    }
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
        &["TOML", "line"],
    );
}

#[test]
fn unknown_key_is_rejected() {
    let text = GOOD.replace("duration = 0.05", "duration = 0.05\nviscosity = 1.0");
    rejects("unknown-key", &text, &["viscosity"]);
}

#[test]
fn too_few_cells_are_rejected() {
    rejects(
        "cells",
        &GOOD.replace("cells = 8", "cells = 3"),
        &["domain.cells", "at least 4"],
    );
}

#[test]
fn zero_ppc_is_rejected() {
    let text = GOOD.replace("duration = 0.05", "duration = 0.05\nppc = 0");
    rejects("ppc", &text, &["simulation.ppc", "at least 1"]);
}

#[test]
fn bad_band_settings_are_rejected() {
    let with = |extra: &str| GOOD.replace("duration = 0.05", &format!("duration = 0.05\n{extra}"));
    rejects(
        "band-name",
        &with("band = \"wide\""),
        &["simulation.band", "wide", "paths"],
    );
    rejects(
        "band-r",
        &with("band = \"paths\"\nband_r = 0"),
        &["simulation.band_r", "at least 1"],
    );
    rejects(
        "band-moore",
        &with("band = \"paths\"\ndirections = \"moore\""),
        &["simulation.band", "von Neumann"],
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
    rejects(
        "spiral-fluid",
        &GOOD.replace("shape = \"box\"", "shape = \"spiral\""),
        &["fluid[0].shape", "static 2D solid"],
    );
    rejects(
        "spiral-keys",
        &spiral("center = [0.5, 0.75]\nradius = 0.2"),
        &["solid[0]", "a spiral needs", "'turns' and 'width'"],
    );
    rejects(
        "spiral-narrow",
        &spiral("center = [0.5, 0.75]\nradius = 0.2\nturns = 0.5\nwidth = 0.02"),
        &["solid[0].width", "narrower than two cells"],
    );
    rejects(
        "spiral-walls",
        &spiral("center = [0.5, 0.75]\nradius = 0.2\nturns = 1.5\nwidth = 0.08"),
        &["solid[0]", "walls between turns", "thinner than two cells"],
    );
    rejects(
        "spiral-outside",
        &spiral("center = [0.5, 0.6]\nradius = 0.2\nturns = 0.5\nwidth = 0.05"),
        &["solid[0]", "channel leaves the box on axis 1"],
    );
    let good_spiral = "center = [0.5, 0.75]\nradius = 0.2\nturns = 0.5\nwidth = 0.05";
    rejects(
        "spiral-3d",
        &spiral(good_spiral)
            .replace("dim = 2", "dim = 3")
            .replace("duration = 0.05", "duration = 0.05\nppc = 8")
            .replace("size = [1.0, 1.0]", "size = [1.0, 1.0, 1.0]")
            .replace("[0.0, 0.0]", "[0.0, 0.0, 0.0]")
            .replace("[0.5, 0.5]", "[0.5, 0.5, 0.5]"),
        &["solid[0].shape", "static 2D solid"],
    );
    rejects(
        "spiral-obstacle",
        &spiral("center = [0.5, 0.75]\nradius = 0.2").replace(
            "[[solid]]",
            "[[obstacle]]\nname = \"s\"\nvelocity = [0.0, 0.0]",
        ),
        &["obstacle[0].shape", "static 2D solid"],
    );
    rejects(
        "box-radius",
        &with("[[solid]]\nshape = \"box\"\nmin = [0.0, 0.0]\nmax = [1.0, 0.1]\nradius = 0.2\n"),
        &["solid[0]", "a box takes 'min' and 'max', not 'radius'"],
    );
    let obstacle = |name: &str, min: &str, max: &str| {
        format!(
            "[[obstacle]]\nname = \"{name}\"\nshape = \"box\"\nmin = {min}\nmax = {max}\n\
             velocity = [0.0, -1.0]\n"
        )
    };
    rejects(
        "obstacle-in-solid",
        &with(&format!(
            "[[solid]]\nshape = \"box\"\nmin = [0.0, 0.6]\nmax = [1.0, 0.7]\n{}",
            obstacle("lid", "[0.2, 0.65]", "[0.4, 0.9]")
        )),
        &["obstacle[0]", "'lid' starts in a cell of solid[0]"],
    );
    rejects(
        "obstacles-overlap",
        &with(&format!(
            "{}{}",
            obstacle("a", "[0.2, 0.6]", "[0.4, 0.8]"),
            obstacle("b", "[0.3, 0.65]", "[0.6, 0.9]")
        )),
        &["obstacle[1]", "'b' starts in a cell of obstacle[0] 'a'"],
    );
}

#[test]
fn negative_duration_is_rejected() {
    rejects(
        "duration",
        &GOOD.replace("duration = 0.05", "duration = -1.0"),
        &["simulation.duration", "positive"],
    );
}

#[test]
fn fluid_outside_the_domain_is_rejected() {
    rejects(
        "outside",
        &GOOD.replace("max = [0.5, 0.5]", "max = [0.5, 1.5]"),
        &["fluid[0].max", "outside the domain"],
    );
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

fn logged_entities(path: &Path) -> BTreeSet<String> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let reader = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out = BTreeSet::new();
    for msg in DecoderApp::decode_lazy(reader) {
        if let LogMsg::ArrowMsg(store, arrow) = msg.unwrap() {
            if store.kind() == rerun::StoreKind::Recording {
                out.insert(
                    Chunk::from_arrow_msg(&arrow)
                        .unwrap()
                        .entity_path()
                        .to_string(),
                );
            }
        }
    }
    out
}

/// Runs `scene` for `steps` steps with `extra` flags into `dir`, then checks that every entity
/// of `expected` (with `<...>` replaced by `fill`) was logged; returns all logged entities.
fn record_and_check(
    dir: &Path,
    scene: &str,
    steps: &str,
    extra: &[&str],
    expected: &[&str],
    fill: (&str, &str),
) -> BTreeSet<String> {
    let out = dir.join(format!("{scene}.rrd"));
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
    let got = logged_entities(&out);
    for e in expected {
        let e = e.replace(fill.0, fill.1);
        assert!(
            got.contains(&format!("/{e}")),
            "{scene}: /{e} missing from {got:?}"
        );
    }
    got
}

#[test]
fn recordings_read_back_with_the_documented_entities_2d_and_3d() {
    let dir = scratch_dir("record");
    for (scene, extra) in [("hydrostatic-2d", vec![]), ("drop-3d", vec!["--res", "12"])] {
        let paths = cellflip::record::ENTITY_PATHS;
        record_and_check(&dir, scene, "3", &extra, paths, ("<stage>", "pressure"));
    }
}

#[test]
fn ccp_recordings_carry_the_corrector_and_export_the_lp() {
    let dir = scratch_dir("ccp");
    let out = dir.join("dam.rrd");
    let o = cellflip(&[
        "run",
        "dam-2d",
        "--steps",
        "4",
        "-q",
        "--export-lp",
        "3",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = logged_entities(&out);
    for e in cellflip::record::CORRECTION_ENTITY_PATHS {
        assert!(got.contains(&format!("/{e}")), "/{e} missing from {got:?}");
    }
    let mps = std::fs::read_to_string(dir.join("dam-2d-step3.mps")).unwrap();
    assert!(
        mps.starts_with("* optimal objective ")
            && mps.contains("\nROWS\n")
            && mps.ends_with("ENDATA\n")
    );
    // Asking for an LP from a method without one is an error, before anything runs.
    let o = cellflip(&["run", "hydrostatic-2d", "--export-lp", "1", "--no-record"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--export-lp"));
}

#[test]
fn band_recordings_carry_depth_levels_paths_and_band_metrics_2d_and_3d() {
    let dir = scratch_dir("band");
    for (scene, extra) in [
        (
            "dam-2d",
            vec![
                "--band",
                "paths",
                "--band-r",
                "2",
                "--res",
                "24",
                "--cross-check",
            ],
        ),
        ("drop-3d", vec!["--res", "12"]),
    ] {
        let paths = cellflip::record::BAND_ENTITY_PATHS;
        let got = record_and_check(&dir, scene, "30", &extra, paths, ("<variant>", "paths"));
        if scene == "dam-2d" {
            // The cross-check records the other variants' objectives on the same problems.
            assert!(got.contains("/metrics/band/objective/full"));
            assert!(got.contains("/metrics/band/objective/one-way"));
        }
    }
}

#[test]
fn obstacle_recordings_carry_the_obstacle_its_trail_and_its_metrics() {
    let dir = scratch_dir("obstacle");
    let paths = cellflip::record::OBSTACLE_ENTITY_PATHS;
    record_and_check(&dir, "compress-2d", "20", &[], paths, ("<name>", "lid"));
}

#[test]
fn ctrl_c_stops_the_run_and_leaves_a_valid_recording() {
    let dir = scratch_dir("ctrlc");
    let out = dir.join("dam.rrd");
    let mut child = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args([
            "run",
            "dam-2d",
            "--duration",
            "1000",
            "-q",
            "--out",
            out.to_str().unwrap(),
        ])
        .spawn()
        .unwrap();
    // Wait until the run has written something, then interrupt it.
    let t0 = std::time::Instant::now();
    while std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0) < 50_000 {
        assert!(t0.elapsed().as_secs() < 60, "the run wrote nothing");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert!(status.success(), "{status:?}");
    let got = logged_entities(&out);
    assert!(
        got.contains("/world/particles") && got.contains("/log"),
        "{got:?}"
    );
}
