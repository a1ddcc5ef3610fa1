//! `cellflip report` as a sweep (docs/cluster.md): the plan, jobs run one by one in separate
//! processes and in reverse order, and their merge, equal to the one-process report in every
//! column but the timings; the cost model against the measured default and paper matrices;
//! bad input.

use crate::common::{ok, scratch_dir};
use cellflip::cmd::report::sweep::Job;
use cellflip::cmd::report::RunSpec;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

/// The matrix every test here uses: two scenes, two methods, two sizes, short runs.
pub const MATRIX: [&str; 10] = [
    "report",
    "--scenes",
    "dam-2d,hydrostatic-2d",
    "--methods",
    "flip,ccp",
    "--res",
    "24,32",
    "--duration",
    "0.1",
    "--no-stability",
];

fn cellflip(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(MATRIX)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

/// The job ids of the plan, in its order.
fn plan_ids(dir: &Path) -> Vec<String> {
    let out = cellflip(dir, &["--plan"]);
    ok(&out);
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().next().unwrap().to_string())
        .collect()
}

/// report.csv's rows, keyed by scene, method and resolution, without the timing columns and
/// the machine's (a job may run on another node, or with other threads).
pub fn untimed_rows(dir: &Path) -> BTreeMap<String, BTreeMap<String, String>> {
    let text = std::fs::read_to_string(dir.join("report.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let timed = |c: &str| {
        c.starts_with("ms_")
            || c.starts_with("share_")
            || c == "peak_mib"
            || c.contains("_ms_")
            || c == "machine"
            || c == "copy_gb_s"
    };
    lines
        .map(|l| {
            let row: BTreeMap<String, String> = header
                .iter()
                .cloned()
                .zip(split_quoted(l).into_iter().map(String::from))
                .filter(|(c, _)| !timed(c))
                .collect();
            (
                format!("{} {} {}", row["scene"], row["method"], row["res"]),
                row,
            )
        })
        .collect()
}

#[test]
fn jobs_run_apart_in_reverse_order_merge_into_the_one_process_report() {
    let dir = scratch_dir("sweep");
    let ids = plan_ids(&dir);
    assert_eq!(ids.len(), 8, "2 scenes x 2 methods x 2 sizes: {ids:?}");
    ok(&cellflip(&dir, &["-q", "--out", "whole"]));
    for id in ids.iter().rev() {
        let out = cellflip(&dir, &["-q", "--out", "apart", "--job", id]);
        ok(&out);
        assert!(
            !dir.join("apart/report.csv").exists(),
            "a job writes no report"
        );
    }
    let again = cellflip(&dir, &["--out", "apart", "--job", &ids[0]]);
    ok(&again);
    let merged = cellflip(&dir, &["--merge", "apart"]);
    ok(&merged);
    let said = String::from_utf8_lossy(&merged.stdout);
    assert!(said.contains("8 of 8 runs (0 failed, 0 missing)"), "{said}");
    let (whole, apart) = (
        untimed_rows(&dir.join("whole")),
        untimed_rows(&dir.join("apart")),
    );
    assert_eq!(whole.len(), 8);
    assert_eq!(whole, apart);
    for f in ["report.md", "report.rrd", "volume-dam-2d.png"] {
        assert!(dir.join("apart").join(f).exists(), "{f}");
    }
}

/// A merge lists the jobs without a result and leaves out a damaged result file; a merge with
/// none, an unknown job id, `--job` with `--merge`, and `--merge` of another matrix are refused.
#[test]
fn missing_damaged_and_unknown_jobs_are_named() {
    let dir = scratch_dir("sweep_bad");
    let ids = plan_ids(&dir);
    refused(
        &cellflip(&dir, &["--merge", "nowhere"]),
        "--merge nowhere: no result of this matrix's 8 jobs",
    );
    refused(
        &cellflip(&dir, &["--job", "no-such-job"]),
        "--job no-such-job: no such job in this matrix (8 jobs",
    );
    let out = cellflip(&dir, &["--job", &ids[0], "--merge", "x"]);
    assert_eq!(out.status.code(), Some(1), "a usage error");
    ok(&cellflip(&dir, &["-q", "--out", "part", "--job", &ids[0]]));
    ok(&cellflip(&dir, &["-q", "--out", "part", "--job", &ids[1]]));
    let damaged = dir.join("part/runs").join(format!("{}.result", ids[1]));
    let mut bytes = std::fs::read(&damaged).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&damaged, bytes).unwrap();
    let out = cellflip(&dir, &["--merge", "part"]);
    ok(&out);
    let (said, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(said.contains("1 of 8 runs (0 failed, 7 missing)"), "{said}");
    assert!(err.contains(&format!("{}.result", ids[1])), "{err}");
    assert_eq!(untimed_rows(&dir.join("part")).len(), 1);
    // The report says which jobs it lacks, with their estimates.
    let md = std::fs::read_to_string(dir.join("part/report.md")).unwrap();
    assert!(
        md.contains("## Not run\n\n7 jobs of the matrix have no result"),
        "{md}"
    );
    let other = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(["report", "--scenes", "dam-2d", "--merge", "part"])
        .current_dir(&*dir)
        .output()
        .unwrap();
    refused(
        &other,
        "the results there are of another matrix, merged with:\n  cellflip report --merge part \
         --scenes dam-2d,hydrostatic-2d --methods flip,ccp --res 24,32 --duration 0.1    (1 result)",
    );
}

/// `cellflip report ARGS` in `dir`.
fn report(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .arg("report")
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

/// Each result keeps the matrix it was run for: `--merge DIR` without matrix options merges
/// the one DIR holds, refuses a mix naming the command for each, and with options of a matrix
/// DIR holds no result of names the command that merges what it holds.
#[test]
fn a_merge_without_matrix_options_merges_the_matrix_its_results_were_run_for() {
    let dir = scratch_dir("sweep_matrix_kept");
    let job = |matrix: &[&str]| {
        let plan = report(&dir, &[matrix, &["--plan"]].concat());
        ok(&plan);
        let said = String::from_utf8_lossy(&plan.stdout);
        let id = said.lines().find(|l| !l.starts_with('#')).unwrap();
        let id = id.split(' ').next().unwrap().to_string();
        ok(&report(
            &dir,
            &[matrix, &["-q", "--out", "kept", "--job", &id]].concat(),
        ));
    };
    let dam = [
        "--scenes",
        "dam-2d",
        "--methods",
        "flip",
        "--res",
        "24",
        "--duration",
        "0.05",
    ];
    job(&dam);
    let merged = report(&dir, &["--merge", "kept"]);
    ok(&merged);
    let said = String::from_utf8_lossy(&merged.stdout);
    assert!(said.contains("1 of 1 runs (0 failed, 0 missing)"), "{said}");
    assert_eq!(untimed_rows(&dir.join("kept")).len(), 1);
    let dam_command =
        "cellflip report --merge kept --scenes dam-2d --methods flip --res 24 --duration 0.05";
    refused(
        &report(
            &dir,
            &["--scenes", "dam-2d", "--res", "32", "--merge", "kept"],
        ),
        &format!(
            "--merge kept: no result of this matrix's 5 jobs (--scenes dam-2d --res 32) in \
             'kept/runs'; the results there are of another matrix, merged with:\n  \
             {dam_command}    (1 result)"
        ),
    );
    let pool = [
        "--scenes",
        "hydrostatic-2d",
        "--methods",
        "ccp",
        "--res",
        "24",
    ];
    job(&[&pool[..], &["--duration", "0.05"]].concat());
    let pool_command = "cellflip report --merge kept --scenes hydrostatic-2d --methods ccp \
                        --res 24 --duration 0.05";
    refused(
        &report(&dir, &["--merge", "kept"]),
        &format!(
            "--merge kept: its results are of 2 matrices; name one with its options:\n  \
             {dam_command}    (1 result)\n  {pool_command}    (1 result)"
        ),
    );
    ok(&report(&dir, &[&dam[..], &["--merge", "kept"]].concat()));
}

/// A command that exited 1 saying `why` on standard error.
fn refused(out: &Output, why: &str) {
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(said.contains(why), "{said}");
}

/// The plan lists jobs larger than this machine (it is for wherever they run), and a job that
/// fits runs beside them; only the job too large is refused, naming the limit. The limit here
/// is `ulimit -v`, as a cluster node's may be.
#[test]
fn the_plan_lists_jobs_larger_than_this_machine_and_only_those_are_refused() {
    let dir = scratch_dir("sweep_large");
    let matrix = "report --scenes dam-3d --methods ccp --res 24,250 --duration 0.02 --no-stability";
    let under_limit = |rest: &str| {
        let script = format!(
            "ulimit -v 2000000; exec {} {matrix} {rest}",
            env!("CARGO_BIN_EXE_cellflip")
        );
        Command::new("bash")
            .args(["-c", &script])
            .current_dir(&*dir)
            .output()
            .unwrap()
    };
    let plan = under_limit("--plan");
    ok(&plan);
    let said = String::from_utf8_lossy(&plan.stdout);
    let ids: Vec<&str> = said
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(' ').next().unwrap())
        .collect();
    assert_eq!(ids.len(), 2, "{said}");
    assert!(ids[1].contains("r250"), "{ids:?}");
    ok(&under_limit(&format!("-q --out o --job {}", ids[0])));
    refused(
        &under_limit(&format!("-q --out o --job {}", ids[1])),
        "address space limit (ulimit -v",
    );
}

/// The results kept beside each page (docs/results/runs/ and docs/results-paper/runs/, written
/// by `report --docs`) merge on any checkout into the page's own report.csv: the repository
/// holds what the page was made from. (The paper's page since 2026-11-30: before, its runs/
/// held newer runs of its jobs than the page showed; docs/cluster.md.)
#[test]
fn the_results_kept_beside_the_page_merge_into_its_csv() {
    let pages = [
        ("docs/results", &[][..]),
        ("docs/results-paper", &["--matrix", "paper"]),
    ];
    for (page, matrix) in pages {
        let dir = scratch_dir(&format!("kept_beside_{}", page.replace('/', "_")));
        let kept = Path::new(env!("CARGO_MANIFEST_DIR")).join(page);
        let folders = format!("{},{}", dir.display(), kept.display());
        let out = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .args(["report", "--merge", &folders, "-q"])
            .args(matrix)
            .output()
            .unwrap();
        ok(&out);
        let csv = |d: &Path| std::fs::read_to_string(d.join("report.csv")).unwrap();
        assert_eq!(csv(&dir), csv(&kept), "{page}: the merge differs");
    }
}

/// The cost model's estimate of each job of the default matrix against the wall time that job
/// took in the committed results (docs/results/report.csv): within 2x either way, on each kind
/// of machine that ran the page's jobs (its factor, estimate over measured:
/// [`within_on_each_machine`]). The model is fitted on both pages as made on 2026-12-03, their
/// jobs run on one 2-core Intel Xeon (memory copy 13.8-14.2 GB/s) but for the paper page's nine
/// largest, kept from runs on an AMD EPYC (2026-11-29 and -30) and counted at 1.39x their time
/// (`tools/cost-fit.py --speed`; docs/cluster.md, "The cost model").
#[test]
fn the_cost_model_is_within_2x_of_the_default_matrix_as_measured() {
    let ratios = cost_ratios(&["--budget", "90"], "docs/results/report.csv");
    assert_eq!(ratios.len(), 95);
    within_on_each_machine(&ratios, |_| 2.0);
}

/// The same for the jobs of the paper's matrix that have run (docs/results-paper/report.csv,
/// whole runs at the paper's sizes, each job alone), each within the bound its method's fit
/// meets, rounded up to a tenth: issues 73 and 76 ask 1.5x, which Power PIC (1.41x in 2D, 1.20x
/// in 3D), FLIP, IDP and narrow-band FLIP meet, and ccp's 3D jobs (1.99x either way, the half
/// drop over and dam-3d at 100^3 and the large obstacle under) do not (docs/cluster.md, "The
/// cost model", says why).
#[test]
fn the_cost_model_is_within_bounds_of_the_paper_matrix_as_measured() {
    let ratios = cost_ratios(&["--matrix", "paper"], "docs/results-paper/report.csv");
    assert!(ratios.len() >= 40, "{} jobs measured", ratios.len());
    within_on_each_machine(&ratios, |method| match method {
        "flip" => 1.3,
        "ccp" => 2.1,
        "idp" => 1.6,
        "nbflip" => 1.5,
        "powerpic" => 1.5,
        other => panic!("no paper-matrix cost bound for method {other}"),
    });
}

/// The plan's count and steps for FLIP's dam-2d at 50^2, whose emitter pours from 2.5 s until
/// the tank is half full: within 10% of what its run held on average and the steps it took
/// (3,469 particles, 1,150 steps; docs/results/report.csv, 2026-11-29, 480cee2), where the
/// memory estimate's bound counts 6,800 particles and a fall through the whole tank 1,253 steps.
#[test]
fn the_plan_counts_the_particles_a_run_holds_on_average() {
    let args = ["--scenes", "dam-2d", "--methods", "flip", "--res", "50"];
    let (particles, steps) = with_plan(&args, |_, jobs| {
        assert_eq!(jobs.len(), 1);
        (jobs[0].particles, jobs[0].steps)
    });
    let near = |x: f64, measured: f64| (x / measured - 1.0).abs() < 0.1;
    assert!(near(particles, 3469.0), "{particles}");
    assert!(near(steps, 1150.0), "{steps}");
}

/// Calls `f` with the matrix of `cellflip report ARGS` and its plan's jobs (which borrow it).
fn with_plan<T>(args: &[&str], f: impl FnOnce(&[RunSpec], Vec<Job<'_>>) -> T) -> T {
    use clap::Parser;
    let cli = cellflip::cmd::cli::Cli::parse_from([&["cellflip", "report"][..], args].concat());
    let cellflip::cmd::cli::Command::Report(args) = cli.command else {
        unreachable!("a report command")
    };
    let specs = cellflip::cmd::report::matrix(&args).unwrap();
    f(&specs, cellflip::cmd::report::sweep::plan(&specs).unwrap())
}

/// A job's estimated wall seconds over its measured ones.
struct CostRatio {
    id: String,
    method: String,
    /// The kind of machine that ran it (report.csv's `machine`).
    machine: String,
    ratio: f64,
}

/// Each job's [`CostRatio`] for the jobs of the matrix `args` names that have a row in `csv`
/// (from the repository's root). The rows are in the plan's order; a job without a row has not
/// run.
fn cost_ratios(args: &[&str], csv: &str) -> Vec<CostRatio> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let csv = std::fs::read_to_string(root.join(csv)).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let (per_s, scene, method) = (col("ms_per_sim_s"), col("scene"), col("method"));
    let (res, machine) = (col("res"), col("machine"));
    let rows: Vec<Vec<&str>> = lines.map(|l| split_quoted(l)).collect();
    with_plan(args, |_, jobs| {
        let mut jobs: Vec<Option<Job<'_>>> = jobs.into_iter().map(Some).collect();
        rows.iter()
            .map(|row| {
                // The job that names the row's resolution, else the first left at the scene's
                // own size (no resolution named).
                let at = |res: Option<&str>| {
                    jobs.iter().position(|j| {
                        j.as_ref().is_some_and(|j| {
                            let named = j.spec.res.map(|r| r.to_string());
                            (j.spec.label == row[scene] && j.spec.method.name() == row[method])
                                && named.as_deref() == res
                        })
                    })
                };
                let job = (at(Some(row[res])).or_else(|| at(None)))
                    .and_then(|i| jobs[i].take())
                    .unwrap_or_else(|| panic!("{} {}: no such job left", row[scene], row[method]));
                let measured = row[per_s].parse::<f64>().unwrap() / 1e3 * job.sim_secs;
                let estimated = job.cpu_secs / cellflip::cmd::report::sweep::FITTED_THREADS;
                CostRatio {
                    id: job.id,
                    method: row[method].to_string(),
                    machine: row[machine].to_string(),
                    ratio: estimated / measured,
                }
            })
            .collect()
    })
}

/// The speed of each kind of machine that ran a page's jobs against the one the cost model was
/// fitted on: for the jobs of one kind (report.csv's `machine`), the middle (geometrically) of
/// the factors `f` under which every job's `ratio / f` is within its method's bound either way.
/// Fails naming every job beyond its bound at that `f` when there is none, and when `f` is
/// beyond 2x either way (these 2-core machines differ by up to 2x: env). A page is made on
/// whatever machines its sessions have, and the model's CPU-seconds are those of the machine it
/// was fitted on; what the bounds guard is how the model follows the jobs' sizes and methods,
/// which no single factor can mend. A kind that ran few jobs is held less by its own factor (one
/// job alone always fits one): the paper page's AMD EPYC rows are nine jobs of four methods.
fn within_on_each_machine(ratios: &[CostRatio], bound: impl Fn(&str) -> f64) {
    let mut kinds: Vec<&str> = ratios.iter().map(|r| &*r.machine).collect();
    kinds.sort_unstable();
    kinds.dedup();
    for kind in kinds {
        let on: Vec<&CostRatio> = ratios.iter().filter(|r| r.machine == kind).collect();
        let ln_bound = |r: &CostRatio| bound(&r.method).ln();
        let lo = (on.iter()).fold(f64::MIN, |lo, r| lo.max(r.ratio.ln() - ln_bound(r)));
        let hi = (on.iter()).fold(f64::MAX, |hi, r| hi.min(r.ratio.ln() + ln_bound(r)));
        let f = ((lo + hi) / 2.0).exp();
        let beyond: Vec<String> = (on.iter())
            .filter(|r| (r.ratio / f).ln().abs() > ln_bound(r))
            .map(|r| format!("{}: {:.2}", r.id, r.ratio / f))
            .collect();
        assert!(
            beyond.is_empty(),
            "on {kind:?}, estimate / measured over the machine's factor {f:.2}: {beyond:?}"
        );
        assert!(
            (0.5..=2.0).contains(&f),
            "{kind:?} is {f:.2}x the model's machine"
        );
    }
}

/// The paper's matrix: every scene of sec. 8 at the size the paper names (docs/cluster.md), five
/// methods each, ccp at half the two largest, and a plan that says what to ask a cluster for.
#[test]
fn the_paper_matrix_has_the_papers_scenes_at_the_papers_sizes() {
    with_plan(&["--matrix", "paper"], |specs, jobs| {
        let methods = cellflip::methods::MethodKind::ALL.len();
        let mut scenes: Vec<(&str, usize)> =
            jobs.iter().map(|j| (&*j.spec.label, j.cells)).collect();
        scenes.dedup();
        let cells_2d = |n: usize| n * n;
        assert_eq!(
            scenes,
            [
                ("dam-2d", cells_2d(50)),
                ("dam-1ppc-2d", cells_2d(100)),
                ("drop-2d", cells_2d(50)),
                ("compress-2d", cells_2d(50)),
                ("spiral-2d", cells_2d(64)),
                ("falling-obstacle-2d", cells_2d(50)),
                ("falling-obstacle-zero-bc-2d", cells_2d(50)),
                ("large-obstacle-2d", cells_2d(50)),
                ("dam-3d", 100 * 100 * 100),
                ("drop-3d", 300 * 300 * 300),
                ("falling-obstacle-200x300x200", 200 * 300 * 200),
                ("drop-3d", 150 * 150 * 150),
                ("falling-obstacle-200x300x200", 100 * 150 * 100),
                ("large-obstacle-3d", 50 * 75 * 50),
            ]
        );
        // Every method at the paper's sizes; the half sizes with ccp alone (issue 76).
        let half: Vec<&str> = (jobs.iter())
            .filter(|j| j.cells == 150 * 150 * 150 || j.cells == 100 * 150 * 100)
            .map(|j| j.spec.method.name())
            .collect();
        assert_eq!(half, ["ccp", "ccp"]);
        assert_eq!(jobs.len(), (scenes.len() - 2) * methods + 2);
        // Whole runs, and the particle count the paper gives for its largest falling obstacle.
        assert!(specs
            .iter()
            .all(|s| s.duration.is_none() && s.budget.is_none()));
        let flip = |label: &str| {
            let j = jobs
                .iter()
                .find(|j| j.spec.label == label && j.spec.method.name() == "flip");
            j.unwrap().particles
        };
        assert!((flip("falling-obstacle-200x300x200") / 46.7e6 - 1.0).abs() < 0.01);
    });
    let plan = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(["report", "--matrix", "paper", "--plan"])
        .output()
        .unwrap();
    ok(&plan);
    let said = String::from_utf8_lossy(&plan.stdout);
    let total = said
        .lines()
        .find(|l| l.starts_with("# 62 jobs, about "))
        .unwrap_or_default();
    assert!(
        total.contains("CPU-hours in all; the largest memory estimate"),
        "{said}"
    );
}

/// A CSV line's fields, commas inside double quotes kept and a quoted field's quotes taken off
/// (a scene label such as `dam-2d, 20 s` is written quoted).
fn split_quoted(line: &str) -> Vec<&str> {
    fn field(f: &str) -> &str {
        (f.strip_prefix('"').and_then(|f| f.strip_suffix('"'))).unwrap_or(f)
    }
    let (mut out, mut start, mut quoted) = (vec![], 0, false);
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => {
                out.push(field(&line[start..i]));
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(field(&line[start..]));
    out
}
