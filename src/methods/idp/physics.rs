//! Method idp's step: the hooks it implements (see the module doc of `super`).

use super::record::{ErrorClass, IdpReport};
use crate::draw::Log;
use crate::grid::active::{par_runs, Active};
use crate::grid::{for_each_cell_weight, Grid, MacField, Vector};
use crate::methods::seam::{FluidMethod, MethodRecording, MethodReport};
use crate::solvers::pcg::PcgSettings;
use crate::stages::advect::{displace, CELL_MARGIN};
use crate::stages::pressure::Poisson;
use crate::stages::solids::clearing_distance;
use crate::stages::{ParticlesMut, State, StepError};
use rand::seq::SliceRandom;
use rand::Rng;
use rayon::prelude::*;
use std::collections::HashMap;

/// Bound on the density error per step, `|s| <= 0.5` (reference `knComputeDensity`; "as
/// suggested in the paper to avoid displacement of more than half a cell at a time", Blub).
pub const CLAMP: f64 = 0.5;

/// How far beyond a solid's surface the push-out puts a particle, cells (our `CELL_MARGIN`,
/// the reference's 0.01).
pub const PUSH_MARGIN: f64 = CELL_MARGIN;

/// Resampling trigger and the density error resampled cells keep (reference
/// `resampeOverfullCells`: `s < -1`, then `s = -1`).
pub const RESAMPLE_BELOW: f64 = -1.0;

/// Most arrows a step records (every k-th particle beyond that).
const MAX_ARROWS: usize = 4000;

/// Implicit density projection in a running simulation.
pub struct IdpSim<const D: usize> {
    resample: bool,
    /// This step's report, until the step ends.
    step: Option<IdpReport<D>>,
}

impl<const D: usize> IdpSim<D> {
    pub fn new(resample: bool) -> Self {
        IdpSim {
            resample,
            step: None,
        }
    }
}

impl<const D: usize> FluidMethod<D> for IdpSim<D> {
    fn correct_positions(
        &mut self,
        s: ParticlesMut<'_, D>,
        _penalty: Option<&[f64]>,
    ) -> Result<(), StepError> {
        let settings = PcgSettings {
            tolerance: s.config.pressure_tolerance,
            preconditioner: s.config.pressure_preconditioner,
            ..Default::default()
        };
        let inputs = Inputs {
            grid: s.grid,
            solid: &s.solids.solid,
            particle_free: s.solids.particle_free(),
            per_axis: s.config.per_axis,
            pcg: &settings,
        };
        let resample = self.resample.then_some(Resample {
            velocity: s.velocity,
            rng: s.rng,
        });
        let p = s.particles;
        let rep = project_density(&inputs, &mut p.pos, &mut p.vel, resample);
        self.step = Some(rep);
        Ok(())
    }

    fn finish_step(&mut self, _s: &State<D>) -> Box<dyn MethodReport<D>> {
        Box::new(self.step.take().expect("idp projected this step"))
    }
}

impl<const D: usize> MethodRecording<D> for IdpSim<D> {
    fn record_setup(&self, log: &mut dyn Log<D>) {
        log.classes("world/idp/density_error", &ErrorClass::table());
    }
}

/// What the projection reads besides the particles.
pub struct Inputs<'a, const D: usize> {
    pub grid: &'a Grid<D>,
    /// Every solid cell (static solids and obstacles).
    pub solid: &'a [bool],
    /// Cells no particle may be moved into.
    pub particle_free: &'a [bool],
    /// Particles per cell along an axis, `k`; `mu = k^D`.
    pub per_axis: usize,
    pub pcg: &'a PcgSettings,
}

/// What resampling needs: the grid velocity for the new particles, and randomness.
pub struct Resample<'a, const D: usize, R: Rng> {
    pub velocity: &'a MacField<D>,
    pub rng: &'a mut R,
}

