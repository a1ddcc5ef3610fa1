//! Method nbflip (Ferstl et al. 2016): the band holds the particles after every step, a deep
//! tank holds a fraction of flip's particles that follows from the band's depth, a tank at rest
//! stays at rest with its volume, resampling and the velocity combination give known answers on
//! hand-made fields. Every run checks the invariants every step (inside `step`), among them
//! what resampling guarantees.

use crate::common::{load, run, run_at_rest, with};
use cellflip::grid::active::Active;
use cellflip::grid::{Grid, MacField, NearCells, Vector};
use cellflip::methods::nbflip::levelset::{particle_radius, LevelSet};
use cellflip::methods::nbflip::region::Region;
use cellflip::methods::nbflip::{combine, NbflipReport, Resampling};
use cellflip::methods::MethodKind;
use cellflip::particles::Particles;
use cellflip::scene::{Overrides, Scene};
use cellflip::stages::markings::Markings;
use cellflip::stages::solids::{ObstacleMode, Solids};
use cellflip::stages::transfer::particles_to_grid;
use cellflip::step::{Simulation, StepReport};
use rand::rngs::StdRng;
use rand::SeedableRng;

fn nbflip<const D: usize>(rep: &StepReport<D>) -> &NbflipReport {
    rep.method_report::<NbflipReport>()
        .expect("an nbflip report")
}

/// A tank `cells` wide along every axis, water `depth` cells deep, at rest.
fn tank(dim: usize, cells: usize, depth: usize, method: MethodKind, r: u32) -> Scene {
    let h = depth as f64 / cells as f64;
    let (size, max) = match dim {
        2 => ("[1.0, 1.0]".to_string(), format!("[1.0, {h}]")),
        _ => ("[1.0, 1.0, 1.0]".to_string(), format!("[1.0, {h}, 1.0]")),
    };
    let min = if dim == 2 {
        "[0.0, 0.0]"
    } else {
        "[0.0, 0.0, 0.0]"
    };
    // R is a key of the band methods only (flip refuses it).
    let band_r = match method {
        MethodKind::Flip => String::new(),
        _ => format!("band_r = {r}\n"),
    };
    let text = format!(
        "name = \"tank\"\ndim = {dim}\n[domain]\nsize = {size}\ncells = {cells}\n\
         [simulation]\nmethod = \"{}\"\n{band_r}duration = 1.0\nppc = {}\nmax_dt = 0.01\n\
         [[fluid]]\nshape = \"box\"\nmin = {min}\nmax = {max}\n",
        method.name(),
        2usize.pow(dim as u32),
    );
    Scene::parse("tank", &text, &Overrides::default()).unwrap()
}

/// After every step every particle lies inside the liquid and at most `R` below its surface,
/// or (a particle seeded this step) at most half a cell diagonal below a band cell's centre.
fn particles_in_band<const D: usize>(sim: &Simulation<D>, rep: &StepReport<D>) {
    let nb = nbflip(rep);
    let lowest = -(nb.band_r as f64) - particle_radius(D);
    for x in &sim.state.particles.pos {
        let phi = nb.phi.interpolate(&sim.state.grid, x);
        assert!(
            (lowest..=0.0).contains(&phi),
            "{D}D step {}: a particle at {:?} has phi = {phi}",
            sim.state.steps,
            x.as_slice()
        );
    }
}

#[test]
fn particles_stay_in_the_band_on_the_breaking_dam_2d_and_3d() {
    let scene = load("dam-2d", &with(MethodKind::Nbflip, None));
    let mut seeded = 0;
    run::<2>(&scene, Some(300), |sim, rep| {
        particles_in_band(sim, rep);
        seeded += nbflip(rep).seeded;
    });
    assert!(seeded > 0, "the collapsing column needs new band particles");
    let o = Overrides {
        cells: Some(24),
        ..with(MethodKind::Nbflip, None)
    };
    run::<3>(&load("dam-3d", &o), Some(40), particles_in_band);
}

/// Particles held at rest in a tank `depth` deep with band `r`, after `steps` steps.
fn held<const D: usize>(depth: usize, r: u32, method: MethodKind, steps: u64) -> usize {
    let runner = run::<D>(&tank(D, 16, depth, method, r), Some(steps), |_, _| {});
    runner.sim.state.particles.len()
}

/// Every step's particles and level set, and the cells the level set was worked on.
fn steps_of<const D: usize>(scene: &Scene, steps: u64) -> Vec<(Particles<D>, NbflipReport)> {
    let mut out = vec![];
    run::<D>(scene, Some(steps), |sim, rep| {
        out.push((sim.state.particles.clone(), nbflip(rep).clone()))
    });
    out
}

