//! Results change only on purpose: a digest of the whole state and of every step's report
//! (all but timings), chained over a fixed number of steps, for every built-in scene with its
//! default method and with flip, for the band variants, and for every other registered method
//! on the dams, and the dams with the multigrid preconditioner (the default's size rule keeps these
//! small runs on MIC(0)). Each line also gives the run's PCG iterations (`pcg=`), so that a
//! solver that takes more iterations shows as a number. The digests live in
//! `tests/it/golden_digests.txt`; after a change that must alter results, regenerate them with
//! `CELLFLIP_BLESS=1 cargo test --release --test it golden::` and say why in the commit.

use crate::common::{band_flags, digest_run, load};
use cellflip::methods::ccp::BandMode;
use cellflip::methods::MethodKind;
use cellflip::scene::{Overrides, BUILT_IN};
use cellflip::solvers::pcg::Preconditioner;

/// A run: scene, method override, band override, preconditioner override, steps.
type Case = (
    String,
    Option<MethodKind>,
    Option<BandMode>,
    Option<Preconditioner>,
    u64,
);

/// The runs. 3D scenes run at 16 cells along their shortest axis.
fn cases() -> Vec<Case> {
    let mut v = vec![];
    for (name, _) in BUILT_IN {
        let s = load(name, &Overrides::default());
        let steps = if s.dim() == 2 { 60 } else { 12 };
        v.push((name.to_string(), None, None, None, steps));
        if s.method.kind != MethodKind::Flip {
            v.push((name.to_string(), Some(MethodKind::Flip), None, None, steps));
        }
    }
    // The emitter starts at 2.5 s; the band variants on the 2D dam.
    v.push(("dam-2d".into(), None, None, None, 330));
    v.push(("dam-2d".into(), None, Some(BandMode::Paths), None, 60));
    v.push(("dam-2d".into(), None, Some(BandMode::OneWay), None, 8));
    v.push(("dam-2d".into(), None, Some(BandMode::Full), None, 8));
    // Every other registered method on the dams: a new method gets its digests here (bless
    // them once it works).
    for &m in MethodKind::ALL {
        for (dam, steps) in [("dam-2d", 60), ("dam-3d", 12)] {
            let default = load(dam, &Overrides::default()).method.kind;
            if m != default && m != MethodKind::Flip {
                v.push((dam.into(), Some(m), None, None, steps));
            }
        }
    }
    // The multigrid preconditioner, which the size rule gives only larger systems: the
    // dams with their default method, and idp's second solve.
    for m in [None, Some(MethodKind::Idp)] {
        let mg = Some(Preconditioner::Multigrid);
        v.push(("dam-2d".into(), m, None, mg, 60));
        v.push(("dam-3d".into(), m, None, mg, 12));
    }
    v
}

fn digest(
    name: &str,
    method: Option<MethodKind>,
    band: Option<BandMode>,
    pressure: Option<Preconditioner>,
    steps: u64,
) -> (String, usize) {
    let mut o = Overrides {
        method,
        flags: band_flags(band),
        pressure,
        ..Default::default()
    };
    let s = load(name, &o);
    if s.dim() == 3 {
        let (lo, hi) = (s.dims.iter().min().unwrap(), s.dims.iter().max().unwrap());
        o.cells = Some(16 * hi / lo);
        let s = load(name, &o);
        return digest_run::<3>(&s, steps);
    }
    digest_run::<2>(&s, steps)
}

const FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/it/golden_digests.txt");

#[test]
fn every_scene_gives_the_recorded_digest() {
    let lines: Vec<String> = cases()
        .into_iter()
        .map(|(name, method, band, pressure, steps)| {
            let (d, pcg) = digest(&name, method, band, pressure, steps);
            format!(
                "{name} method={} band={} pressure={} steps={steps} pcg={pcg} {d}",
                method.map_or("default", |m| m.name()),
                band.map_or("default", |b| b.name()),
                pressure.map_or("default", |p| p.name())
            )
        })
        .collect();
    if std::env::var_os("CELLFLIP_BLESS").is_some() {
        std::fs::write(FILE, lines.join("\n") + "\n").unwrap();
        return;
    }
    let want = std::fs::read_to_string(FILE).expect("tests/it/golden_digests.txt");
    let want: Vec<&str> = want.lines().collect();
    let changed: Vec<String> = lines
        .iter()
        .zip(&want)
        .filter(|(a, b)| a != b)
        .map(|(a, b)| format!("  now  {a}\n  was  {b}"))
        .collect();
    assert_eq!(lines.len(), want.len(), "the list of runs changed");
    assert!(
        changed.is_empty(),
        "results changed (regenerate with CELLFLIP_BLESS=1 only if on purpose):\n{}",
        changed.join("\n")
    );
}
