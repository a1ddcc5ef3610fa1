//! Checkpoints (issue 55): K steps, a checkpoint, a simulation restored from it and the steps
//! after K give the same data as the run never stopped: every later step's state and report
//! digest ([`crate::common::digest_state`], [`crate::common::digest_report`]) bit for bit, for
//! every method in 2D and 3D, ccp's band variants, the obstacle modes, an emitter mid-pour,
//! and a run that continues on another number of threads.

use crate::common::{band_flags, digest_report, digest_state, load, Digest};
use cellflip::methods::ccp::BandMode;
use cellflip::methods::MethodKind;
use cellflip::runner::{Limit, Runner};
use cellflip::scene::{Overrides, Scene};
use cellflip::snapshot::{Reader, Writer};
use cellflip::stages::solids::ObstacleMode;
use cellflip::step::Simulation;

/// The digest of the state after a step, with that step's report when there is one.
fn digest_of<const D: usize>(
    sim: &Simulation<D>,
    rep: Option<&cellflip::step::StepReport<D>>,
) -> String {
    let mut d = Digest::default();
    if let Some(rep) = rep {
        digest_report(&mut d, rep);
    }
    digest_state(&mut d, sim);
    d.hex()
}

/// Runs until `limit`, giving each step's digest.
fn steps<const D: usize>(runner: &mut Runner<D>, limit: Limit) -> Vec<String> {
    let mut out = vec![];
    runner
        .run(
            limit,
            || false,
            |sim, rep| {
                out.push(digest_of(sim, Some(rep)));
                Ok::<_, anyhow::Error>(())
            },
        )
        .unwrap_or_else(|e| panic!("{e:#}"));
    out
}

/// The simulation a checkpoint of `sim` holds, through the file's bytes.
fn through_checkpoint<const D: usize>(scene: &Scene, sim: &Simulation<D>) -> Simulation<D> {
    let mut w = Writer::default();
    sim.save(&mut w);
    let mut bytes = vec![];
    w.write_to(&mut bytes).unwrap();
    let r = Reader::from_bytes(bytes).unwrap();
    Simulation::restore(scene.config::<D>(), &scene.method, &r).unwrap()
}

/// On `threads[0]` threads: a run to `first`, then `more` steps, straight; and the same run
/// stopped at `first`, checkpointed, restored and continued on `threads[1]` threads. Their
/// states at the checkpoint and every step after it are equal, bit for bit. Returns the
/// particles ever seeded or emitted at the checkpoint and at the end.
fn same_run<const D: usize>(
    scene: &Scene,
    first: Limit,
    more: u64,
    threads: [usize; 2],
) -> [usize; 2] {
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let (straight, at_k, k, resumed) = pool(threads[0]).install(|| {
        let new = || Simulation::<D>::new(scene.config::<D>(), &scene.method);
        let mut a = Runner::new(new());
        steps(&mut a, first);
        let k = a.sim.state.steps;
        let straight = steps(&mut a, Limit::Steps(k + more));
        let mut b = Runner::new(new());
        steps(&mut b, first);
        let restored = through_checkpoint(scene, &b.sim);
        let at_k = [digest_of(&b.sim, None), digest_of(&restored, None)];
        (straight, at_k, k, restored)
    });
    let label = format!(
        "{} {} on {threads:?} threads",
        scene.name(),
        scene.method.kind.name()
    );
    assert_eq!(
        at_k[0], at_k[1],
        "{label}: the restored state differs at step {k}"
    );
    let total_at_k = resumed.state.total_particles;
    let mut c = Runner::new(resumed);
    let continued = pool(threads[1]).install(|| steps(&mut c, Limit::Steps(k + more)));
    assert_eq!(
        straight.len() as u64,
        more,
        "{label}: the straight run ended early"
    );
    for (i, (a, b)) in straight.iter().zip(&continued).enumerate() {
        assert_eq!(
            a,
            b,
            "{label}: step {} differs after a checkpoint at step {k}",
            k + 1 + i as u64
        );
    }
    assert_eq!(
        continued.len(),
        straight.len(),
        "{label}: steps after the checkpoint"
    );
    [total_at_k, c.sim.state.total_particles]
}

