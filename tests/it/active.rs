//! The active spans (docs/architecture.md, "Active spans"): a step whose grid passes visit only
//! the active cells leaves the state bit for bit as one whose passes visit every cell, on a
//! drop that falls through air (most lines of the box hold no liquid, and the ones the drop
//! leaves empty go inactive behind it) and lands in its pool.

use crate::common::{load, simulation};
use cellflip::grid::active::Active;
use cellflip::methods::MethodKind;
use cellflip::scene::Overrides;
use cellflip::stages::markings::{CellKind, Markings};

/// Steps `name` at `cells` twice, once as the program does and once with every cell active
/// before each step, and checks that the reports and states agree exactly.
fn same_as_every_cell_active<const D: usize>(name: &str, cells: usize, method: MethodKind) {
    let o = Overrides {
        cells: Some(cells),
        method: Some(method),
        ..Default::default()
    };
    let scene = load(name, &o);
    let (mut sparse, mut whole) = (
        simulation::<D>(&scene, false),
        simulation::<D>(&scene, false),
    );
    let all = Active::all(&whole.state.grid);
    let n = whole.state.grid.num_cells();
    let mut fewest = n;
    for step in 1..=60 {
        let active = sparse.state.active.num_cells();
        fewest = fewest.min(active);
        whole.state.active = all.clone();
        let (a, b) = (sparse.step().unwrap(), whole.step().unwrap());
        let at = format!("{name} at {cells} with {method:?}, step {step}");
        assert_eq!(a.max_speed, b.max_speed, "{at}: largest speed");
        assert_eq!(
            (a.dt_secs, a.pcg.iterations),
            (b.dt_secs, b.pcg.iterations),
            "{at}"
        );
        let (s, w) = (&sparse.state, &whole.state);
        assert_eq!(s.particles.pos, w.particles.pos, "{at}: positions");
        assert_eq!(s.particles.vel, w.particles.vel, "{at}: velocities");
        assert_eq!(s.markings.kind, w.markings.kind, "{at}: cell kinds");
        let depths = |m: &Markings| (0..m.kind.len()).map(|c| m.depth(c)).collect::<Vec<_>>();
        assert_eq!(depths(&s.markings), depths(&w.markings), "{at}: depths");
        // The grid velocity the next step starts from, on the faces of fluid cells (where
        // the band reads it).
        let fluid = |c: usize| s.markings.kind[c] == CellKind::Fluid;
        for ax in 0..D {
            for i in 0..s.grid.num_faces(ax) {
                if s.grid.face_cells(ax, i).any(fluid) {
                    let (u, v) = (s.velocity.comp[ax][i], w.velocity.comp[ax][i]);
                    assert_eq!(u, v, "{at}: grid velocity, face {i} of component {ax}");
                }
            }
        }
    }
    // The test means something only where most of the box was skipped.
    assert!(
        fewest < n / 2,
        "{name}: {fewest} of {n} cells active at the fewest"
    );
}

#[test]
fn a_falling_drop_steps_as_with_every_cell_active_2d() {
    same_as_every_cell_active::<2>("drop-2d", 128, MethodKind::Ccp);
    same_as_every_cell_active::<2>("drop-2d", 128, MethodKind::Flip);
}

#[test]
fn a_falling_drop_steps_as_with_every_cell_active_3d() {
    same_as_every_cell_active::<3>("drop-3d", 40, MethodKind::Ccp);
    same_as_every_cell_active::<3>("drop-3d", 40, MethodKind::Nbflip);
}
