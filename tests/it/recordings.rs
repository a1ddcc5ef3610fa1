//! Recordings as a viewer opens them (issue 15): their layout (blueprint), read back from the
//! file, against what they log, both ways; the side panels; the moves drawn against the moves
//! counted. Tests cannot look at pixels: the screenshots in docs/ were checked by eye.

use crate::common::{self, ReadView};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `cellflip run <scene> --steps <steps> <extra>` into a scratch folder and returns the
/// folder (which goes when dropped) and the recording's path.
fn record(test: &str, scene: &str, steps: &str, extra: &[&str]) -> (common::Scratch, PathBuf) {
    let dir = common::Scratch::new("rec", test);
    let out = dir.join(format!("{scene}-{}.rrd", extra.join("")));
    let o = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(["run", scene, "--steps", steps, "-q", "--out"])
        .arg(&out)
        .args(extra)
        .output()
        .expect("the binary runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (dir, out)
}

/// Whether query line `q` (`+ path` or `+ path/**`) takes the entity `e`.
fn takes(q: &str, e: &str) -> bool {
    match q.strip_prefix("+ ") {
        Some(p) => match p.strip_suffix("/**") {
            Some(prefix) => e == prefix || e.starts_with(&format!("{prefix}/")),
            None => e == p,
        },
        None => false,
    }
}

/// The run's layout plots every scalar it logs in exactly one time-series panel, and every
/// panel plots something it logs; every entity a spatial view names is logged.
fn check_layout(rrd: &Path) -> Vec<ReadView> {
    let logged = common::logged_entities(rrd);
    let (views, _) = common::blueprint(rrd);
    let series: Vec<&ReadView> = views.iter().filter(|v| v.class == "TimeSeries").collect();
    let metrics = logged.iter().filter(|e| e.starts_with("metrics/"));
    for m in metrics {
        let panels: Vec<&str> = series
            .iter()
            .filter(|v| v.queries.iter().any(|q| takes(q, m)))
            .map(|v| v.name.as_str())
            .collect();
        assert_eq!(panels.len(), 1, "{m} is plotted in {panels:?} ({rrd:?})");
    }
    for v in &views {
        for q in v.queries.iter().filter(|q| q.starts_with("+ ")) {
            assert!(
                logged.iter().any(|e| takes(q, e)),
                "view '{}' ({}) shows '{q}', which {rrd:?} never logs",
                v.name,
                v.class
            );
        }
    }
    views
}

fn names(views: &[ReadView]) -> BTreeSet<String> {
    views.iter().map(|v| v.name.clone()).collect()
}

#[test]
fn every_panel_plots_what_the_run_logs_and_every_metric_has_one_panel() {
    let runs: [(&str, &str, &[&str]); 7] = [
        ("hydrostatic-2d", "3", &[]),
        ("dam-2d", "4", &["--cross-check"]),
        ("dam-2d", "20", &["--band", "paths", "--res", "24"]),
        ("falling-obstacle-2d", "3", &[]),
        ("dam-2d", "3", &["--method", "idp"]),
        (
            "dam-3d",
            "3",
            &["--method", "nbflip", "--res", "12", "--record-every", "1"],
        ),
        ("drop-3d", "10", &["--res", "12"]),
    ];
    for (scene, steps, extra) in runs {
        let (_dir, rrd) = record("panels", scene, steps, extra);
        let views = check_layout(&rrd);
        let names = names(&views);
        let band = extra.contains(&"--band") || scene == "drop-3d";
        assert_eq!(
            names.contains("band: objective"),
            band,
            "{rrd:?}: {names:?}"
        );
        assert_eq!(
            names.contains("correction: cross-check difference"),
            extra.contains(&"--cross-check"),
            "{rrd:?}: {names:?}"
        );
        let obstacles = scene.starts_with("falling");
        assert_eq!(names.contains("obstacles: speed (m/s)"), obstacles);
        assert!(names.contains("legend") && names.contains("log") && names.contains("scene"));
    }
}

#[test]
fn the_world_view_comes_first_the_side_panels_start_collapsed_and_3d_has_a_slice() {
    for (scene, world_class, slice) in [("dam-2d", "2D", false), ("drop-3d", "3D", true)] {
        let (_dir, rrd) = record("world", scene, "2", &["--res", "24"]);
        let (views, panels) = common::blueprint(&rrd);
        let world: Vec<&ReadView> = views.iter().filter(|v| v.name == "world").collect();
        assert_eq!(world.len(), 1, "{views:?}");
        assert_eq!(
            (world[0].class.as_str(), world[0].origin.as_str()),
            (world_class, "world")
        );
        let has_slice = views
            .iter()
            .any(|v| v.name == "slice" && v.class == "2D" && v.origin == "slice");
        assert_eq!(has_slice, slice, "{views:?}");
        for p in ["blueprint_panel", "selection_panel", "time_panel"] {
            assert_eq!(panels.get(p), Some(&2), "{p} collapsed: {panels:?}");
        }
    }
}

/// The web viewer follows the browser's theme, and in the light one a view's background is
/// white, where white labels and the speed ramp's white vanish: every spatial view keeps a dark
/// background in both themes (docs/cli.md, "In a browser").
#[test]
fn every_spatial_view_keeps_a_dark_background_in_either_theme() {
    for (scene, res) in [("dam-2d", "24"), ("drop-3d", "12")] {
        let (_dir, rrd) = record("background", scene, "1", &["--res", res]);
        let (views, _) = common::blueprint(&rrd);
        let spatial: Vec<&ReadView> = views.iter().filter(|v| v.class.ends_with('D')).collect();
        assert!(!spatial.is_empty(), "{views:?}");
        for v in spatial {
            let expected = match v.class.as_str() {
                "2D" => (3, Some(0x121212ff)),
                _ => (1, None),
            };
            assert_eq!(v.background, Some(expected), "{v:?}");
        }
    }
}

#[test]
fn band_levels_have_their_own_view_and_leave_the_world_view_but_not_the_paths() {
    let q = |s: &str| s.to_string();
    let (_dir, rrd) = record("layers", "dam-2d", "3", &["--band", "paths", "--res", "24"]);
    let (views, _) = common::blueprint(&rrd);
    let world = views.iter().find(|v| v.name == "world").unwrap();
    assert!(
        world.queries.contains(&q("- world/grid/depth")),
        "{world:?}"
    );
    assert!(
        !world.queries.iter().any(|l| l.contains("paths")),
        "{world:?}"
    );
    let levels = views.iter().find(|v| v.name == "band levels").unwrap();
    assert!(
        levels.queries.contains(&q("+ world/grid/depth")),
        "{levels:?}"
    );
    assert!(
        levels.queries.contains(&q("+ world/corrector/paths")),
        "{levels:?}"
    );
    // In 3D both are views of the slice: the slice leaves out the band levels, not the paths.
    let (_dir, rrd) = record("layers", "drop-3d", "2", &["--res", "12"]);
    let (views, _) = common::blueprint(&rrd);
    let slice = views.iter().find(|v| v.name == "slice").unwrap();
    assert!(
        slice.queries.contains(&q("- slice/grid/depth")),
        "{slice:?}"
    );
    assert!(
        !slice.queries.iter().any(|l| l.contains("paths")),
        "{slice:?}"
    );
    let levels = views.iter().find(|v| v.name == "band levels").unwrap();
    assert_eq!(levels.origin, "slice");
    assert!(
        levels.queries.contains(&q("+ slice/corrector/paths")),
        "{levels:?}"
    );
}

#[test]
fn every_move_counted_is_drawn_as_one_arrow_in_both_move_styles() {
    for moves in ["arrows", "hops"] {
        let (_dir, rrd) = record("moves", "dam-2d", "12", &["--moves", moves]);
        let drawn = common::arrows_2d_per_step(&rrd, "world/corrector/moves");
        let counted = common::scalars_per_step(&rrd, "metrics/correction/moved");
        assert_eq!(drawn.len(), 12, "{drawn:?}");
        assert!(
            drawn.iter().any(|(_, n)| *n > 0),
            "no moves drawn: {drawn:?}"
        );
        for (step, n) in &drawn {
            let c = counted.iter().find(|(s, _)| s == step).map(|(_, c)| *c);
            assert_eq!(c, Some(*n as f64), "{moves}: step {step}");
        }
    }
}

#[test]
fn step_zero_has_the_state_metrics() {
    let (_dir, rrd) = record("zero", "falling-obstacle-2d", "1", &[]);
    for entity in [
        "metrics/volume_percent",
        "metrics/particles",
        "metrics/max_speed",
        "metrics/obstacle/box/height",
    ] {
        let steps: Vec<i64> = common::scalars_per_step(&rrd, entity)
            .iter()
            .map(|(s, _)| *s)
            .collect();
        assert_eq!(steps, [0, 1], "{entity}");
    }
}

#[test]
fn a_slice_of_a_2d_scene_or_off_the_tank_is_refused_naming_the_option() {
    for (scene, slice, says) in [
        ("dam-2d", "z", "2D"),
        ("drop-3d", "w=0.5", "x, y or z"),
        ("drop-3d", "x=1.5", "fraction"),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_cellflip"))
            .args([
                "run",
                scene,
                "--steps",
                "1",
                "--no-record",
                "--slice",
                slice,
            ])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("--slice") && err.contains(says),
            "{err}"
        );
    }
}
