//! Checkpoints from elsewhere (issue 74): a file whose checksum is valid but whose content is
//! not a state (edited with numpy through `tools/checkpoint.py`, its checksum recomputed) is
//! refused before anything is built from it, naming the checkpoint, the array and the first bad
//! element, exit 1, no file left behind; random single-array edits never make a panic.

use crate::common::{cellflip, ok, scratch_dir};
use cellflip::snapshot::crc_of;
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A checkpoint of `scene` with `flags` after [`STEPS`], in `dir/<tag>`.
fn checkpoint_of(dir: &Path, tag: &str, scene: &str, flags: &[&str]) -> PathBuf {
    let ckdir = dir.join(tag);
    let ck = ckdir.to_str().unwrap();
    let steps = STEPS.to_string();
    let mut args = vec!["run", scene, "--steps", &steps, "-q", "--no-record"];
    args.extend(["--checkpoint-every", "1000", "--checkpoint-dir", ck]);
    args.extend(flags);
    ok(&cellflip(&args));
    ckdir.join(cellflip::checkpoint::file_name(STEPS))
}

/// Steps before the checkpoint: enough for ccp's correction to have moved particles on the dam
/// (it keeps prices only then) and for Power PIC's plan to exist.
const STEPS: u64 = 30;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Resumes from `ckpt` for two steps more, recording to `dir/resumed.rrd`.
fn resume(dir: &Path, ckpt: &Path) -> Output {
    let out = dir.join("resumed.rrd");
    cellflip(&[
        "run",
        "--resume",
        ckpt.to_str().unwrap(),
        "--steps",
        &(STEPS + 2).to_string(),
        "-q",
        "--out",
        out.to_str().unwrap(),
    ])
}

/// Whether numpy answers; without it the numpy test skips (printing so), unless
/// `CELLFLIP_REQUIRE_NUMPY` is set (`.ci/run` installs numpy and sets it).
fn numpy() -> bool {
    let has = Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has && std::env::var_os("CELLFLIP_REQUIRE_NUMPY").is_some() {
        panic!("CELLFLIP_REQUIRE_NUMPY is set and python3 cannot import numpy");
    }
    if !has {
        eprintln!("skipped: python3 cannot import numpy (pip install numpy)");
    }
    has
}

/// `edit`, a Python expression over `a` (the checkpoint's arrays, from `tools/checkpoint.py`'s
/// `load`) giving a dict of arrays, stored into a copy of `ckpt` at `into`.
fn numpy_edit(ckpt: &Path, edit: &str, into: &Path) {
    let tools = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools");
    let script = format!(
        "import sys, numpy as np\nsys.path.insert(0, {tools:?})\n\
         from checkpoint import load, store\n\
         meta, a = load({ckpt:?})\n\
         a = {{k: v.copy() for k, v in a.items()}}\n\
         store({ckpt:?}, {edit}, into={into:?})\n",
        tools = tools.to_str().unwrap(),
        ckpt = ckpt.to_str().unwrap(),
        into = into.to_str().unwrap(),
    );
    let o = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{edit}: {}", stderr(&o));
}

/// Python: array `name` of the arrays `a` with its number `i` (counted over the flattened
/// array, as numpy's `flat`) set to `value`.
fn set(name: &str, i: &str, value: &str) -> String {
    format!("(lambda x: (x.flat.__setitem__({i}, {value}), {{{name:?}: x}})[1])(a[{name:?}])")
}

