//! Envelope tests (issue 72): every method on every scene of the paper's matrix (sec. scenes),
//! at small sizes and over durations that include the impact or the obstacle's travel, stays
//! within what its paper and its reference run allow. Each bound names its source beside it.
//! Every step also checks the invariants inside `step`.
//!
//! The bounds:
//! - **Liquid remains** (every method): the volume at the end is at least [`LIQUID_REMAINS`] of
//!   `V*` (nbflip may hold no particle where its liquid has no free surface). No method's description allows liquid to
//!   vanish from a closed tank; the lowest minimum of any whole run of the paper's matrix is
//!   FLIP's 16.4 % on dam-1ppc-2d over 8 s (docs/results-paper.md, binary of 9816f07).
//! - **ccp** never goes below 100 % (Levi, sec. Evaluation: "Our method uses constrained
//!   optimization and cannot lose volume").
//! - **nbflip** keeps at least FLIP's minimum on the same run, less [`NBFLIP_BELOW_FLIP`], and
//!   at most [`NBFLIP_MOST`] (Levi: "The volume of the narrow band FLIP fluctuates"; Ferstl et
//!   al. 2016 keep the liquid in a level set that the grid carries, so it loses less than FLIP,
//!   which it is built on; the upper bound is issue 72's target for the paper's 2D scenes).
//! - **The lid of compress-2d**: under ccp it never ends below the height the liquid's volume
//!   allows (`V* / width`, less half a cell: a cell is solid when its centre is covered);
//!   under a `naive` obstacle it stops on the liquid, at least [`LID_ON_THE_LIQUID`] above the
//!   floor (Levi, sec. Evaluation, compressing: "the obstacle stops and waits until the fluid
//!   clears the cells that the obstacle is moving into").
//! - **A `naive` obstacle never covers liquid** under nbflip, on every scene: the cells of
//!   liquid it newly covers (`nbflip_carved`) are 0 every step (for the particle methods the
//!   invariant "no particle in a solid" says the same every step).

use crate::common::{self, load};
use cellflip::methods::nbflip::NbflipReport;
use cellflip::methods::MethodKind;
use cellflip::scene::{Overrides, Scene};

/// The least volume, % of `V*`, any method may end with.
const LIQUID_REMAINS: f64 = 10.0;
/// How far below FLIP's minimum nbflip's minimum may lie, points of `V*`: the spread of FLIP's
/// own minimum over seeds at these sizes is a few points.
const NBFLIP_BELOW_FLIP: f64 = 5.0;
/// The most nbflip's volume may reach, % of `V*`.
const NBFLIP_MOST: f64 = 120.0;
/// How far above the floor a `naive` lid on compress-2d must end, cells: the liquid left under
/// it (at least [`LIQUID_REMAINS`] of `V*`, 5 cells at 50 cells) keeps it off the floor.
const LID_ON_THE_LIQUID: f64 = 1.0;

/// What one run did.
#[derive(Debug)]
struct Envelope {
    volume_min: f64,
    volume_max: f64,
    volume_end: f64,
    particles_end: usize,
    /// `V*` and the liquid's volume at the end, cells.
    target_cells: f64,
    /// The first obstacle's lowest point at the end, cells, and the tank's width in cells.
    bottom_end: Option<f64>,
    width: f64,
    /// Whether the obstacles wait for the liquid (`naive`).
    naive: bool,
    /// Cells of liquid obstacles newly covered, over the run (nbflip's report; 0 otherwise).
    carved: usize,
}

fn scene(name: &str, method: MethodKind, cells: Option<usize>, duration: f64) -> Scene {
    let o = Overrides {
        method: Some(method),
        cells,
        duration: Some(duration),
        ..Default::default()
    };
    load(name, &o)
}

fn run<const D: usize>(scene: &Scene) -> Envelope {
    let (mut lo, mut hi, mut carved) = (f64::INFINITY, f64::NEG_INFINITY, 0);
    let runner = common::run::<D>(scene, None, |_, rep| {
        lo = lo.min(rep.volume_percent);
        hi = hi.max(rep.volume_percent);
        carved += rep.method_report::<NbflipReport>().map_or(0, |r| r.carved);
    });
    let s = &runner.sim.state;
    Envelope {
        volume_min: lo,
        volume_max: hi,
        volume_end: s.volume_percent(),
        particles_end: s.particles.len(),
        target_cells: s.target_volume,
        bottom_end: s.solids.obstacles.first().map(|o| o.bottom()),
        width: s.grid.dims[0] as f64,
        naive: scene.obstacle_mode == cellflip::stages::solids::ObstacleMode::Naive,
        carved,
    }
}