fn scene(
    name: &str,
    method: MethodKind,
    band: Option<BandMode>,
    obstacle: Option<ObstacleMode>,
) -> Scene {
    let o = Overrides {
        method: Some(method),
        flags: band_flags(band),
        obstacle,
        ..Default::default()
    };
    let s = load(name, &o);
    if s.dim() == 2 {
        return s;
    }
    // 3D at 16 cells along the shortest axis, as the golden digests.
    let (lo, hi) = (s.dims.iter().min().unwrap(), s.dims.iter().max().unwrap());
    load(
        name,
        &Overrides {
            cells: Some(16 * hi / lo),
            ..o
        },
    )
}

#[test]
fn every_method_continues_a_2d_run_bit_for_bit() {
    for &m in MethodKind::ALL {
        same_run::<2>(
            &scene("dam-2d", m, None, None),
            Limit::Steps(20),
            12,
            [2, 2],
        );
    }
}

#[test]
fn every_method_continues_a_3d_run_bit_for_bit() {
    for &m in MethodKind::ALL {
        same_run::<3>(&scene("dam-3d", m, None, None), Limit::Steps(5), 4, [2, 2]);
    }
}

#[test]
fn every_band_variant_continues_bit_for_bit() {
    for b in [
        BandMode::None,
        BandMode::Paths,
        BandMode::OneWay,
        BandMode::Full,
    ] {
        same_run::<2>(
            &scene("dam-2d", MethodKind::Ccp, Some(b), None),
            Limit::Steps(5),
            4,
            [2, 2],
        );
    }
}

#[test]
fn obstacles_continue_bit_for_bit_in_every_mode() {
    use ObstacleMode::{Couple, Ignore, Naive};
    for (m, mode) in [
        (MethodKind::Ccp, Couple),
        (MethodKind::Flip, Naive),
        (MethodKind::Flip, Ignore),
    ] {
        let s = scene("falling-obstacle-2d", m, None, Some(mode));
        same_run::<2>(&s, Limit::Steps(40), 10, [2, 2]);
    }
    // nbflip carves its obstacles (their cells at the last rebuild come from the restored
    // solids): stopped after the box reached the water.
    for mode in [Naive, Ignore] {
        let s = scene("falling-obstacle-2d", MethodKind::Nbflip, None, Some(mode));
        same_run::<2>(&s, Limit::Steps(35), 25, [2, 2]);
    }
    let s = scene("large-obstacle-3d", MethodKind::Ccp, None, Some(Couple));
    same_run::<3>(&s, Limit::Steps(6), 4, [2, 2]);
}

/// The dam's emitter pours from 2.5 s: stopped while it pours, the run goes on pouring.
#[test]
fn an_emitter_mid_pour_continues_bit_for_bit() {
    let s = scene("dam-2d", MethodKind::Ccp, None, None);
    let [at_k, at_end] = same_run::<2>(&s, Limit::SimSeconds(2.55), 10, [2, 2]);
    assert!(
        at_end > at_k,
        "nothing was poured after the checkpoint ({at_k} particles)"
    );
}

/// Runs are the same on any number of threads: a run stopped on two continues on one, and
/// the other way round.
#[test]
fn a_run_continues_bit_for_bit_on_another_thread_count() {
    same_run::<2>(
        &scene("dam-2d", MethodKind::Ccp, None, None),
        Limit::Steps(10),
        8,
        [2, 1],
    );
    same_run::<3>(
        &scene("dam-3d", MethodKind::Nbflip, None, None),
        Limit::Steps(4),
        3,
        [1, 2],
    );
}

// The command line: writing, resuming, the recording going on, signals and bad input.