/// Each class of edit the issue names, on the method whose arrays it touches: refused with
/// exit 1, naming the checkpoint, the array and its element, and leaving no recording (nor
/// its `.partial`) behind.
#[test]
fn edited_checkpoints_are_refused_naming_the_array_and_its_element() {
    if !numpy() {
        return;
    }
    let dir = scratch_dir("ckpt-content");
    let flip = checkpoint_of(&dir, "flip", "falling-obstacle-2d", &["--method", "flip"]);
    let ccp = checkpoint_of(&dir, "ccp", "dam-2d", &["--method", "ccp"]);
    let nbflip = checkpoint_of(&dir, "nbflip", "dam-2d", &["--method", "nbflip"]);
    let powerpic = checkpoint_of(&dir, "powerpic", "dam-2d", &["--method", "powerpic"]);
    let swap = "{'particles.pos': a['particles.vel'], 'particles.vel': a['particles.pos']}";
    let cases: Vec<(&Path, String, &str, &str)> = vec![
        (
            &flip,
            set("particles.pos", "11", "np.nan"),
            "particles.pos",
            "element 5",
        ),
        (
            &flip,
            set("particles.pos", "7", "1e6"),
            "particles.pos",
            "outside the domain",
        ),
        (&flip, swap.into(), "particles.pos", "outside the domain"),
        (
            &flip,
            set("particles.vel", "0", "np.inf"),
            "particles.vel",
            "not finite",
        ),
        (
            &flip,
            set("velocity.1", "3", "np.nan"),
            "velocity.1",
            "element 3",
        ),
        (
            &flip,
            set("markings.kind", "0", "7"),
            "markings.kind",
            "cell kind 7",
        ),
        (
            &flip,
            set("markings.count", "0", "3"),
            "markings.count",
            "particles",
        ),
        (
            &flip,
            set("obstacles.offset", "0", "-1e3"),
            "obstacles.offset",
            "outside the tank",
        ),
        (
            &flip,
            set("obstacles.velocity", "0", "np.nan"),
            "obstacles.velocity",
            "not finite",
        ),
        (
            &flip,
            set("target_volume", "0", "-1"),
            "target_volume",
            "positive",
        ),
        (
            &flip,
            set("total_particles", "0", "1"),
            "total_particles",
            "held",
        ),
        (
            &flip,
            set("pressure.cells", "0", "10**9"),
            "pressure.cells",
            "outside the grid",
        ),
        (
            &flip,
            set("pressure.cells", "1", "x.flat[0]"),
            "pressure.cells",
            "not ascending",
        ),
        (
            &flip,
            set("pressure.x", "2", "np.nan"),
            "pressure.x",
            "element 2",
        ),
        (
            &flip,
            set("pressure.dt", "0", "-1"),
            "pressure.dt",
            "at least 0",
        ),
        (
            &ccp,
            set("ccp.n_deep", "0", "2**62"),
            "ccp.n_deep",
            "more than",
        ),
        (
            &ccp,
            set("ccp.cell_prices", "0", "np.nan"),
            "ccp.cell_prices",
            "element 0",
        ),
        (
            &nbflip,
            set("nbflip.phi", "10", "np.nan"),
            "nbflip.phi",
            "element 10",
        ),
        (
            &nbflip,
            set("nbflip.not_held", "0", "-5"),
            "total_particles",
            "not held",
        ),
        (
            &powerpic,
            set("powerpic.v", "2", "-1.0"),
            "powerpic.v",
            "positive",
        ),
        (
            &powerpic,
            set("powerpic.active", "0", "2**31"),
            "powerpic.active",
            "element 0",
        ),
    ];
    for (i, (ckpt, edit, array, why)) in cases.iter().enumerate() {
        let edited = dir.join(format!("edited-{i}.ckpt"));
        numpy_edit(ckpt, edit, &edited);
        let o = resume(&dir, &edited);
        let err = stderr(&o);
        let said = format!("{array} ({edit}): {:?} {err}", o.status.code());
        assert_eq!(o.status.code(), Some(1), "{said}");
        let named = format!("'{}'", edited.display());
        assert!(
            err.contains(&named) && err.contains(array) && err.contains(why),
            "{said}"
        );
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains("resumed"))
            .collect();
        assert!(left.is_empty(), "{said}: left {left:?}");
    }
}

/// A checkpoint written before the pressure solve kept its last solution (2026-12-01) has no
/// `pressure.*` arrays (made here from today's by renaming them in its header, their bytes
/// untouched, the checksum made valid again): refused with exit 1, naming the checkpoint and
/// `pressure.cells`, rather than resumed with a first solve its run never had.
#[test]
fn a_checkpoint_from_before_the_warm_start_is_refused() {
    let dir = scratch_dir("ckpt-before-warm-start");
    let ckpt = checkpoint_of(&dir, "flip", "dam-2d", &["--method", "flip"]);
    let mut bytes = std::fs::read(&ckpt).unwrap();
    let header_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let (from, to) = (b"\"pressure.", b"\"pressurx.");
    let header = &mut bytes[16..16 + header_len];
    let at: Vec<usize> = (0..=header.len() - from.len())
        .filter(|&i| &header[i..i + from.len()] == from)
        .collect();
    assert_eq!(at.len(), 3, "pressure.cells, .x and .dt in the header");
    for i in at {
        header[i..i + to.len()].copy_from_slice(to);
    }
    reseal(&mut bytes);
    assert!(arrays_of(&bytes)
        .iter()
        .all(|a| !a.name.starts_with("pressure.")));
    let old = dir.join("before-warm-start.ckpt");
    std::fs::write(&old, &bytes).unwrap();
    let o = resume(&dir, &old);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let named = format!("'{}'", old.display());
    assert!(
        err.contains(&named)
            && err.contains("pressure.cells: absent")
            && err.contains("start it again"),
        "{err}"
    );
}

/// An array of a checkpoint: where its bytes are and what they hold.
struct Located {
    name: String,
    dtype: String,
    offset: usize,
    bytes: usize,
}

/// The arrays a checkpoint's header lists (docs/checkpoints.md).
fn arrays_of(bytes: &[u8]) -> Vec<Located> {
    let header_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let header: toml::Table = std::str::from_utf8(&bytes[16..16 + header_len])
        .unwrap()
        .parse()
        .unwrap();
    let arrays = header["array"].as_array().unwrap();
    arrays
        .iter()
        .map(|a| {
            let dtype = a["dtype"].as_str().unwrap().to_string();
            let shape = a["shape"].as_array().unwrap();
            let count: i64 = shape.iter().map(|d| d.as_integer().unwrap()).product();
            let size = dtype[2..].parse::<usize>().unwrap();
            Located {
                name: a["name"].as_str().unwrap().into(),
                dtype,
                offset: a["offset"].as_integer().unwrap() as usize,
                bytes: count as usize * size,
            }
        })
        .collect()
}