/// Runs every method on `name` (at `cells`, for `duration` s) and checks the bounds.
fn check_scene(name: &str, cells: Option<usize>, duration: f64) {
    let dim = scene(name, MethodKind::Flip, cells, duration).dim();
    let go = |m: MethodKind| {
        let s = scene(name, m, cells, duration);
        let e = match dim {
            2 => run::<2>(&s),
            _ => run::<3>(&s),
        };
        eprintln!("{name} {}: {e:?}", m.name());
        e
    };
    let flip = go(MethodKind::Flip);
    for &m in MethodKind::ALL {
        let e = if m == MethodKind::Flip { &flip } else { &go(m) };
        let at = format!("{name} {}", m.name());
        check_remains(&at, e);
        match m {
            MethodKind::Ccp => check_ccp(&at, e, name),
            MethodKind::Nbflip => check_nbflip(&at, e, &flip),
            _ => {}
        }
        if e.naive {
            check_naive(&at, e, name);
        }
    }
}

fn check_remains(at: &str, e: &Envelope) {
    assert!(
        e.volume_end >= LIQUID_REMAINS,
        "{at}: ends with {:.2} % of V* ({} particles): the liquid is gone",
        e.volume_end,
        e.particles_end
    );
}

fn check_ccp(at: &str, e: &Envelope, name: &str) {
    assert!(
        e.volume_min >= 100.0 - 1e-9,
        "{at}: volume fell to {:.4} %",
        e.volume_min
    );
    if name == "compress-2d" {
        let allowed = e.target_cells / e.width - 0.5;
        let bottom = e.bottom_end.expect("the lid");
        assert!(
            bottom >= allowed,
            "{at}: the lid ends at {bottom:.3} cells, below the {allowed:.3} the liquid allows"
        );
    }
}

fn check_nbflip(at: &str, e: &Envelope, flip: &Envelope) {
    assert!(
        e.volume_min >= flip.volume_min - NBFLIP_BELOW_FLIP && e.volume_max <= NBFLIP_MOST,
        "{at}: volume {:.2} .. {:.2} %, outside [FLIP's minimum {:.2} - {NBFLIP_BELOW_FLIP}, {NBFLIP_MOST}]",
        e.volume_min,
        e.volume_max,
        flip.volume_min
    );
}

fn check_naive(at: &str, e: &Envelope, name: &str) {
    assert_eq!(
        e.carved, 0,
        "{at}: a naive obstacle covered cells of liquid"
    );
    if name == "compress-2d" {
        let bottom = e.bottom_end.expect("the lid");
        assert!(
            bottom >= LID_ON_THE_LIQUID,
            "{at}: the lid ends at {bottom:.3} cells: it did not stop on the liquid"
        );
    }
}

#[test]
fn dam_2d() {
    check_scene("dam-2d", None, 1.0);
}

#[test]
fn dam_1ppc_2d() {
    check_scene("dam-1ppc-2d", None, 1.0);
}

#[test]
fn drop_2d() {
    check_scene("drop-2d", None, 0.8);
}

#[test]
fn compress_2d() {
    check_scene("compress-2d", None, 2.0);
}

#[test]
fn spiral_2d() {
    check_scene("spiral-2d", None, 1.0);
}

#[test]
fn falling_obstacle_2d() {
    check_scene("falling-obstacle-2d", None, 1.2);
}

#[test]
fn falling_obstacle_zero_bc_2d() {
    check_scene("falling-obstacle-zero-bc-2d", None, 1.2);
}

#[test]
fn large_obstacle_2d() {
    check_scene("large-obstacle-2d", None, 1.2);
}

#[test]
fn dam_3d() {
    check_scene("dam-3d", Some(24), 0.6);
}

#[test]
fn drop_3d() {
    check_scene("drop-3d", Some(24), 0.5);
}

#[test]
fn falling_obstacle_3d() {
    check_scene("falling-obstacle-3d", Some(24), 0.8);
}

#[test]
fn large_obstacle_3d() {
    check_scene("large-obstacle-3d", Some(36), 0.8);
}