/// The projection: density error, surface rule, clamp, second solve, displacement, move.
///
/// Its grid passes visit the cells within one of a particle's cell ([`near_particles`]) and
/// the faces beside them; the other cells' values are those of no particle (0, and class
/// [`ErrorClass::NotFluid`]), left in fresh zeroed arrays.
pub fn project_density<const D: usize, R: Rng>(
    inp: &Inputs<'_, D>,
    pos: &mut [Vector<D>],
    vel: &mut [Vector<D>],
    resample: Option<Resample<'_, D, R>>,
) -> IdpReport<D> {
    let grid = inp.grid;
    let mu = inp.per_axis.pow(D as u32) as f64;
    let near = near_particles(grid, pos);
    let fluid = fluid_cells(grid, inp.solid, pos, &near);
    let mut rep = IdpReport::default();
    let (push, pushed) = push_field(grid, inp.solid, pos);
    rep.pushed = pushed;
    let mut s = density_error(inp, pos, &fluid, &push, &near);
    rep.overdense = near.count_cells(|c| s[c] < -1.0 / mu);
    if let Some(r) = resample {
        rep.resampled = resample_degenerate(grid, pos, vel, &mut s, &fluid, &near, r);
    }
    let in_solve = surface_rule(grid, inp.solid, &fluid, &mut s, &near);
    rep.surface = near.count_cells(|c| fluid[c] && !in_solve[c]);
    rep.clamped = near.count_cells(|c| s[c] != RESAMPLE_BELOW && s[c].abs() > CLAMP);
    par_runs(near.cells(), &mut s).for_each(|(_, run)| {
        for e in run.iter_mut().filter(|e| **e != RESAMPLE_BELOW) {
            *e = e.clamp(-CLAMP, CLAMP);
        }
    });
    let system = Poisson::new(grid, |c| in_solve[c], inp.solid, &near);
    let rhs = system.cells().iter().map(|&c| s[c]).collect();
    let cold = vec![0.0; system.cells().len()];
    let (phi, pcg) = system.solve(rhs, cold, inp.pcg);
    let phi = system.per_cell(&phi);
    rep.pcg = pcg;
    let d = displacement(grid, inp.solid, &phi, push, &near);
    rep.class = vec![ErrorClass::NotFluid as u8; s.len()];
    par_runs(near.cells(), &mut rep.class).for_each(|(r, run)| {
        for (c, v) in r.zip(run) {
            *v = ErrorClass::of(fluid[c], in_solve[c], s[c]) as u8;
        }
    });
    move_particles(grid, inp.particle_free, &d, pos, &mut rep);
    rep
}

/// The cells within one of a particle's cell: every cell the tent weights reach, with the
/// face neighbours the surface rule looks at, and the faces beside them hold every face a
/// particle's displacement is interpolated from.
fn near_particles<const D: usize>(grid: &Grid<D>, pos: &[Vector<D>]) -> Active<D> {
    Active::around_points(grid, pos.par_iter(), 1)
}

/// The push-out field of step 2 and how many particles it pushes.
fn push_field<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    pos: &[Vector<D>],
) -> (MacField<D>, usize) {
    let mut push = MacField::zeros(grid);
    let inside: Vec<&Vector<D>> = pos
        .iter()
        .filter(|x| solid[grid.cell_index_of(x)])
        .collect();
    if inside.is_empty() {
        return (push, 0);
    }
    // How far each solid cell is from the nearest non-solid one (1 next to it), for particles
    // deep inside: over the solids that hold particles, as far as they are connected (the
    // distance of a cell depends on its own solid's cells alone, and a push reads the
    // particle's cell and its solid neighbours).
    let held = inside.iter().map(|x| grid.cell_index_of(x));
    let solid_cells = grid.components_of(held, |c| solid[c]);
    let depth = clearing_distance(grid, &solid_cells, &vec![false; solid.len()]);
    let mut pushed = 0;
    for x in &inside {
        let Some((axis, d)) = push_out(grid, solid, &depth, x) else {
            continue;
        };
        pushed += 1;
        let c = grid.cell_coords(grid.cell_index_of(x));
        for side in [0, 1] {
            let mut f = c;
            f[axis] += side;
            let i = grid.face_index(axis, f);
            if d.abs() > push.comp[axis][i].abs() {
                push.comp[axis][i] = d;
            }
        }
    }
    (push, pushed)
}

