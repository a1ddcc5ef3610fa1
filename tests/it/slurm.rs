//! The sweep on a real Slurm (tools/slurm/, docs/cluster.md): submitted by the sweep script,
//! run as array tasks and merged by a dependent job into the one-process report; a task
//! requeued while it runs goes on from its checkpoint and ends as the job run straight.
//!
//! These need a running cluster: `.ci/run` starts a one-node one with
//! `tools/slurm/local-cluster.sh start` (Debian's packages, as root) before the tests. Without
//! one (`sinfo` does not answer), each test prints that it skipped and checks nothing, so that
//! a `cargo test --release` without Slurm passes; `CELLFLIP_REQUIRE_SLURM=1` (set by `.ci/run`)
//! makes a missing cluster a failure instead.

use crate::common::{ok, scratch_dir};
use crate::sweep::{untimed_rows, MATRIX};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// The local cluster's configuration, if one answers.
fn cluster() -> Option<String> {
    let conf =
        std::env::var("SLURM_CONF").unwrap_or_else(|_| "/tmp/cellflip-slurm/slurm.conf".into());
    let answers = Command::new("sinfo")
        .args(["-h", "-o", "%t"])
        .env("SLURM_CONF", &conf)
        .output()
        .is_ok_and(|o| o.status.success() && !o.stdout.is_empty());
    if !answers && std::env::var_os("CELLFLIP_REQUIRE_SLURM").is_some() {
        panic!("CELLFLIP_REQUIRE_SLURM is set and no Slurm answers at {conf}");
    }
    if !answers {
        eprintln!("skipped: no Slurm answers (start one with tools/slurm/local-cluster.sh start)");
    }
    answers.then_some(conf)
}

