//! `cellflip report` on a tiny matrix: every documented column, figures recomputed from an
//! independent run of the same scene, valid plots, a readable comparison recording, and runs
//! that fail (a scene that does not load, one that breaks an invariant) as rows, not aborts.

use crate::common;
use crate::sweep::untimed_rows;
use cellflip::cmd::report::docs;
use cellflip::cmd::report::measure::{figure_columns, COLUMNS};
use cellflip::methods::MethodKind;
use cellflip::scene::Overrides;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A scene whose emitter velocity makes the grid velocity overflow in the first step.
/// A full tank whose particles are 1.44 times too large for Power PIC's transport cells
/// (`tau = 0.3`: `V_p = 0.6^2` cells at 4 per cell): its powerpic runs fail at step 1 (the Sinkhorn solve cannot place them), the others run. (An
/// emitter at 1e300 m/s used to be the failing scene; it is now refused before it runs.)
const OVERFLOW: &str = r#"
name = "overflow"
dim = 2
[domain]
size = [1.0, 1.0]
cells = 16
[simulation.powerpic]
tau = 0.3
[[fluid]]
shape = "box"
min = [0.0, 0.0]
max = [1.0, 1.0]
"#;

/// Splits a CSV line, honouring double quotes.
fn fields(line: &str) -> Vec<String> {
    let (mut out, mut cur, mut quoted) = (vec![], String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut cur)),
            _ => cur.push(c),
        }
    }
    out.push(cur);
    out
}

/// Runs the tiny matrix once per test binary and returns its folder: one under cargo's target
/// folder, replaced by every run (the tests share it, so no test can remove it).
fn tiny_report() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("tiny-report");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("overflow.toml"), OVERFLOW).unwrap();
        let scenes = format!(
            "hydrostatic-2d,dam-2d,{}",
            dir.join("overflow.toml").display(),
        );
        let out = dir.join("out");
        let o = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .args([
                "report",
                "--scenes",
                &scenes,
                "--res",
                "24,32",
                "--duration",
                "0.1",
                "-q",
            ])
            .args(["--out", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    })
    .clone()
}

/// The CSV's rows as column -> value maps.
fn rows(dir: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(dir.join("report.csv")).unwrap();
    let mut lines = text.lines();
    let header = fields(lines.next().unwrap());
    lines
        .map(|l| header.iter().cloned().zip(fields(l)).collect())
        .collect()
}

#[test]
fn the_csv_has_every_documented_column_and_a_row_per_run() {
    let dir = tiny_report();
    let text = std::fs::read_to_string(dir.join("report.csv")).unwrap();
    let header = fields(text.lines().next().unwrap());
    // The manual documents exactly the columns the code declares, and every method figure.
    let page = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/report.md"));
    for (c, _) in COLUMNS {
        assert!(header.contains(&c.to_string()), "{c} missing from the CSV");
        assert!(
            page.contains(&format!("| `{c}` |")),
            "{c} not documented in docs/report.md"
        );
    }
    let documented = crate::docs::first_column(page, "| column | what |");
    assert_eq!(
        documented.len(),
        COLUMNS.len(),
        "docs/report.md's columns: {documented:?}"
    );
    for c in figure_columns() {
        assert!(header.contains(&c), "{c} missing");
        let figure = (c
            .strip_suffix("_median")
            .or_else(|| c.strip_suffix("_mean")))
        .expect("a figure's column ends in _median or _mean");
        assert!(
            page.contains(&format!("`{figure}`")),
            "the figure {figure} is not documented in docs/report.md"
        );
    }
    // 3 scenes x 2 resolutions x every method.
    assert_eq!(rows(&dir).len(), 3 * 2 * MethodKind::ALL.len());
}

/// Each row names the kind of machine that ran it (timings compare only within one kind) and
/// the memory copy bandwidth its process measured: this machine's, for a report run here.
#[test]
fn each_row_names_the_machine_that_ran_it() {
    let here = cellflip::machine::Machine::here(1);
    let (cpu, cores) = (here.cpu, cellflip::machine::count(here.cores, "core"));
    for r in rows(&tiny_report()) {
        let (machine, gb_s) = (&r["machine"], &r["copy_gb_s"]);
        let threads = machine.strip_prefix(&format!("{cpu} ({cores}, "));
        assert!(
            threads.is_some_and(|t| t.ends_with(" threads)") || t == "1 thread)"),
            "{machine}"
        );
        assert!(gb_s.parse::<f64>().unwrap() > 0.0, "{gb_s}");
    }
}

