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
use std::process::{Child, Command, Stdio};
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

/// What the sweep script submitted: its arrays' ids and the merge job's.
struct Submitted {
    arrays: Vec<String>,
    merge: String,
}

/// The sweep script on `matrix` into `dir/out`, with `env` added to its environment. The ids
/// are read from what the script says, not worked out from each other: tests run at once, and
/// two sweeps' `sbatch` calls can take turns.
fn sweep(conf: &str, dir: &Path, matrix: &[&str], env: &[(&str, &str)]) -> Submitted {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm/sweep.sh");
    let out = Command::new(script)
        .args(["--out", "out"])
        .args(matrix)
        .current_dir(dir)
        .env("SLURM_CONF", conf)
        .env("CELLFLIP", env!("CARGO_BIN_EXE_cellflip"))
        .env("CELLFLIP_CPUS", "1")
        .envs(env.iter().copied())
        .output()
        .unwrap();
    ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    let merge = said.lines().last().expect("the merge job's id").to_string();
    // `array 116: 1 jobs, --mem=512M --time=1 min`, one line per array, on stderr.
    let arrays = String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter_map(|l| l.strip_prefix("array ")?.split_once(':'))
        .map(|(id, _)| id.to_string())
        .collect();
    Submitted { arrays, merge }
}

/// A job's state (`scontrol show job`), e.g. PENDING, RUNNING, COMPLETED.
fn state(conf: &str, job: &str) -> String {
    let shown = slurm(conf, "scontrol", &["show", "job", job]);
    let field = shown
        .split_whitespace()
        .find_map(|f| f.strip_prefix("JobState="));
    field.unwrap_or_default().to_string()
}

/// The states of a job that has ended (and was not requeued).
const ENDED: [&str; 6] = [
    "COMPLETED",
    "FAILED",
    "CANCELLED",
    "TIMEOUT",
    "NODE_FAIL",
    "OUT_OF_MEMORY",
];