use crate::common::{cellflip, chunks, ok, scratch_dir};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// Everything a recording holds per entity and step, as text, but what differs between two
/// runs of the same data: the wall times (`metrics/time/*`, the solver's and the band's ms).
fn recorded(path: &Path) -> BTreeMap<(String, i64), Vec<String>> {
    let timed = |e: &str| e.starts_with("metrics/time/") || e.ends_with("_ms");
    let mut out: BTreeMap<(String, i64), Vec<String>> = BTreeMap::new();
    for c in chunks(path, rerun::StoreKind::Recording) {
        let entity = c
            .entity_path()
            .to_string()
            .trim_start_matches('/')
            .to_string();
        let Some(steps) = c.timelines().get(&"step".into()) else {
            continue;
        };
        if timed(&entity) {
            continue;
        }
        let steps = steps.times_raw().to_vec();
        for component in c.components().keys() {
            let list = c.components().get_array(*component).unwrap();
            for (row, step) in steps.iter().enumerate() {
                let cell = format!("{component}: {:?}", list.value(row));
                out.entry((entity.clone(), *step)).or_default().push(cell);
            }
        }
    }
    out.values_mut().for_each(|v| v.sort());
    out
}

/// How many chunks of static data (no timeline) each entity has, blueprint included: a
/// recording that goes on in its file sends none again (the viewer lost the markings' class
/// colours when a second layout and new chunks of the same static data followed the first).
fn static_chunks(path: &Path) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for kind in [rerun::StoreKind::Recording, rerun::StoreKind::Blueprint] {
        for c in chunks(path, kind)
            .iter()
            .filter(|c| c.timelines().is_empty())
        {
            *out.entry(format!("{kind:?} {}", c.entity_path()))
                .or_default() += 1;
        }
    }
    out
}

/// The steps at which `metrics/volume_percent` was recorded, in file order.
fn volume_steps(path: &Path) -> Vec<i64> {
    let mut steps = vec![];
    for c in chunks(path, rerun::StoreKind::Recording) {
        if c.entity_path().to_string().trim_start_matches('/') == "metrics/volume_percent" {
            steps.extend_from_slice(c.timelines().get(&"step".into()).unwrap().times_raw());
        }
    }
    steps
}

/// The complete checkpoints in `dir`, by name.
fn checkpoints(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.retain(|n| n.starts_with("step-") && n.ends_with(".ckpt"));
    v.sort();
    v
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A run stopped after its step 6 and resumed to step 14 records what the run of 14 steps
/// straight records, at every step, in one file with no step twice; with `--save`, the
/// continuation goes to a new file of the same recording id.
#[test]
fn a_resumed_run_s_recording_is_the_run_never_stopped() {
    let dir = scratch_dir("ckpt-recording");
    let (straight, split) = (dir.join("straight.rrd"), dir.join("split.rrd"));
    let run = |extra: &[&str]| {
        let mut a = vec!["run", "falling-obstacle-2d", "-q"];
        a.extend_from_slice(extra);
        cellflip(&a)
    };
    ok(&run(&[
        "--steps",
        "14",
        "--save",
        straight.to_str().unwrap(),
    ]));
    let s = split.to_str().unwrap();
    ok(&run(&[
        "--steps",
        "6",
        "--save",
        s,
        "--checkpoint-every",
        "1000",
    ]));
    let ckdir = dir.join("split.checkpoints");
    assert_eq!(checkpoints(&ckdir), ["step-00000006.ckpt"]);
    let resume = |extra: &[&str]| {
        let mut a = vec!["run", "--resume", ckdir.to_str().unwrap(), "-q"];
        a.extend_from_slice(extra);
        cellflip(&a)
    };
    ok(&resume(&["--steps", "14"]));
    assert_eq!(volume_steps(&split), (0..=14).collect::<Vec<_>>());
    assert_eq!(static_chunks(&straight), static_chunks(&split));
    let (a, b) = (recorded(&straight), recorded(&split));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, v) in &a {
        assert_eq!(v, &b[k], "{k:?} differs");
    }
    // The continuation of the checkpoint at step 14 into a file of its own, same recording id.
    let more = dir.join("more.rrd");
    ok(&resume(&[
        "--steps",
        "16",
        "--save",
        more.to_str().unwrap(),
    ]));
    assert_eq!(volume_steps(&more), [15, 16]);
    let id = |p: &Path| {
        use rerun::external::re_log_encoding::DecoderApp;
        let f = std::io::BufReader::new(std::fs::File::open(p).unwrap());
        let ids: std::collections::BTreeSet<String> = DecoderApp::decode_lazy(f)
            .filter_map(|m| match m.unwrap() {
                rerun::log::LogMsg::ArrowMsg(store, _)
                    if store.kind() == rerun::StoreKind::Recording =>
                {
                    Some(store.recording_id().to_string())
                }
                _ => None,
            })
            .collect();
        assert_eq!(ids.len(), 1, "{}: {ids:?}", p.display());
        ids.into_iter().next().unwrap()
    };
    assert_eq!(id(&split), id(&more));
    assert_ne!(id(&split), id(&straight));
}