#[test]
fn failing_runs_are_rows_that_say_why() {
    let rows = rows(&tiny_report());
    let status = |scene: &str| -> Vec<String> {
        rows.iter()
            .filter(|r| r["scene"].contains(scene))
            .map(|r| r["status"].clone())
            .collect()
    };
    let overflow: Vec<_> = rows
        .iter()
        .filter(|r| r["scene"].contains("overflow"))
        .collect();
    assert!(!overflow.is_empty());
    for r in overflow {
        let s = &r["status"];
        match r["method"].as_str() {
            "powerpic" => assert!(
                s.starts_with("failed: step 1: ") && s.contains("simulation.powerpic.tau"),
                "{s}"
            ),
            m => assert!(
                !s.starts_with("failed") && !s.starts_with("not run"),
                "{m}: {s}"
            ),
        }
    }
    assert!(status("dam-2d").iter().all(|s| s == "ok"));
}

/// A scene that cannot run (unknown, unreadable, malformed, at an impossible resolution) or an
/// unknown method stops the report before any run, naming each reason once, with exit 1 and
/// nothing written. (It used to write a report of failed rows and exit 0.)
#[test]
fn a_matrix_that_cannot_run_is_refused_before_any_run() {
    let dir = crate::common::scratch_dir("report-refused");
    let broken = dir.join("broken.toml");
    std::fs::write(&broken, "name = \"broken\"\ndim = 2\n[domain\n").unwrap();
    let missing = dir.join("missing.toml");
    let out = dir.join("out");
    let cases: [(&[&str], &[&str]); 5] = [
        (&["--scenes", "nowhere"], &["unknown scene 'nowhere'"]),
        (&["--scenes", broken.to_str().unwrap()], &["broken.toml"]),
        (
            &["--scenes", missing.to_str().unwrap()],
            &["cannot read scene file", "missing.toml"],
        ),
        (
            &["--scenes", "dam-2d,nowhere", "--res", "0"],
            &["2 of the report's scenes cannot run", "nowhere", "got 0"],
        ),
        (
            &["--scenes", "dam-2d", "--methods", "nope"],
            &["invalid value 'nope'"],
        ),
    ];
    for (args, says) in cases {
        let o = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .arg("report")
            .args(args)
            .args(["-q", "--out", out.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(says.iter().all(|s| err.contains(s)), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
}

#[test]
fn a_runs_figures_match_an_independent_run_of_the_same_scene() {
    let rows = rows(&tiny_report());
    for method in MethodKind::ALL {
        let row = rows
            .iter()
            .find(|r| r["scene"] == "dam-2d" && r["method"] == method.name() && r["res"] == "24")
            .unwrap();
        let o = Overrides {
            method: Some(*method),
            cells: Some(24),
            duration: Some(0.1),
            ..Default::default()
        };
        let scene = common::load("dam-2d", &o);
        let (mut vmin, mut vmax, mut err, mut steps) = (100.0f64, 100.0f64, 0.0, 0);
        let runner = common::run::<2>(&scene, None, |_, rep| {
            vmin = vmin.min(rep.volume_percent);
            vmax = vmax.max(rep.volume_percent);
            err += (rep.volume_percent - 100.0).abs();
            steps += 1;
        });
        let s = &runner.sim.state;
        let (g, h, mu) = (&s.grid, s.config.cell_size_m, s.config.mu() as f64);
        // The liquid's kinetic energy per unit mass (docs/report.md): a particle is 1/mu of a
        // cell, a deep cell a whole one moving with the grid velocity at its centre.
        let deep: Vec<f64> = (0..g.num_cells())
            .filter(|&c| s.markings.is_fluid(c) && runner.sim.method.is_deep(s, c))
            .map(|c| (s.velocity.interpolate(g, &g.center(g.cell_coords(c)))).norm_squared())
            .collect();
        let particles: f64 = s.particles.vel.iter().map(|v| v.norm_squared()).sum();
        let mass = s.particles.len() as f64 / mu + deep.len() as f64;
        let ke = 0.5 * (particles / mu + deep.iter().sum::<f64>()) / mass * h * h;
        let num = |c: &str| {
            row[c]
                .parse::<f64>()
                .unwrap_or_else(|_| panic!("{c}: {}", row[c]))
        };
        let at = method.name();
        assert_eq!(num("steps"), steps as f64, "{at}");
        assert_eq!(num("particles"), s.particles.len() as f64, "{at}");
        assert_eq!(num("volume_min"), vmin, "{at}");
        assert_eq!(num("volume_max"), vmax, "{at}");
        assert!(
            (num("volume_error") - err / steps as f64).abs() < 1e-12,
            "{at}"
        );
        assert!((num("ke_end") - ke).abs() <= 1e-12 * ke.max(1e-30), "{at}");
        let shares: f64 = COLUMNS
            .iter()
            .filter(|(c, _)| c.starts_with("share_"))
            .map(|(c, _)| num(c))
            .sum();
        assert!(
            (shares - 100.0).abs() < 1e-6,
            "{at}: shares sum to {shares}"
        );
    }
}

#[test]
fn plots_are_valid_png_and_svg_and_the_recording_reads_back() {
    let dir = tiny_report();
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    // Two resolutions: the Pareto view of dam-2d, and a volume plot per scene that ran.
    for stem in [
        "pareto-dam-2d-volume",
        "volume-dam-2d",
        "volume-hydrostatic-2d",
    ] {
        let png =
            image::open(dir.join(format!("{stem}.png"))).unwrap_or_else(|e| panic!("{stem}: {e}"));
        assert_eq!((png.width(), png.height()), (900, 560));
        let rgb = png.to_rgb8();
        assert!(
            rgb.pixels().any(|p| p.0 != [255, 255, 255]),
            "{stem}.png is blank"
        );
        let svg = std::fs::read_to_string(dir.join(format!("{stem}.svg"))).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>") && svg.contains("<text"),
            "{stem}.svg"
        );
        assert!(
            md.contains(&format!("{stem}.png")),
            "report.md links {stem}.png"
        );
    }
    let got = common::logged_entities(&dir.join("report.rrd"));
    for k in MethodKind::ALL {
        assert!(
            got.contains(&format!("volume/dam-2d/{}/24", k.name())),
            "{got:?}"
        );
        assert!(
            got.contains(&format!("kinetic_energy/hydrostatic-2d/{}/32", k.name())),
            "{got:?}"
        );
    }
}

#[test]
fn a_run_over_its_budget_stops_and_says_so() {
    let dir = common::scratch_dir("report_budget");
    let out = common::cellflip_in(
        &dir,
        &[
            "report",
            "--scenes",
            "dam-2d",
            "--methods",
            "flip,ccp",
            // Long enough that no run ends within the budget however fast it steps (1 s of
            // flip on dam-2d took under 0.05 s once its grid passes followed the liquid).
            "--duration",
            "20",
            "--budget",
            "0.05",
            "-q",
            "--out",
            "out",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for row in rows(&dir.join("out")) {
        let status = &row["status"];
        assert!(
            status.starts_with("over budget: stopped after 0.05 s wall at t = "),
            "{}: {status}",
            row["method"]
        );
        let t: f64 = row["sim_s"].parse().unwrap();
        assert!(t > 0.0 && t < 20.0, "{}: {t} s simulated", row["method"]);
    }
}

#[test]
fn docs_mode_refuses_a_folder_without_the_readme_markers_before_running() {
    let dir = common::scratch_dir("report_docs_refused");
    std::fs::write(dir.join("README.md"), "# not cellflip\n").unwrap();
    let t0 = std::time::Instant::now();
    let out = common::cellflip_in(&dir, &["report", "--docs", "-q"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("README.md") && err.contains("results markers"),
        "{err}"
    );
    assert!(
        t0.elapsed().as_secs() < 10,
        "refused before running the matrix"
    );
    assert!(!dir.join("docs").exists(), "nothing written");
}

/// `--docs` keeps the page's results beside it (docs/results-paper/runs/ for the paper's
/// matrix, two of whose cheap jobs ran) and no others, and a checkout merges them again into
/// the page's own report.csv without the folder that ran them.
#[test]
fn docs_mode_keeps_the_pages_results_in_the_repository() {
    let dir = common::scratch_dir("report_docs_kept");
    let readme = format!("# cellflip\n{}\n{}\n", docs::BEGIN, docs::END);
    std::fs::write(dir.join("README.md"), readme).unwrap();
    let runs = dir.join("docs/results-paper/runs");
    std::fs::create_dir_all(&runs).unwrap();
    let stale = runs.join("gone-flip-r24-s1-00000000.result");
    std::fs::write(&stale, "a job no longer on the page").unwrap();
    let plan = common::cellflip_in(&dir, &["report", "--matrix", "paper", "--plan"]);
    common::ok(&plan);
    let plan = String::from_utf8_lossy(&plan.stdout);
    let ids: Vec<&str> = (plan.lines())
        .filter(|l| l.starts_with("drop-2d-flip-") || l.starts_with("drop-2d-ccp-"))
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(ids.len(), 2, "{plan}");
    let paper = ["report", "--matrix", "paper", "-q"];
    let jobs = ids.join(",");
    common::ok(&common::cellflip_in(
        &dir,
        &[&paper[..], &["--out", "ran", "--job", &jobs]].concat(),
    ));
    common::ok(&common::cellflip_in(
        &dir,
        &[&paper[..], &["--merge", "ran", "--docs"]].concat(),
    ));
    let mut kept: Vec<String> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    kept.sort();
    let mut expected: Vec<String> = ids.iter().map(|id| format!("{id}.result")).collect();
    expected.sort();
    assert_eq!(kept, expected, "the page's results and no others");
    std::fs::remove_dir_all(dir.join("ran")).unwrap();
    std::fs::create_dir(dir.join("again")).unwrap();
    let again = ["report", "--merge", "again,docs/results-paper", "-q"];
    common::ok(&common::cellflip_in(&dir, &again));
    let csv = |p: &str| std::fs::read_to_string(dir.join(p)).unwrap();
    assert_eq!(
        csv("again/report.csv"),
        csv("docs/results-paper/report.csv")
    );
}

/// A report stopped by Ctrl-C while its second run goes on, then started again with the same
/// arguments: the first run is read back (not run again), the second resumes from the
/// checkpoint the signal left, and report.csv is the report never stopped but for its timings.
#[test]
fn a_report_stopped_and_started_again_goes_on_where_it_stopped() {
    let dir = common::scratch_dir("report-resume");
    let (straight, split) = (dir.join("straight"), dir.join("split"));
    let args = |out: &Path| -> Vec<String> {
        let a = [
            "report",
            "--scenes",
            "dam-2d",
            "--methods",
            "flip,ccp",
            "--res",
            "100",
        ];
        let mut a: Vec<String> = a.iter().map(|s| s.to_string()).collect();
        a.extend(["--duration", "2", "--no-stability", "-q", "--out"].map(String::from));
        a.push(out.display().to_string());
        a
    };
    let cellflip = || Command::new(env!("CARGO_BIN_EXE_cellflip"));
    common::ok(&cellflip().args(args(&straight)).output().unwrap());
    let child = cellflip()
        .args(args(&split))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let runs = split.join("runs");
    let count = |ext: &str| {
        std::fs::read_dir(&runs).map_or(0, |d| {
            d.flatten()
                .filter(|e| e.path().extension().is_some_and(|x| x == ext))
                .count()
        })
    };
    let t0 = std::time::Instant::now();
    while count("result") == 0 {
        assert!(t0.elapsed().as_secs() < 120, "the first run never ended");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    std::thread::sleep(std::time::Duration::from_millis(300));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    assert!(kill.unwrap().success());
    let o = child.wait_with_output().unwrap();
    assert_eq!(
        o.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(
        (count("result"), count("checkpoints")),
        (1, 1),
        "stopped mid-run"
    );
    // A merge meanwhile names the stopped job's newest checkpoint.
    let merged = cellflip().args(["report", "--merge"]).arg(&split).output();
    let merged = merged.unwrap();
    common::ok(&merged);
    let said = String::from_utf8_lossy(&merged.stderr);
    assert!(
        said.contains("missing: dam-2d ccp 100: under way (checkpoint after step "),
        "{said}"
    );
    let loud: Vec<String> = args(&split).into_iter().filter(|a| a != "-q").collect();
    let again = cellflip().args(loud).output();
    let again = again.unwrap();
    common::ok(&again);
    let said = String::from_utf8_lossy(&again.stderr);
    assert!(said.contains("resuming dam-2d ccp from"), "{said}");
    assert!(!said.contains("resuming dam-2d flip"), "{said}");
    assert_eq!((count("result"), count("checkpoints")), (2, 0));
    let (a, b) = (untimed_rows(&straight), untimed_rows(&split));
    assert_eq!(a.len(), 2);
    assert_eq!(a, b);
}

/// A report run's pauses for its checkpoints change none of its figures: checkpointed after
/// every step it measures what it measures without checkpoints, and stopped after a few steps
/// and resumed from its newest checkpoint, the same again.
#[test]
fn checkpoints_during_a_report_run_change_none_of_its_figures() {
    use cellflip::cmd::report::options::MatrixOptions;
    use cellflip::cmd::report::{matrix, measure, measure::Measured, saved::RunFiles};
    use clap::Parser;
    let cli = cellflip::cmd::cli::Cli::parse_from([
        "cellflip",
        "report",
        "--scenes",
        "falling-obstacle-2d",
        "--methods",
        "ccp",
        "--duration",
        "0.3",
        "--no-stability",
    ]);
    let cellflip::cmd::cli::Command::Report(args) = cli.command else {
        unreachable!("a report command")
    };
    let spec = &matrix(&args).unwrap()[0];
    let dir = common::scratch_dir("report-pauses");
    let every_step = |sub: &str| RunFiles {
        every: std::time::Duration::ZERO,
        ..RunFiles::of(&dir.join(sub), spec, &MatrixOptions::of(&args))
    };
    let timed = |c: &str| {
        c.starts_with("ms_") || c.starts_with("share_") || c == "peak_mib" || c.contains("_ms")
    };
    let same = |a: &Measured, b: &Measured, what: &str| {
        assert_eq!(
            (&a.status, &a.volume, &a.ke),
            (&b.status, &b.volume, &b.ke),
            "{what}"
        );
        for (col, v) in a.values.iter().filter(|(c, _)| !timed(c)) {
            assert_eq!(v.to_bits(), b.get(col).to_bits(), "{what}: {col}");
        }
    };
    let plain = measure::run(spec, &|| false, None, None);
    assert_eq!(plain.status, "ok");
    let files = every_step("a");
    same(
        &plain,
        &measure::run(spec, &|| false, Some(&files), None),
        "paused every step",
    );
    assert!(files.result.exists() && !files.checkpoints.exists());
    let files = every_step("b");
    let calls = std::cell::Cell::new(0);
    let stop = || {
        calls.set(calls.get() + 1);
        calls.get() > 8
    };
    let first = measure::run(spec, &stop, Some(&files), None);
    assert_eq!(first.status, "interrupted");
    let resumed = measure::resumable(&files.checkpoints).expect("a checkpoint");
    assert!(resumed.step > 0);
    same(
        &plain,
        &measure::run(spec, &|| false, Some(&files), Some(resumed)),
        "resumed",
    );
}

/// A run's peak memory is its own in a report of several runs in one process: hydrostatic-2d
/// at 64^2 after drop-3d at 64^3 peaks within 1.25x of what it peaks in a process of its own
/// (before the allocator's free pages were handed back between runs, 29.6 MiB after the drop
/// against 14.1 alone; 2026-11-29, 8cb4dd1).
#[test]
fn a_runs_peak_memory_is_its_own_after_a_larger_run_in_the_same_process() {
    let dir = common::scratch_dir("report_peak");
    let peak_of_pool = |scenes: &str, out: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .args([
                "report",
                "--scenes",
                scenes,
                "--methods",
                "ccp",
                "--res",
                "64",
            ])
            .args(["--duration", "0.02", "--no-stability", "-q", "--out", out])
            .current_dir(&*dir)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let pool = rows(&dir.join(out))
            .into_iter()
            .find(|r| r["scene"] == "hydrostatic-2d");
        pool.unwrap()["peak_mib"].parse::<f64>().unwrap()
    };
    let after = peak_of_pool("drop-3d,hydrostatic-2d", "after");
    let alone = peak_of_pool("hydrostatic-2d", "alone");
    assert!(
        after <= 1.25 * alone,
        "{after} MiB after the drop, {alone} alone"
    );
}