/// Waits until `job` is in one of `states` (at most `secs`); `context` is added to a failure's
/// message (e.g. a task's log).
fn wait_for(conf: &str, job: &str, states: &[&str], secs: u64, context: &dyn Fn() -> String) {
    let t0 = Instant::now();
    loop {
        let s = state(conf, job);
        if states.contains(&s.as_str()) {
            return;
        }
        assert!(
            !ENDED.contains(&s.as_str()),
            "job {job} ended {s}, not {states:?}\n{}",
            context()
        );
        assert!(
            t0.elapsed().as_secs() < secs,
            "job {job} still {s} after {secs} s\n{}",
            context()
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
    let merge = sweep(&conf, &dir, &MATRIX[1..], &[]).merge;
    let whole = one_process(&dir, &MATRIX);
    wait_for(&conf, &merge, &["COMPLETED"], 300, &String::new);
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

/// A time limit the warning signal could come at once under (Slurm may send it up to a minute
/// early) is refused before anything is submitted: each run of the task would be warned at its
/// start and never get far. No cluster needed.
#[test]
fn a_time_limit_within_the_warning_is_refused() {
    let dir = scratch_dir("slurm_limit_refused");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm/sweep.sh");
    let out = Command::new(script)
        .args(["--out", "out"])
        .args(&MATRIX[1..])
        .current_dir(&*dir)
        .env("CELLFLIP", env!("CARGO_BIN_EXE_cellflip"))
        .env("CELLFLIP_TIME_MINUTES", "3")
        .env("PATH", "/usr/bin:/bin")
        // Without the refusal, nothing must reach the cluster that `.ci/run` names.
        .env_remove("SLURM_CONF")
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(
        said.contains("a time limit of 3 min leaves no time before the warning"),
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

/// A task that reaches its real time limit: the sweep with a one-minute `--time` and no warning
/// signal, on a job that takes about two minutes on one CPU, so that Slurm's own limit stops
/// it (slurmctld checks limits every 30 s: 60 to 90 s after the start). Nothing here sends a
/// signal; slurmstepd's line in the log says it was the limit. The script must see it, wait for
/// the checkpoint and requeue the task within KillWait (15 s on the local cluster); the task
/// then goes on from the checkpoint and ends as the job run straight.
#[test]
fn a_task_stopped_by_its_time_limit_requeues_itself_and_goes_on() {
    let Some(conf) = cluster() else { return };
    let dir = scratch_dir("slurm_time_limit");
    // 114 s on one thread of a 2-core AMD EPYC (2026-11-28, other work running): past the
    // limit's latest check with a quarter to spare.
    let matrix = one_job_matrix("225", "8");
    let limit = [
        ("CELLFLIP_TIME_MINUTES", "1"),
        ("CELLFLIP_SIGNAL_SECS", "0"),
    ];
    let job = OneJob::submit(&conf, &dir, &matrix, &limit);
    let shown = slurm(&conf, "scontrol", &["show", "job", &job.task]);
    assert!(shown.contains("TimeLimit=00:01:00"), "{shown}");
    let straight = job.run_straight(&matrix);
    // The second run's limit is raised once it runs: on a busy machine the rest of the job can
    // outlast a second minute, and a third run would show nothing new, only add a minute or more.
    job.wait_in_log("SLURM_RESTART_COUNT=1", 240);
    let raise = format!("JobId={}", job.task);
    slurm(&conf, "scontrol", &["update", &raise, "TimeLimit=10"]);
    let said = job.finish(straight);
    // slurmstepd's line, e.g. `*** JOB 27 ON vm CANCELLED AT 2026-11-28T21:01:45 DUE TO TIME
    // LIMIT ***`, which a cancel or a signal sent by hand does not write.
    let by_limit = format!("*** JOB {} ON ", job.task_job_id());
    assert!(
        said.lines()
            .any(|l| l.contains(&by_limit) && l.ends_with("DUE TO TIME LIMIT ***")),
        "the limit did not stop the task:\n{said}"
    );
    assert!(
        said.contains("stopped by the time limit: checkpoint written, requeue"),
        "{said}"
    );
    assert!(!said.contains("near the time limit"), "{said}");
    assert!(!said.contains("SLURM_RESTART_COUNT=2"), "{said}");
    job.ends_as_run_straight(&matrix, &said);
}

/// `--scenes dam-2d --methods flip` at `res` cells for `duration` simulated seconds.
fn one_job_matrix(res: &'static str, duration: &'static str) -> [&'static str; 9] {
    [
        "--scenes",
        "dam-2d",
        "--methods",
        "flip",
        "--res",
        res,
        "--duration",
        duration,
        "--no-stability",
    ]
}

/// A run of the job outside Slurm, ended if the test fails before it does (it would otherwise
/// go on for minutes after the test, on a machine the other tests share).
struct Straight(Child);

impl Drop for Straight {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A one-job sweep on the cluster.
struct OneJob {
    conf: String,
    dir: std::path::PathBuf,
    /// The job's id in the plan.
    id: String,
    /// Its array task, `<array>_1`.
    task: String,
    merge: String,
}

impl OneJob {
    /// The sweep script on `matrix` (one job), with `env` for the script; once its task runs
    /// cellflip (its log says SLURM_RESTART_COUNT=0).
    fn submit(conf: &str, dir: &Path, matrix: &[&str], env: &[(&str, &str)]) -> OneJob {
        let Submitted { arrays, merge } = sweep(conf, dir, matrix, env);
        assert_eq!(arrays.len(), 1, "{arrays:?}");
        let plan = std::fs::read_to_string(dir.join("out/slurm/plan.txt")).unwrap();
        let id = plan
            .lines()
            .find(|l| !l.starts_with('#'))
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .to_string();
        let task = format!("{}_1", arrays[0]);
        let job = OneJob {
            conf: conf.to_string(),
            dir: dir.to_path_buf(),
            id,
            task,
            merge,
        };
        wait_for(conf, &job.task, &["RUNNING"], 120, &|| job.log());
        job.wait_in_log("SLURM_RESTART_COUNT=0", 60);
        job
    }

    /// The task's log, all its runs (the merge's left out).
    fn log(&self) -> String {
        std::fs::read_dir(self.dir.join("out/slurm/logs"))
            .unwrap()
            .flatten()
            .filter(|e| !e.file_name().to_string_lossy().starts_with("merge"))
            .map(|e| std::fs::read_to_string(e.path()).unwrap())
            .collect()
    }

    /// Waits until the task's log says `what` (at most `secs`, and not after the task ended).
    fn wait_in_log(&self, what: &str, secs: u64) {
        let t0 = Instant::now();
        while !self.log().contains(what) {
            let s = state(&self.conf, &self.task);
            assert!(
                !ENDED.contains(&s.as_str()) && t0.elapsed().as_secs() < secs,
                "the task's log does not say '{what}' ({s} after {} s):\n{}",
                t0.elapsed().as_secs(),
                self.log()
            );
            std::thread::sleep(Duration::from_millis(300));
        }
    }

    /// The task's own job id (`SLURM_JOB_ID`, which slurmstepd's lines name).
    fn task_job_id(&self) -> String {
        let shown = slurm(&self.conf, "scontrol", &["show", "job", &self.task]);
        let field = shown
            .split_whitespace()
            .find_map(|f| f.strip_prefix("JobId="));
        field.expect("scontrol shows JobId").to_string()
    }

    /// The job run straight into `straight/`, outside Slurm, while the sweep goes on.
    fn run_straight(&self, matrix: &[&str]) -> Straight {
        let err = std::fs::File::create(self.dir.join("straight.err")).unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .arg("report")
            .args(matrix)
            .args(["-q", "--out", "straight", "--job", &self.id])
            .current_dir(&self.dir)
            .stdout(Stdio::null())
            .stderr(err)
            .spawn()
            .unwrap();
        Straight(child)
    }

    /// Waits for the straight run and the merge: the task's log.
    fn finish(&self, mut straight: Straight) -> String {
        let status = straight.0.wait().unwrap();
        let err = std::fs::read_to_string(self.dir.join("straight.err")).unwrap();
        assert!(status.success(), "the straight run: {status}: {err}");
        // A requeued job waits for its old credential to expire (10 s on the local cluster,
        // whose configuration says so; 120 s by default) before it runs again.
        wait_for(&self.conf, &self.merge, &["COMPLETED"], 300, &|| self.log());
        self.log()
    }

    /// Checks that the task restarted (SLURM_RESTART_COUNT=1 in its log, `said`), went on from
    /// its checkpoint and ended with the figures of the straight run.
    fn ends_as_run_straight(&self, matrix: &[&str], said: &str) {
        assert!(said.contains("SLURM_RESTART_COUNT=1"), "{said}");
        assert!(said.contains("resuming dam-2d flip from"), "{said}");
        let merged = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .arg("report")
            .args(matrix)
            .args(["-q", "--merge", "straight"])
            .current_dir(&self.dir)
            .output()
            .unwrap();
        ok(&merged);
        let (a, b) = (
            untimed_rows(&self.dir.join("straight")),
            untimed_rows(&self.dir.join("out")),
        );
        assert_eq!(a.len(), 1);
        assert_eq!(a, b);
    }
}

/// A one-job sweep whose task is stopped by `stop` (a Slurm command, the task's id appended)
/// while it runs: it must restart, resume and end as the job run straight.
fn requeued(conf: &str, test: &str, stop: &[&str]) {
    let dir = scratch_dir(test);
    let matrix = one_job_matrix("100", "10");
    let job = OneJob::submit(conf, &dir, &matrix, &[]);
    std::thread::sleep(Duration::from_secs(3));
    slurm(conf, stop[0], &[&stop[1..], &[job.task.as_str()]].concat());
    let straight = job.run_straight(&matrix);
    let said = job.finish(straight);
    job.ends_as_run_straight(&matrix, &said);
}