#[test]
fn the_narrow_level_set_gives_the_dense_one_s_results_2d_and_3d() {
    // The same particles every step, the same level set wherever the dense one is re-marched
    // (between its caps -(R + 4) and 5) and the same side everywhere else, while the narrow
    // one is worked on a part of the grid only. The dam-2d run reaches its emitter (2.5 s).
    fn check<const D: usize>(name: &str, cells: Option<usize>, steps: u64, most: Option<f64>) {
        let o = Overrides {
            cells,
            ..with(MethodKind::Nbflip, None)
        };
        let narrow = load(name, &o);
        let mut dense = narrow.clone();
        dense.method.nbflip.narrow = false;
        let (a, b) = (steps_of::<D>(&narrow, steps), steps_of::<D>(&dense, steps));
        let mut worked = vec![];
        for (step, ((pn, n), (pd, d))) in a.iter().zip(&b).enumerate() {
            let at = format!("{name} step {step}");
            assert_eq!(pn, pd, "{at}: particles differ");
            let caps = (-(d.band_r as f64) - 4.0, 5.0);
            let mut marched = 0;
            for (c, (&vn, &vd)) in n.phi.phi.iter().zip(&d.phi.phi).enumerate() {
                if caps.0 < vd && vd < caps.1 {
                    assert_eq!(vn, vd, "{at}: cell {c}");
                    marched += 1;
                }
                assert_eq!(vn < 0.0, vd < 0.0, "{at}: cell {c} on the other side");
            }
            assert!(marched > 0, "{at}");
            assert_eq!(d.cells_worked, d.phi.phi.len(), "{at}: dense");
            worked.push(n.cells_worked as f64 / d.cells_worked as f64);
        }
        assert_eq!(a.len(), steps as usize);
        // The deep pools' liquid is mostly far from the surface: not worked on.
        if let Some(most) = most {
            let last = worked[worked.len() - 1];
            assert!(last <= most, "{name}: worked on {last:.2} of the grid");
        }
    }
    check::<2>("dam-2d", None, 300, None);
    check::<3>("dam-3d", Some(24), 12, None);
    check::<2>("deep-pool-2d", Some(128), 60, Some(0.5));
    // At 48 cells the margin (10 cells into the liquid and 8 into the air for R = 3, whole
    // tiles) still spans most of the depth.
    check::<3>("deep-pool-3d", Some(48), 15, Some(0.7));
}

#[test]
fn a_deep_tank_holds_the_band_s_share_of_flip_s_particles_2d_and_3d() {
    // Particles lie at most R below the level set's zero, which the particles' spheres put
    // between the top particles and a sphere radius above them: R - radius to R + 1 layers
    // of mu per cell, out of the depth's layers.
    fn check<const D: usize>(depth: usize, r: u32) {
        let flip = held::<D>(depth, r, MethodKind::Flip, 3);
        let nb = held::<D>(depth, r, MethodKind::Nbflip, 3);
        let layers = nb as f64 / flip as f64 * depth as f64;
        let r = r as f64;
        assert!(
            (r - particle_radius(D)..=r + 1.0).contains(&layers),
            "{D}D, depth {depth}, R = {r}: nbflip holds {nb} of flip's {flip} particles, {layers:.2} layers"
        );
    }
    check::<2>(14, 3);
    check::<2>(14, 6);
    check::<3>(12, 3);
}

#[test]
fn a_tank_at_rest_stays_at_rest_and_keeps_its_volume_2d_and_3d() {
    fn check<const D: usize>(steps: u64) {
        let scene = tank(D, 16, 10, MethodKind::Nbflip, 3);
        let (_, fastest) = run_at_rest::<D>(&scene, steps, |rep, at| {
            assert_eq!(nbflip(rep).deleted(), 0, "{at}");
        });
        // Gravity adds 3.2 cells/s a step here; the projection takes it back to the
        // solver's tolerance.
        assert!(fastest < 1e-2, "{D}D: a particle reached {fastest} cells/s");
    }
    check::<2>(200);
    check::<3>(40);
}

