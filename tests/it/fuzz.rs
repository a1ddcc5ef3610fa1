//! Generated scene files (seeded, reproducible): each is either refused with a scene error
//! naming a key, or runs a few steps with every invariant checked inside the step. Never a
//! panic. A failing case prints its TOML.

use crate::common;
use cellflip::runner::Limit;
use cellflip::scene::{Overrides, Scene};
use rand::rngs::StdRng;
use rand::seq::IndexedRandom;
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;

/// A small valid scene per dimension, as (table, key) -> TOML value.
fn base(dim: usize) -> BTreeMap<(String, String), String> {
    let v = |x: &str| {
        if dim == 2 {
            format!("[{x}, {x}]")
        } else {
            format!("[{x}, {x}, {x}]")
        }
    };
    let entries = [
        ("", "name", "\"fuzz\"".to_string()),
        ("", "dim", dim.to_string()),
        ("domain", "size", v("1.0")),
        ("domain", "cells", "8".into()),
        ("simulation", "duration", "0.05".into()),
        ("simulation", "ppc", if dim == 2 { "4" } else { "8" }.into()),
        ("[fluid]", "shape", "\"box\"".into()),
        ("[fluid]", "min", v("0.0")),
        ("[fluid]", "max", v("0.5")),
        ("[emitter]", "min", v("0.6")),
        ("[emitter]", "max", v("0.8")),
        ("[emitter]", "velocity", v("0.0")),
    ];
    entries
        .into_iter()
        .map(|(t, k, v)| ((t.to_string(), k.to_string()), v))
        .collect()
}

const KEYS: &[(&str, &str)] = &[
    ("", "name"),
    ("", "dim"),
    ("domain", "size"),
    ("domain", "cells"),
    ("simulation", "method"),
    ("simulation", "duration"),
    ("simulation", "ppc"),
    ("simulation", "jitter"),
    ("simulation", "gravity"),
    ("simulation", "flip_ratio"),
    ("simulation", "cfl"),
    ("simulation", "max_dt"),
    ("simulation", "max_speed"),
    ("simulation", "pressure_tolerance"),
    ("simulation", "seed"),
    ("simulation", "band"),
    ("simulation", "band_r"),
    ("simulation", "directions"),
    ("[fluid]", "shape"),
    ("[fluid]", "min"),
    ("[fluid]", "max"),
    ("[fluid]", "center"),
    ("[fluid]", "radius"),
    ("[emitter]", "min"),
    ("[emitter]", "max"),
    ("[emitter]", "velocity"),
    ("[emitter]", "start"),
    ("[emitter]", "stop"),
    ("[emitter]", "until_fill"),
];

/// Values out of range, of the wrong type, or hostile (paths, huge integers, non-finite).
const HOSTILE: &[&str] = &[
    "0",
    "2",
    "3",
    "9",
    "27",
    "-1",
    "1e-300",
    "1e300",
    "-1e300",
    "nan",
    "inf",
    "9223372036854775807",
    "4294967296",
    "\"\"",
    "\"../x\"",
    "\"ball\"",
    "\"full\"",
    "\"moore\"",
    "[]",
    "[0.1, 0.9]",
    "[0.5, 0.5, 0.5]",
    "[1.0, 1.0, 1.0]",
    "[nan, 0.0]",
    "[0.0, -1e300]",
    "[2.0, 2.0]",
];

/// Values most keys take (methods, band modes, small counts and sizes): drawn 70% of the time
/// so that many generated scenes run.
const PLAUSIBLE: &[&str] = &[
    "\"ccp\"",
    "\"flip\"",
    "\"idp\"",
    "\"nbflip\"",
    "\"powerpic\"",
    "\"paths\"",
    "\"none\"",
    "\"one-way\"",
    "\"von-neumann\"",
    "\"box\"",
    "1",
    "4",
    "6",
    "8",
    "0.3",
    "0.9",
    "0.05",
    "0.1",
    "[0.0, 0.0]",
    "[0.2, 0.4]",
    "[0.0, 0.0, 0.0]",
    "[0.2, 0.4, 0.3]",
];

fn render(scene: &BTreeMap<(String, String), String>) -> String {
    let mut text = String::new();
    let mut table = None;
    for ((t, k), v) in scene {
        if table != Some(t) {
            if !t.is_empty() {
                text += &format!("\n[{t}]\n");
            }
            table = Some(t);
        }
        text += &format!("{k} = {v}\n");
    }
    text
}

/// Runs a scene a few steps, unless it is too large for a test.
fn run_briefly(scene: &Scene) -> anyhow::Result<()> {
    let size = scene.memory_estimate(false);
    if size.cells > 40_000 || size.particles > 2e5 {
        return Ok(());
    }
    let limit = Limit::Steps(3);
    match scene.dim() {
        2 => common::try_run_sim(common::simulation::<2>(scene, false), limit, |_, _| {}),
        _ => common::try_run_sim(common::simulation::<3>(scene, false), limit, |_, _| {}),
    }
}

#[test]
fn generated_scenes_are_refused_naming_a_key_or_run_keeping_their_invariants() {
    let mut rng = StdRng::seed_from_u64(16);
    let (mut refused, mut ran) = (0, 0);
    for case in 0..1500 {
        let mut scene = base(if rng.random() { 2 } else { 3 });
        for _ in 0..rng.random_range(1..=2) {
            let (t, k) = *KEYS.choose(&mut rng).unwrap();
            let pool = if rng.random::<f64>() < 0.3 {
                HOSTILE
            } else {
                PLAUSIBLE
            };
            let value = pool.choose(&mut rng).unwrap().to_string();
            scene.insert((t.into(), k.into()), value);
        }
        let text = render(&scene);
        let outcome = std::panic::catch_unwind(|| {
            match Scene::parse("fuzz.toml", &text, &Overrides::default()) {
                Err(e) if !e.key.is_empty() => Ok(false),
                Err(e) => Err(format!("refused without naming a key: {e}")),
                Ok(scene) => run_briefly(&scene)
                    .map(|()| true)
                    .map_err(|e| format!("{e:#}")),
            }
        });
        match outcome {
            Ok(Ok(true)) => ran += 1,
            Ok(Ok(false)) => refused += 1,
            Ok(Err(why)) => panic!("case {case}: {why}\n{text}"),
            Err(_) => panic!("case {case} panicked:\n{text}"),
        }
    }
    // The generator must reach both sides.
    assert!(ran >= 40 && refused >= 40, "ran {ran}, refused {refused}");
}