/// The push-out of a particle at `x` in a solid cell: along the axis of the nearest face into a
/// non-solid cell of the domain, to [`PUSH_MARGIN`] beyond it; or, with no such face, one cell
/// towards the nearest non-solid cell (`depth` falls by one), at most one cell per step as in
/// the reference. `None` when the solid encloses the cell.
pub fn push_out<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    depth: &[u32],
    x: &Vector<D>,
) -> Option<(usize, f64)> {
    let c = grid.cell_coords(grid.cell_index_of(x));
    let here = depth[grid.cell_index(c)];
    let mut best: Option<(usize, f64)> = None;
    for axis in 0..D {
        for dir in [-1, 1] {
            let Some(nb) = grid.neighbor(c, axis, dir) else {
                continue;
            };
            let nb = grid.cell_index(nb);
            let to_face = if dir > 0 {
                c[axis] as f64 + 1.0 - x[axis]
            } else {
                x[axis] - c[axis] as f64
            };
            let step = if !solid[nb] {
                to_face + PUSH_MARGIN
            } else if depth[nb] < here && here != u32::MAX {
                1.0
            } else {
                continue;
            };
            if best.is_none_or(|(_, b)| step < b.abs()) {
                best = Some((axis, step * dir as f64));
            }
        }
    }
    best
}

/// `k` sample offsets per axis from the cell centre, `(a + 1/2)/k - 1/2`.
fn sample_offsets(k: usize) -> impl Iterator<Item = f64> {
    (0..k).map(move |a| (a as f64 + 0.5) / k as f64 - 0.5)
}

/// The tent-kernel share that a neighbour cell regularly sampled with `k^D` particles gives
/// to a cell's centre: per axis `S(0) = sum (1 - |o|)` for the same index, `S(1) = sum_{o > 0} o`
/// for a neighbour; a neighbour at offset `n` gives `prod_a S(|n_a|) / mu`. The shares of the
/// `3^D` cells sum to 1 (for `k = 2`: 0.75 + 0.25 + ... the reference's `N = {0.25, 0.75, 0.25}`
/// times two samples per axis).
pub struct SolidShare {
    same: f64,
    next: f64,
    mu: f64,
}

impl SolidShare {
    pub fn new(k: usize, dim: usize) -> Self {
        Self {
            same: sample_offsets(k).map(|o| 1.0 - o.abs()).sum(),
            next: sample_offsets(k).filter(|&o| o > 0.0).sum(),
            mu: k.pow(dim as u32) as f64,
        }
    }

    /// The share of the neighbour at `offset` (entries -1, 0 or 1).
    pub fn of<const D: usize>(&self, offset: &[i64; D]) -> f64 {
        offset
            .iter()
            .map(|&o| if o == 0 { self.same } else { self.next })
            .product::<f64>()
            / self.mu
    }
}

/// The density error `s` of every cell holding particles outside solids (0 elsewhere), as
/// steps 1-3 compute it, before the surface rule and the clamp.
pub fn density_errors<const D: usize>(inp: &Inputs<'_, D>, pos: &[Vector<D>]) -> Vec<f64> {
    let near = near_particles(inp.grid, pos);
    let fluid = fluid_cells(inp.grid, inp.solid, pos, &near);
    let (push, _) = push_field(inp.grid, inp.solid, pos);
    density_error(inp, pos, &fluid, &push, &near)
}

/// Step 1: non-solid cells holding a particle (all of them in `near`).
fn fluid_cells<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    pos: &[Vector<D>],
    near: &Active<D>,
) -> Vec<bool> {
    let mut held = vec![false; grid.num_cells()];
    pos.iter().for_each(|x| held[grid.cell_index_of(x)] = true);
    near.flags(grid, |c| held[c] && !solid[c])
}

/// Step 3: the density error of every fluid cell (0 elsewhere; all of them in `near`).
fn density_error<const D: usize>(
    inp: &Inputs<'_, D>,
    pos: &[Vector<D>],
    fluid: &[bool],
    push: &MacField<D>,
    near: &Active<D>,
) -> Vec<f64> {
    let grid = inp.grid;
    let mu = inp.per_axis.pow(D as u32) as f64;
    let density = tent_density(grid, pos, near);
    let share = SolidShare::new(inp.per_axis, D);
    let offsets: Vec<[i64; D]> = (0..3usize.pow(D as u32))
        .map(|code| std::array::from_fn(|k| (code / 3usize.pow(k as u32) % 3) as i64 - 1))
        .filter(|o| o.iter().any(|&v| v != 0))
        .collect();
    let mut s = vec![0.0; grid.num_cells()];
    let error = |c: usize| {
        let cc = grid.cell_coords(c);
        let mut s = 1.0 - density[c] / mu;
        for o in &offsets {
            let nb: Option<usize> = (0..D).try_fold(0, |idx, k| {
                let i = cc[k] as i64 + o[k];
                (0..grid.dims[k] as i64)
                    .contains(&i)
                    .then(|| idx + i as usize * grid.cell_stride(k))
            });
            if nb.is_none_or(|n| inp.solid[n]) {
                s -= share.of(o);
            }
        }
        // The push-out's divergence (right minus left faces).
        for a in 0..D {
            let mut f = cc;
            let left = push.comp[a][grid.face_index(a, f)];
            f[a] += 1;
            s += push.comp[a][grid.face_index(a, f)] - left;
        }
        s
    };
    par_runs(near.cells(), &mut s).for_each(|(r, run)| {
        for (c, v) in r.zip(run).filter(|(c, _)| fluid[*c]) {
            *v = error(c);
        }
    });
    s
}