/// A long run of dam-2d with checkpoints, its stderr piped.
fn start_long_run(out: &Path, every: &str) -> Child {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args([
            "run",
            "dam-2d",
            "--duration",
            "1000",
            "-q",
            "--checkpoint-every",
            every,
        ])
        .arg("--save")
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until `dir` holds a complete checkpoint (60 s at most).
fn wait_for_checkpoint(dir: &Path) {
    let t0 = std::time::Instant::now();
    while checkpoints(dir).is_empty() {
        assert!(
            t0.elapsed().as_secs() < 60,
            "no checkpoint in {}",
            dir.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

fn kill(child: &Child, signal: &str) {
    let status = Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status();
    assert!(status.unwrap().success());
}

fn step_of(checkpoint: &str) -> i64 {
    checkpoint[5..13].parse().unwrap()
}

/// Resumes from the newest checkpoint in `ckdir` up to step `to`: the recording `out` then
/// holds every step from 0 to `to` once, in order.
fn resume_records_every_step_once(ckdir: &Path, out: &Path, to: i64) {
    let steps = to.to_string();
    let dir = ckdir.to_str().unwrap();
    ok(&cellflip(&[
        "run", "--resume", dir, "--steps", &steps, "-q",
    ]));
    assert_eq!(volume_steps(out), (0..=to).collect::<Vec<_>>());
}

/// SIGTERM with checkpoints on: a checkpoint of the last finished step, the recording up to
/// it, exit 143; the run resumed goes on from there and its recording has every step once.
/// SIGUSR1 writes a checkpoint and the run goes on.
#[test]
fn signals_write_a_checkpoint_and_the_run_goes_on_from_it() {
    let dir = scratch_dir("ckpt-signals");
    let out = dir.join("dam.rrd");
    let ckdir = dir.join("dam.checkpoints");
    let mut child = start_long_run(&out, "1000");
    std::thread::sleep(std::time::Duration::from_millis(1500));
    kill(&child, "USR1");
    wait_for_checkpoint(&ckdir);
    let first = checkpoints(&ckdir);
    std::thread::sleep(std::time::Duration::from_millis(500));
    assert!(child.try_wait().unwrap().is_none(), "SIGUSR1 ended the run");
    kill(&child, "TERM");
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(143), "{}", stderr(&o));
    let after = checkpoints(&ckdir);
    assert_eq!(
        after.len(),
        2,
        "the USR1 checkpoint and the SIGTERM one: {after:?}"
    );
    assert!(
        after[1] > first[0],
        "the run went on after SIGUSR1: {first:?} {after:?}"
    );
    let stopped = step_of(&after[1]);
    assert_eq!(
        *volume_steps(&out).last().unwrap(),
        stopped,
        "the recording ends at the checkpoint"
    );
    resume_records_every_step_once(&ckdir, &out, stopped + 3);
}

/// A run killed outright (SIGKILL: no checkpoint at the end) recorded steps past its last
/// checkpoint; resumed, the recording is cut back to the checkpoint and no step is twice.
#[test]
fn a_killed_run_resumes_from_its_last_checkpoint_with_no_step_recorded_twice() {
    let dir = scratch_dir("ckpt-kill");
    let out = dir.join("dam.rrd");
    let ckdir = dir.join("dam.checkpoints");
    let mut child = start_long_run(&out, "0.05");
    wait_for_checkpoint(&ckdir);
    std::thread::sleep(std::time::Duration::from_millis(700));
    child.kill().unwrap();
    child.wait().unwrap();
    let last = step_of(checkpoints(&ckdir).last().unwrap());
    resume_records_every_step_once(&ckdir, &out, last + 4);
    assert!(checkpoints(&ckdir).len() <= 2, "{:?}", checkpoints(&ckdir));
}

/// A checkpoint to damage: dam-2d after 3 steps.
fn a_checkpoint(dir: &Path) -> PathBuf {
    let ckdir = dir.join("ck");
    let o = cellflip(&[
        "run",
        "dam-2d",
        "--steps",
        "3",
        "-q",
        "--no-record",
        "--checkpoint-every",
        "1000",
        "--checkpoint-dir",
        ckdir.to_str().unwrap(),
    ]);
    ok(&o);
    ckdir.join("step-00000003.ckpt")
}

/// Each bad input stops with exit 1 before anything is written, naming the file and the reason.
#[test]
fn bad_checkpoints_and_options_are_refused_naming_the_file_and_the_reason() {
    let dir = scratch_dir("ckpt-refused");
    let good = a_checkpoint(&dir);
    let bytes = std::fs::read(&good).unwrap();
    let variant = |name: &str, b: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, b).unwrap();
        p
    };
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 1;
    let mut version = bytes.clone();
    version[8] = 9;
    let cases: Vec<(PathBuf, &str)> = vec![
        (
            variant("text.ckpt", b"not a checkpoint at all"),
            "not a cellflip checkpoint",
        ),
        (variant("cut.ckpt", &bytes[..bytes.len() / 2]), "truncated"),
        (variant("flipped.ckpt", &flipped), "corrupted"),
        (variant("v9.ckpt", &version), "format version 9"),
    ];
    for (p, reason) in &cases {
        let o = cellflip(&["run", "--resume", p.to_str().unwrap(), "--no-record"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains(&format!("'{}'", p.display())) && err.contains(reason),
            "{err}"
        );
    }
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(empty.join(".step-00000009.ckpt.partial"), &bytes[..100]).unwrap();
    let g = good.to_str().unwrap();
    let file = dir.join("a-file");
    std::fs::write(&file, "").unwrap();
    let under_a_file = file.join("x");
    let refusals: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["--resume", empty.to_str().unwrap()],
            "no complete checkpoint",
        ),
        (vec!["--resume", g, "--res", "64"], "--res: checkpoint"),
        (
            vec!["--resume", g, "--method", "flip"],
            "--method: checkpoint",
        ),
        (
            vec!["--resume", g, "--cross-check"],
            "--cross-check: checkpoint",
        ),
        (vec!["dam-3d", "--resume", g], "dam-3d: checkpoint"),
        (
            vec!["dam-2d", "--checkpoint-every", "0"],
            "--checkpoint-every 0: must be",
        ),
        (
            vec!["dam-2d", "--checkpoint-every", "-1"],
            "--checkpoint-every -1: must be",
        ),
        (
            vec!["dam-2d", "--checkpoint-every", "inf"],
            "--checkpoint-every inf: must be",
        ),
        (
            vec![
                "dam-2d",
                "--checkpoint-every",
                "1",
                "--checkpoint-dir",
                under_a_file.to_str().unwrap(),
            ],
            "cannot write there",
        ),
        (
            vec!["dam-2d", "--checkpoint-dir", "somewhere"],
            "only with --checkpoint-every",
        ),
    ];
    for (args, reason) in refusals {
        let mut a = vec!["run", "--no-record", "-q"];
        a.extend(&args);
        let o = cellflip(&a);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(reason), "{args:?}: {err}");
    }
    // What is allowed: the same value again, the scene by name, a longer run.
    ok(&cellflip(&[
        "run",
        "dam-2d",
        "--resume",
        g,
        "--res",
        "50",
        "--steps",
        "5",
        "--no-record",
        "-q",
    ]));
    assert_eq!(
        std::fs::read(&good).unwrap(),
        bytes,
        "the checkpoint resumed from was changed"
    );
}