#[test]
fn resampling_deletes_and_seeds_by_the_level_set_2d() {
    // Surface at y = 6, R = 3, mu = 4; the surface layer is phi > -1.43 (rows 5 and up).
    let g = Grid::new([6, 8]);
    let phi = LevelSet::sampled(&g, |x| x[1] - 6.0);
    let solid = vec![false; g.num_cells()];
    let rs = Resampling {
        grid: &g,
        phi: &phi,
        solid: &solid,
        cells: &Region::all(&g).cells,
        r: 3.0,
        mu: 4,
    };
    let mut p = Particles::<2>::default();
    let v = Vector::<2>::zeros();
    p.push(Vector::<2>::new(0.5, 6.5), v); // outside the liquid
    p.push(Vector::<2>::new(0.5, 2.4), v); // phi = -3.6: below the band
    for k in 0..10 {
        p.push(Vector::<2>::new(2.05 + 0.09 * k as f64, 4.5), v); // row 4: 2 over 2 mu
        p.push(Vector::<2>::new(3.05 + 0.09 * k as f64, 5.5), v); // surface row: never thinned
    }
    let mut u = MacField::zeros(&g);
    u.comp[0].iter_mut().for_each(|v| *v = 0.7);
    let rep = rs.run(&mut p, &u, &mut StdRng::seed_from_u64(1));
    assert_eq!((rep.outside, rep.below, rep.crowded), (1, 1, 2));
    // Rows 3 (phi = -2.5) and 4 (phi = -1.5) are seedable; all their cells but (2, 4) get 4.
    assert_eq!(rep.seeded, 11 * 4);
    assert_eq!(p.len(), 8 + 10 + 44);
    let mut count = vec![0; g.num_cells()];
    for (x, v) in p.pos.iter().zip(&p.vel).skip(18) {
        let c = g.cell_coords(g.cell_index_of(x));
        assert!(c[1] == 3 || (c[1] == 4 && c[0] != 2), "seeded at {c:?}");
        assert!((v[0] - 0.7).abs() < 1e-12 && v[1] == 0.0);
        count[g.cell_index(c)] += 1;
    }
    assert!(count.iter().all(|&n| n == 0 || n == 4));
}

#[test]
fn the_combination_takes_particles_in_the_band_and_the_grid_below_3d() {
    // A full 4 x 4 x 10 column (the tank's whole footprint), surface at z = 10 in a 12-high
    // tank; R = 3, so faces at phi >= -2 with particle weight keep the particles' +1 along z,
    // deeper ones take the grid's -7. Particles only in the top four layers.
    let g = Grid::new([4, 4, 12]);
    let phi = LevelSet::sampled(&g, |x| x[2] - 10.0);
    let mut pos = vec![];
    for c in 0..g.num_cells() {
        let cc = g.cell_coords(c);
        if (6..10).contains(&cc[2]) {
            pos.push(g.center(cc));
        }
    }
    let vel = vec![Vector::<3>::new(0.0, 0.0, 1.0); pos.len()];
    let keep = NearCells::new(&g, phi.phi.iter().map(|&v| v < 0.0).collect());
    let solids = Solids::new(&g, &[], &[], ObstacleMode::Couple);
    let (m, _) = Markings::compute_keeping(&g, &pos, solids.cells(), Some(&keep));
    let (mut u, mut known) = particles_to_grid(&g, &pos, &vel);
    let mut grid_u = MacField::zeros(&g);
    grid_u.comp[2].iter_mut().for_each(|v| *v = -7.0);
    // The fluid cells alone as the active set: the least one the combination may be given.
    let active = Active::around(&g, |c| m.is_fluid(c), 0);
    combine(&g, &m, &active, &phi, 3.0, &mut u, &mut known, &grid_u);
    for (i, (&k, &v)) in known[2].iter().zip(&u.comp[2]).enumerate() {
        let z = g.face_coords(2, i)[2];
        match z {
            // phi at the face is z - 10: particles' in the combine band where they gave weight.
            8..=10 => assert!(k && (v - 1.0).abs() < 1e-12, "z = {z}"),
            // Below the combine band, or no particles: the grid's.
            0..=7 => assert!(k && v == -7.0, "z = {z}"),
            // Faces in the air: left to the extrapolation.
            _ => assert!(!k, "z = {z}"),
        }
    }
}

#[test]
fn the_readme_s_comparison_scene_runs_ccp_with_the_band_and_nbflip_at_the_same_depth() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/scenes/dam-2d-band.toml");
    let ccp = load(path, &Overrides::default());
    let m = &ccp.method;
    assert_eq!(
        (m.kind, m.band().map(|b| (b.variant, b.r))),
        (MethodKind::Ccp, Some(("paths", 6)))
    );
    let nb = load(path, &with(MethodKind::Nbflip, None));
    run::<2>(&nb, Some(3), |_, rep| assert_eq!(nbflip(rep).band_r, 6));
}