/// `sum_p w_c(x_p)` per cell, in a fixed number of chunks summed in order (the same result
/// whatever the thread count); the cells of `near` hold every weight.
fn tent_density<const D: usize>(grid: &Grid<D>, pos: &[Vector<D>], near: &Active<D>) -> Vec<f64> {
    const CHUNKS: usize = 4;
    let chunk = pos.len().div_ceil(CHUNKS).max(1);
    let partials: Vec<Vec<f64>> = pos
        .par_chunks(chunk)
        .map(|xs| {
            let mut acc = vec![0.0; grid.num_cells()];
            xs.iter()
                .for_each(|x| for_each_cell_weight(grid, x, |i, w| acc[i] += w));
            acc
        })
        .collect();
    let mut density = vec![0.0; grid.num_cells()];
    par_runs(near.cells(), &mut density).for_each(|(r, run)| {
        for (c, v) in r.zip(run) {
            *v = partials.iter().map(|p| p[c]).sum();
        }
    });
    density
}

/// Step 4: fluid cells with an empty face neighbour and `s > 0` leave the solve (`s = 0`).
/// Returns which cells are in the solve. Tested against the fluid cells before the rule (all
/// of them in `near`).
fn surface_rule<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    fluid: &[bool],
    s: &mut [f64],
    near: &Active<D>,
) -> Vec<bool> {
    let in_solve = near.flags(grid, |c| {
        let at_surface = grid.face_neighbors(c).any(|nb| !fluid[nb] && !solid[nb]);
        fluid[c] && !(at_surface && s[c] > 0.0)
    });
    par_runs(near.cells(), s).for_each(|(r, run)| {
        for (_, e) in r.zip(run).filter(|(c, _)| !in_solve[*c]) {
            *e = 0.0;
        }
    });
    in_solve
}

/// Step 7's face field: `phi_R - phi_L` between two non-solid cells, the push-out elsewhere;
/// on the faces beside `near`, which hold every row of `phi` and every push-out (0 beyond).
fn displacement<const D: usize>(
    grid: &Grid<D>,
    solid: &[bool],
    phi: &[f64],
    mut push: MacField<D>,
    near: &Active<D>,
) -> MacField<D> {
    for a in 0..D {
        near.par_for_each_face(grid, a, &mut push.comp[a], |_, f, v| {
            if f[a] == 0 || f[a] == grid.dims[a] {
                return;
            }
            let right = grid.cell_index(f);
            let left = right - grid.cell_stride(a);
            if !solid[left] && !solid[right] {
                *v = phi[right] - phi[left];
            }
        });
    }
    push
}

/// Moves every particle by the interpolated displacement; records the largest move and every
/// k-th one. A displacement longer than a cell on some axis (a large region at the clamp: the
/// clamp bounds `s`, not `grad phi`) is taken in sub-moves of at most a cell, each stopped at
/// solids like advection, so that no particle passes through a solid.
fn move_particles<const D: usize>(
    grid: &Grid<D>,
    particle_free: &[bool],
    d: &MacField<D>,
    pos: &mut [Vector<D>],
    rep: &mut IdpReport<D>,
) {
    let every = pos.len().div_ceil(MAX_ARROWS).max(1);
    let moved: Vec<(Vector<D>, Vector<D>)> = pos
        .par_iter_mut()
        .map(|x| {
            let before = *x;
            let step = d.interpolate(grid, x);
            let parts = step.amax().ceil().max(1.0);
            for _ in 0..parts as usize {
                *x = displace(grid, particle_free, x, step / parts);
            }
            (before, *x)
        })
        .collect();
    rep.max_displacement = moved
        .iter()
        .map(|(a, b)| (b - a).norm())
        .fold(0.0, f64::max);
    rep.moves = moved.into_iter().step_by(every).collect();
}

