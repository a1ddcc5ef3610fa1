//! `cellflip compare` and the live sinks (issue 38): one recording of several runs, each run's
//! series equal to its own `cellflip run`'s, a failing run that stops alone, and streams that
//! carry the file's data or survive a viewer that is not there.

use crate::common::{self, cellflip_in, ok, scratch_dir};
use cellflip::cmd::compare::{step_frames, Frames, Status};
use cellflip::methods::MethodKind;
use cellflip::record::{ComparedRun, Comparison, Sink};
use cellflip::runner::Runner;
use std::path::Path;

#[test]
fn a_comparison_holds_one_world_per_run_and_each_runs_series_is_its_own_runs() {
    let dir = scratch_dir("compare_worlds");
    let cmp = dir.join("cmp.rrd");
    let cmp_s = cmp.to_str().unwrap();
    let args = ["--duration", "0.25", "-q"];
    ok(&cellflip_in(
        &dir,
        &[
            &[
                "compare",
                "dam-2d",
                "--methods",
                "flip,ccp",
                "--save",
                cmp_s,
            ],
            &args[..],
        ]
        .concat(),
    ));
    let (views, _) = common::blueprint(&cmp);
    let mut worlds: Vec<(String, String)> = views
        .iter()
        .filter(|v| v.class == "2D")
        .map(|v| (v.name.clone(), v.origin.clone()))
        .collect();
    worlds.sort();
    let expected = [("ccp", "ccp/world"), ("flip", "flip/world")];
    assert_eq!(worlds, expected.map(|(a, b)| (a.into(), b.into())));
    let logged = common::logged_entities(&cmp);
    for e in [
        "flip/world/particles",
        "ccp/world/particles",
        "ccp/world/corrector/moves",
    ] {
        assert!(logged.contains(e), "{e} not in {logged:?}");
    }
    for method in ["flip", "ccp"] {
        let own = dir.join(format!("{method}.rrd"));
        let own_s = own.to_str().unwrap();
        let run = ["run", "dam-2d", "--method", method, "--save", own_s];
        ok(&cellflip_in(&dir, &[&run[..], &args[..]].concat()));
        let entity = "metrics/volume_percent";
        let alone = common::scalars_on(&own, entity, "sim_time");
        let compared = common::scalars_on(&cmp, &format!("{method}/{entity}"), "sim_time");
        assert!(alone.len() > 20, "{method}: {} steps", alone.len());
        assert_eq!(compared, alone, "{method}'s volume, compared and alone");
    }
}

/// The labels a 2D points entity carries, over the whole recording.
fn labels(path: &Path, entity: &str) -> Vec<String> {
    let rows = common::on_timeline(path, entity, "sim_time", |c| {
        c.iter_slices::<String>("Points2D:labels".into())
            .map(|s| s.iter().map(|l| l.to_string()).collect::<Vec<_>>().concat())
            .collect()
    });
    rows.into_iter().map(|(_, l)| l).collect()
}

#[test]
fn a_run_that_fails_stops_alone_and_its_world_says_why() {
    let dir = scratch_dir("compare_failure");
    let path = dir.join("cmp.rrd");
    let scenes: Vec<_> = [MethodKind::Flip, MethodKind::Ccp]
        .map(|k| common::load("drop-2d", &common::with(k, None)))
        .into();
    let runs: Vec<ComparedRun<'_>> = scenes
        .iter()
        .map(|s| ComparedRun {
            label: s.method.kind.name().into(),
            title: s.method.kind.name().into(),
            scene: s,
            color: s.method.kind.rgb(),
            surface: false,
        })
        .collect();
    let rec = Comparison::create(&Sink::File(path.clone()), "failure", &runs).unwrap();
    let mut runners: Vec<(Runner<2>, Status)> = scenes
        .iter()
        .map(|s| {
            (
                Runner::new(common::simulation::<2>(s, false)),
                Status::Running,
            )
        })
        .collect();
    // ccp's state goes bad after its first step: its second step fails, as a broken run would.
    runners[1].0.sim.step().unwrap();
    runners[1].0.sim.state.particles.vel[7][0] = f64::NAN;
    let frames = Frames {
        dt: 0.04,
        until: 0.2,
        progress: false,
    };
    step_frames(&mut runners, &["flip", "ccp"], Some(&rec), &mut [], frames).unwrap();
    rec.finish().unwrap();
    assert_eq!(runners[0].1, Status::Running, "flip went on");
    assert!(
        runners[0].0.sim.state.time_secs >= 0.2,
        "flip ran to the end"
    );
    let Status::Failed { at, why } = &runners[1].1 else {
        panic!("ccp did not fail: {:?}", runners[1].1)
    };
    assert!(*at < 0.04 && why.contains("not finite"), "{at}: {why}");
    let ccp = labels(&path, "ccp/world/label");
    assert!(
        ccp.last()
            .is_some_and(|l| l.contains("stopped at t =") && l.contains("not finite")),
        "ccp's label: {ccp:?}"
    );
    let flip = labels(&path, "flip/world/label");
    assert!(flip.len() >= 5, "flip's frames: {flip:?}");
}
