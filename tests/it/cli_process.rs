//! The command line as a process: listing, exit codes, the files a run writes (a recording
//! that reads back with the documented entities, exported problems that `cellflip solve` reads
//! back). Signals, full devices and closed standard output are in `regression`, named after
//! what they did before.

use crate::common::{self, cellflip, cellflip_in, scratch_dir};
use std::collections::BTreeSet;
use std::path::Path;

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

/// The summary's memory line: the process's peak, and the estimate the run was admitted on,
/// which is never below it.
#[test]
fn a_run_s_summary_gives_its_peak_memory_beside_the_estimate() {
    let o = cellflip(&[
        "run",
        "dam-3d",
        "--res",
        "24",
        "--steps",
        "3",
        "--no-record",
    ]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    let line = text.lines().find(|l| l.starts_with("memory: peak "));
    let line = line.unwrap_or_else(|| panic!("no memory line in:\n{text}"));
    let mib = |after: &str| -> f64 {
        let rest = &line[line.find(after).expect(after) + after.len()..];
        rest.split_whitespace().next().unwrap().parse().unwrap()
    };
    let (peak, estimate) = (mib("memory: peak "), mib("estimated up front "));
    assert!(peak > 0.0 && estimate >= peak, "{line}");
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
    // obstacles (under ccp and nbflip), idp in 2D and 3D (its slice), nbflip and powerpic in 3D.
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
    logged.extend(record(&dir, "compress-2d", "5", &["--method", "nbflip"]));
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
        &[&every_step[..], &["--method", "nbflip"]].concat(),
    ));
    logged.extend(record(
        &dir,
        "dam-3d",
        "2",
        &[&every_step[..], &["--method", "powerpic"]].concat(),
    ));
    let documented = common::documented_entities();
    assert!(
        documented.len() > 30,
        "docs/recordings.md's table: {documented:?}"
    );
    let undocumented: Vec<&String> = logged
        .iter()
        .filter(|l| !documented.iter().any(|d| common::matches(d, l)))
        .collect();
    assert!(
        undocumented.is_empty(),
        "logged but not in docs/recordings.md: {undocumented:?}"
    );
    let missing: Vec<&String> = documented
        .iter()
        .filter(|d| !logged.iter().any(|l| common::matches(d, l)))
        .collect();
    assert!(
        missing.is_empty(),
        "in docs/recordings.md but never logged: {missing:?}"
    );
    let mps = std::fs::read_to_string(dir.join("dam-2d-ccp-50x50-ppc4-seed1-step3.mps")).unwrap();
    assert!(
        mps.starts_with("* optimal objective ")
            && mps.contains("\nROWS\n")
            && mps.ends_with("ENDATA\n")
    );
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