/// The checkpoint's checksum made to match its bytes again (what `store` does).
fn reseal(bytes: &mut [u8]) {
    let body = bytes.len() - 12;
    let crc = crc_of(&bytes[..body]).unwrap();
    bytes[body..body + 4].copy_from_slice(&crc.to_le_bytes());
}

/// One element of `a` set to a value chosen to hurt: NaN, an infinity, a huge or negative
/// number, zero, or random bits.
fn hurt(bytes: &mut [u8], a: &Located, rng: &mut impl Rng) {
    let size = a.dtype[2..].parse::<usize>().unwrap();
    let at = a.offset + size * rng.random_range(0..a.bytes / size);
    let float = a.dtype.starts_with("<f");
    let value: [u8; 8] = match (rng.random_range(0..6), float) {
        (0, true) => f64::NAN.to_le_bytes(),
        (1, true) => f64::NEG_INFINITY.to_le_bytes(),
        (2, true) => 1e300f64.to_le_bytes(),
        (3, true) => (-7.5f64).to_le_bytes(),
        (0, false) => u64::MAX.to_le_bytes(),
        (1, false) => (i64::MIN as u64).to_le_bytes(),
        (2, false) => (u32::MAX as u64).to_le_bytes(),
        (3, false) => 3u64.to_le_bytes(),
        (4, _) => [0; 8],
        _ => rng.random::<u64>().to_le_bytes(),
    };
    let value = match (float, size) {
        (true, 4) => (f64::from_le_bytes(value) as f32).to_le_bytes().to_vec(),
        _ => value[..size].to_vec(),
    };
    bytes[at..at + size].copy_from_slice(&value);
}

/// Two arrays of the same size exchanged, if the checkpoint has such a pair.
fn swap(bytes: &mut [u8], arrays: &[Located], rng: &mut impl Rng) -> Option<String> {
    let pairs: Vec<(&Located, &Located)> = (arrays.iter())
        .flat_map(|a| arrays.iter().map(move |b| (a, b)))
        .filter(|(a, b)| a.name < b.name && a.bytes == b.bytes && a.bytes > 0)
        .collect();
    let (a, b) = *pairs.get(rng.random_range(0..pairs.len().max(1)))?;
    let first = bytes[a.offset..a.offset + a.bytes].to_vec();
    bytes.copy_within(b.offset..b.offset + b.bytes, a.offset);
    bytes[b.offset..b.offset + b.bytes].copy_from_slice(&first);
    Some(format!("{} <-> {}", a.name, b.name))
}

/// Random single-array edits of every method's checkpoint (an obstacle's for flip), each with
/// its checksum made valid again: a resumed run goes on or is refused (exit 1), never a panic.
#[test]
fn random_single_array_edits_never_make_a_panic() {
    let dir = scratch_dir("ckpt-fuzz");
    let checkpoints = [
        checkpoint_of(&dir, "flip", "falling-obstacle-2d", &["--method", "flip"]),
        checkpoint_of(&dir, "ccp", "dam-2d", &["--method", "ccp"]),
        checkpoint_of(
            &dir,
            "band",
            "dam-2d",
            &["--method", "ccp", "--band", "paths"],
        ),
        checkpoint_of(&dir, "idp", "dam-2d", &["--method", "idp"]),
        checkpoint_of(&dir, "nbflip", "dam-2d", &["--method", "nbflip"]),
        checkpoint_of(&dir, "powerpic", "dam-2d", &["--method", "powerpic"]),
    ];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(74);
    let (mut refused, mut ran) = (0, 0);
    for ckpt in &checkpoints {
        let good = std::fs::read(ckpt).unwrap();
        let arrays = arrays_of(&good);
        for k in 0..12 {
            let mut bytes = good.clone();
            let what = match k % 4 {
                3 => swap(&mut bytes, &arrays, &mut rng).unwrap_or_default(),
                _ => {
                    let a = &arrays[rng.random_range(0..arrays.len())];
                    if a.bytes == 0 {
                        continue;
                    }
                    hurt(&mut bytes, a, &mut rng);
                    a.name.clone()
                }
            };
            reseal(&mut bytes);
            let edited = dir.join("fuzzed.ckpt");
            std::fs::write(&edited, &bytes).unwrap();
            let o = resume(&dir, &edited);
            let err = stderr(&o);
            let said = format!("{} {what}: {:?} {err}", ckpt.display(), o.status.code());
            assert!(matches!(o.status.code(), Some(0 | 1)), "{said}");
            assert!(!err.contains("panicked"), "{said}");
            match o.status.success() {
                true => ran += 1,
                false => refused += 1,
            }
        }
    }
    eprintln!("{refused} edits refused, {ran} ran on");
    assert!(
        refused > 0,
        "no edit was refused: the checks were not reached"
    );
}