/// A Slurm client command with the cluster's configuration.
fn slurm(conf: &str, program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .env("SLURM_CONF", conf)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{program} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

/// The sweep script on `matrix` into `dir/out`: the merge job's id.
fn sweep(conf: &str, dir: &Path, matrix: &[&str]) -> String {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm/sweep.sh");
    let out = Command::new(script)
        .args(["--out", "out"])
        .args(matrix)
        .current_dir(dir)
        .env("SLURM_CONF", conf)
        .env("CELLFLIP", env!("CARGO_BIN_EXE_cellflip"))
        .env("CELLFLIP_CPUS", "1")
        .output()
        .unwrap();
    ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    said.lines().last().expect("the merge job's id").to_string()
}

/// A job's state (`scontrol show job`), e.g. PENDING, RUNNING, COMPLETED.
fn state(conf: &str, job: &str) -> String {
    let shown = slurm(conf, "scontrol", &["show", "job", job]);
    let field = shown
        .split_whitespace()
        .find_map(|f| f.strip_prefix("JobState="));
    field.unwrap_or_default().to_string()
}

/// Waits until `job` is in one of `states` (at most `secs`).
fn wait_for(conf: &str, job: &str, states: &[&str], secs: u64) {
    let t0 = Instant::now();
    loop {
        let s = state(conf, job);
        if states.contains(&s.as_str()) {
            return;
        }
        let ended = [
            "COMPLETED",
            "FAILED",
            "CANCELLED",
            "TIMEOUT",
            "NODE_FAIL",
            "OUT_OF_MEMORY",
        ];
        assert!(
            !ended.contains(&s.as_str()),
            "job {job} ended {s}, not {states:?}"
        );
        assert!(
            t0.elapsed().as_secs() < secs,
            "job {job} still {s} after {secs} s"
        );
        std::thread::sleep(Duration::from_millis(300));
    }
}

/// The one-process report of `matrix` in `dir/whole`.
fn one_process(dir: &Path, matrix: &[&str]) -> std::path::PathBuf {
    let out = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(matrix)
        .args(["-q", "--out", "whole"])
        .current_dir(dir)
        .output()
        .unwrap();
    ok(&out);
    dir.join("whole")
}

#[test]
fn a_sweep_on_slurm_merges_into_the_one_process_report() {
    let Some(conf) = cluster() else { return };
    let dir = scratch_dir("slurm_sweep");
    let merge = sweep(&conf, &dir, &MATRIX[1..]);
    let whole = one_process(&dir, &MATRIX);
    wait_for(&conf, &merge, &["COMPLETED"], 300);
    let (a, b) = (untimed_rows(&whole), untimed_rows(&dir.join("out")));
    assert_eq!(a.len(), 8);
    assert_eq!(a, b);
}

/// `--only` that matches no job of the plan is refused before anything is submitted (no
/// cluster needed: the script stops before `sbatch`).
#[test]
fn a_sweep_of_no_job_is_refused() {
    let dir = scratch_dir("slurm_only");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm/sweep.sh");
    let out = Command::new(script)
        .args(["--out", "out", "--only", "^no-such-job-"])
        .args(&MATRIX[1..])
        .current_dir(&*dir)
        .env("CELLFLIP", env!("CARGO_BIN_EXE_cellflip"))
        .env("PATH", "/usr/bin:/bin")
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(
        said.contains("no job of the plan matches --only '^no-such-job-'"),
        "{said}"
    );
    assert!(!dir.join("out/slurm/logs").read_dir().unwrap().any(|_| true));
}

/// A task requeued while it runs (`scontrol requeue`, as on preemption) stops with a
/// checkpoint, runs again (SLURM_RESTART_COUNT=1), goes on from the checkpoint and ends with
/// the figures of the job run straight.
#[test]
fn a_requeued_task_goes_on_from_its_checkpoint_and_ends_as_run_straight() {
    let Some(conf) = cluster() else { return };
    requeued(&conf, "slurm_requeue", &["scontrol", "requeue"]);
}

/// The same for a task near its time limit: Slurm's `--signal=B:USR1@N` (sent here at once with
/// `scancel --signal=USR1 --batch`) makes it checkpoint and requeue itself.
#[test]
fn a_task_near_its_time_limit_checkpoints_requeues_itself_and_goes_on() {
    let Some(conf) = cluster() else { return };
    requeued(
        &conf,
        "slurm_near_limit",
        &["scancel", "--signal=USR1", "--batch"],
    );
}

/// A one-job sweep whose task is stopped by `stop` (a Slurm command, the task's id appended)
/// while it runs: it must restart, resume and end as the job run straight.
fn requeued(conf: &str, test: &str, stop: &[&str]) {
    let conf = conf.to_string();
    let dir = scratch_dir(test);
    let matrix = [
        "--scenes",
        "dam-2d",
        "--methods",
        "flip",
        "--res",
        "100",
        "--duration",
        "10",
        "--no-stability",
    ];
    let merge = sweep(&conf, &dir, &matrix);
    let plan = std::fs::read_to_string(dir.join("out/slurm/plan.txt")).unwrap();
    let id = plan
        .lines()
        .find(|l| !l.starts_with('#'))
        .unwrap()
        .split(' ')
        .next()
        .unwrap();
    let log = |dir: &Path| -> String {
        std::fs::read_dir(dir.join("out/slurm/logs"))
            .unwrap()
            .flatten()
            .filter(|e| !e.file_name().to_string_lossy().starts_with("merge"))
            .map(|e| std::fs::read_to_string(e.path()).unwrap())
            .collect()
    };
    let task = format!("{}_1", merge.parse::<u64>().unwrap() - 1);
    wait_for(&conf, &task, &["RUNNING"], 120);
    let t0 = Instant::now();
    while !log(&dir).contains("SLURM_RESTART_COUNT=0") {
        assert!(
            t0.elapsed().as_secs() < 60,
            "the task never started cellflip"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_secs(3));
    slurm(&conf, stop[0], &[&stop[1..], &[task.as_str()]].concat());
    // A requeued job waits for its old credential to expire (10 s on the local cluster, whose
    // configuration says so; 120 s by default) before it runs again.
    let straight = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .arg("report")
        .args(matrix)
        .args(["-q", "--out", "straight", "--job", id])
        .current_dir(&*dir)
        .output()
        .unwrap();
    ok(&straight);
    wait_for(&conf, &merge, &["COMPLETED"], 300);
    let said = log(&dir);
    assert!(said.contains("SLURM_RESTART_COUNT=1"), "{said}");
    assert!(said.contains("resuming dam-2d flip from"), "{said}");
    let merged = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .arg("report")
        .args(matrix)
        .args(["-q", "--merge", "straight"])
        .current_dir(&*dir)
        .output()
        .unwrap();
    ok(&merged);
    let (a, b) = (
        untimed_rows(&dir.join("straight")),
        untimed_rows(&dir.join("out")),
    );
    assert_eq!(a.len(), 1);
    assert_eq!(a, b);
}