/// A checkpoint that cannot be written (a file size limit, as a full disk) stops the run with
/// the file's name and the OS error, leaves no half-written file, and the checkpoints written
/// before it survive whole: flip's checkpoints of the dam keep their size until its emitter
/// pours (2.5 s), and the limit lets through exactly that size.
#[test]
fn a_checkpoint_that_cannot_be_written_stops_the_run_and_the_earlier_ones_survive() {
    let dir = scratch_dir("ckpt-full");
    let (first, full) = (dir.join("first"), dir.join("full"));
    let dam = ["run", "dam-2d", "--method", "flip", "-q", "--no-record"];
    let mut a = dam.to_vec();
    a.extend([
        "--steps",
        "2",
        "--checkpoint-every",
        "1000",
        "--checkpoint-dir",
        first.to_str().unwrap(),
    ]);
    ok(&cellflip(&a));
    let size = std::fs::metadata(first.join("step-00000002.ckpt"))
        .unwrap()
        .len();
    let limit_kib = size.div_ceil(1024);
    let o = Command::new("bash")
        .arg("-c")
        .arg(format!(
            "ulimit -f {limit_kib}; exec '{}' {} --duration 3 --checkpoint-every 0.05 --checkpoint-dir '{}'",
            env!("CARGO_BIN_EXE_cellflip"),
            dam.join(" "),
            full.display()
        ))
        .output()
        .unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("cannot write checkpoint") && err.contains("File too large"),
        "{err}"
    );
    let left: Vec<String> = std::fs::read_dir(&full)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(checkpoints(&full).len(), 2, "{left:?}");
    assert_eq!(left.len(), 2, "a half-written file was left: {left:?}");
    let last = step_of(checkpoints(&full).last().unwrap());
    let to = (last + 1).to_string();
    ok(&cellflip(&[
        "run",
        "--resume",
        full.to_str().unwrap(),
        "--steps",
        &to,
        "--no-record",
        "-q",
    ]));
}