/// Resampling: every cell with `s <` [`RESAMPLE_BELOW`] gets its particles spread over distinct
/// sub-cells of a `q^D` sub-grid in random order, with the grid velocity, and `s` =
/// [`RESAMPLE_BELOW`]. Returns how many cells were resampled.
fn resample_degenerate<const D: usize, R: Rng>(
    grid: &Grid<D>,
    pos: &mut [Vector<D>],
    vel: &mut [Vector<D>],
    s: &mut [f64],
    fluid: &[bool],
    near: &Active<D>,
    r: Resample<'_, D, R>,
) -> usize {
    let degenerate: Vec<usize> = (near.each_cell())
        .filter(|&c| fluid[c] && s[c] < RESAMPLE_BELOW)
        .collect();
    if degenerate.is_empty() {
        return 0;
    }
    let mut members: HashMap<usize, Vec<usize>> = HashMap::new();
    for (j, x) in pos.iter().enumerate() {
        let c = grid.cell_index_of(x);
        if s[c] < RESAMPLE_BELOW && fluid[c] {
            members.entry(c).or_default().push(j);
        }
    }
    for &c in &degenerate {
        let members = &members[&c];
        let n = members.len();
        let q = (1..).find(|q: &usize| q.pow(D as u32) >= n).unwrap();
        let mut sub: Vec<usize> = (0..q.pow(D as u32)).collect();
        sub.shuffle(r.rng);
        let cell = grid.cell_coords(c);
        for (&j, &code) in members.iter().zip(&sub) {
            let x = Vector::<D>::from_fn(|k, _| {
                cell[k] as f64 + ((code / q.pow(k as u32)) % q) as f64 / q as f64 + 0.5 / q as f64
            });
            pos[j] = x;
            vel[j] = r.velocity.interpolate(grid, &x);
        }
        s[c] = RESAMPLE_BELOW;
    }
    degenerate.len()
}

/// The class of a cell's density error (the classes, their labels and colours: `super::record`).
impl ErrorClass {
    /// Errors within this of 0 count as at rest.
    const REST: f64 = 0.05;

    fn of(fluid: bool, in_solve: bool, s: f64) -> Self {
        match (fluid, in_solve) {
            (false, _) => ErrorClass::NotFluid,
            (true, false) => ErrorClass::Surface,
            _ if s <= -CLAMP => ErrorClass::OverClamped,
            _ if s < -Self::REST => ErrorClass::Over,
            _ if s <= Self::REST => ErrorClass::Rest,
            _ if s < CLAMP => ErrorClass::Under,
            _ => ErrorClass::UnderClamped,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::MethodKind;
    use crate::scene::{Overrides, Scene};
    use crate::solvers::pcg::{PcgStats, Preconditioner};
    use crate::step::Simulation;

    /// Particle positions and the second solve after a dam-2d step of idp, the steps before
    /// it with MIC(0) and that one with `last` (both solves of the step take it).
    fn idp_step(last: Preconditioner) -> (Vec<Vector<2>>, PcgStats) {
        let o = Overrides {
            cells: Some(80),
            method: Some(MethodKind::Idp),
            ..Default::default()
        };
        let scene = Scene::load("dam-2d", &o).unwrap();
        let mut sim = Simulation::<2>::new(scene.config(), &scene.method);
        for _ in 0..8 {
            sim.step().unwrap();
        }
        sim.state.config.pressure_preconditioner = last;
        let rep = sim.step().unwrap();
        let idp = rep.method_report::<IdpReport<2>>().expect("an idp step");
        (sim.state.particles.pos, idp.pcg)
    }

    #[test]
    fn the_second_solve_takes_the_scenes_preconditioner() {
        let (mic, mic_pcg) = idp_step(Preconditioner::Mic0);
        let (mg, mg_pcg) = idp_step(Preconditioner::Multigrid);
        assert!(mic_pcg.converged && mg_pcg.converged);
        assert_ne!(
            mic_pcg.iterations, mg_pcg.iterations,
            "two different solves"
        );
        let worst = mic
            .iter()
            .zip(&mg)
            .map(|(p, q)| (p - q).amax())
            .fold(0.0, f64::max);
        assert!(worst <= 1e-6, "particles {worst} cells apart");
    }
}