/// A checkpoint keeps the scene as run (its resolved TOML); read back, it is the same scene:
/// the same configuration and method settings, for every built-in scene with every method, and
/// with the overrides a command line gives.
#[test]
fn the_scene_as_run_reads_back_as_the_same_scene() {
    use cellflip::scene::BUILT_IN;
    let mut checked = 0;
    for (name, _) in BUILT_IN {
        for &m in MethodKind::ALL {
            let o = Overrides {
                method: Some(m),
                seed: Some(7),
                ppc: None,
                duration: Some(0.5),
                ..Default::default()
            };
            let Ok(s) = Scene::load(name, &o) else {
                continue;
            };
            let back = Scene::parse_resolved(&s.source, &s.resolved_toml(), &Overrides::default())
                .unwrap_or_else(|e| panic!("{name} {}: {e:#}", m.name()));
            assert_eq!(
                back.resolved_toml(),
                s.resolved_toml(),
                "{name} {}",
                m.name()
            );
            assert_eq!(back.method, s.method, "{name} {}", m.name());
            assert_eq!(back.dims, s.dims, "{name} {}", m.name());
            match s.dim() {
                2 => assert!(back.config::<2>() == s.config::<2>(), "{name} {}", m.name()),
                _ => assert!(back.config::<3>() == s.config::<3>(), "{name} {}", m.name()),
            }
            checked += 1;
        }
    }
    assert!(
        checked >= BUILT_IN.len() * 4,
        "only {checked} scene and method pairs loaded"
    );
}
