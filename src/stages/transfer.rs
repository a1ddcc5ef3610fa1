//! Velocity transfer between particles and the MAC grid (paper alg. flip, lines 1 and 4):
//! particle-to-grid with tent weights on faces, extrapolation of face velocities into cells
//! without fluid, and grid-to-particle with a FLIP/PIC blend. The band method's velocity
//! combination is in [`crate::stages::band`].

use crate::grid::active::{par_runs, Active};
use crate::grid::{Cell, FacePoint, FaceStencil, Grid, MacField, Vector};
use crate::particles::Particles;
use crate::{PAR_GRAIN, PAR_GRAIN_PARTICLES};
use rayon::prelude::*;

/// Per face component, whether a face holds a value (from particles, the projection or the
/// grid) or still needs one from extrapolation.
pub type Known<const D: usize> = [Vec<bool>; D];

/// Transfers particle velocities to faces: `u_f = sum_p w_fp v_p / sum_p w_fp` with the
/// multilinear tent weights `w_fp`. Returns the field and, per component, whether a face
/// received any weight.
pub fn particles_to_grid<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    vel: &[Vector<D>],
) -> (MacField<D>, [Vec<bool>; D]) {
    splat(grid, pos, vel, None)
}

/// As [`particles_to_grid`] for points of masses `mass`: `u_f = sum_p m_p w_fp v_p / sum_p
/// m_p w_fp` (Power PIC's transport cells).
pub fn weighted_to_grid<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    vel: &[Vector<D>],
    mass: &[f64],
) -> (MacField<D>, [Vec<bool>; D]) {
    splat(grid, pos, vel, Some(mass))
}

/// Cell layers per slab of the particles-to-grid pass (along the last axis).
const SLAB: usize = 2;

/// Splats without atomics or per-thread copies of the grid. The domain is cut into slabs of
/// [`SLAB`] cell layers along the last axis; a particle's faces lie within one face layer of
/// its slab, so slabs two apart write disjoint faces. The even slabs run in parallel, then
/// the odd ones, each slab's particles in index order: every face sums its particles in one
/// fixed order, whatever the thread count. A face's `m w v` is summed in the field itself and
/// divided by its `m w` in place, so that a step asks for no third grid-sized array
/// (docs/benchmarks/flip.md).
fn splat<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    vel: &[Vector<D>],
    mass: Option<&[f64]>,
) -> (MacField<D>, [Vec<bool>; D]) {
    let (starts, order) = slab_order(grid, pos);
    // Per face: the sum of m w v, in the field itself, and the sum of m w.
    let mut field = MacField::zeros(grid);
    let mut weight: [Vec<f64>; D] = std::array::from_fn(|a| vec![0.0; grid.num_faces(a)]);
    for parity in 0..2 {
        let mut windows: Vec<_> = (field.comp.iter_mut().zip(&mut weight).enumerate())
            .map(|(a, (sums, weights))| {
                let sums = slab_windows(grid, a, sums, parity).into_iter();
                sums.zip(slab_windows(grid, a, weights, parity))
            })
            .collect();
        let jobs: Vec<(usize, [Window; D])> = (parity..starts.len() - 1)
            .step_by(2)
            .map(|slab| {
                let win = std::array::from_fn(|a| {
                    let ((offset, sums), (_, weights)) = windows[a].next().unwrap();
                    (offset, sums, weights)
                });
                (slab, win)
            })
            .collect();
        // About PAR_GRAIN_PARTICLES particles per task (each pass holds about half of them).
        let per_task = (2 * PAR_GRAIN_PARTICLES * jobs.len()).div_ceil(pos.len().max(1));
        jobs.into_par_iter()
            .with_min_len(per_task)
            .for_each(|(slab, mut win)| {
                for &p in &order[starts[slab]..starts[slab + 1]] {
                    let (x, v) = (&pos[p], &vel[p]);
                    let m = mass.map_or(1.0, |m| m[p]);
                    let at = FacePoint::new(grid, x);
                    for (a, (offset, sums, weights)) in win.iter_mut().enumerate() {
                        for (i, w) in FaceStencil::at(grid, &at, a).weights() {
                            sums[i - *offset] += m * w * v[a];
                            weights[i - *offset] += m * w;
                        }
                    }
                }
            });
    }
    // Only the faces beside the points' cells and their neighbours got weight: the rest stay
    // zero and unknown, and their pages are never touched.
    let reached = Active::around_points(grid, pos.par_iter(), 1);
    let known = std::array::from_fn(|a| {
        let mut known = vec![false; grid.num_faces(a)];
        let faces = reached.faces(a);
        (par_runs(faces, &mut field.comp[a]).zip(par_runs(faces, &mut known))).for_each(
            |((r, u), (_, k))| {
                for ((u, k), &w) in u.iter_mut().zip(k).zip(&weight[a][r]) {
                    *k = w > 1e-12;
                    *u = if *k { *u / w } else { 0.0 };
                }
            },
        );
        known
    });
    (field, known)
}

/// A slab's faces of one component: the index of its first face, the faces' sums of `m w v`
/// and of `m w`.
type Window<'a> = (usize, &'a mut [f64], &'a mut [f64]);

/// The particles' indices grouped by slab, each group in index order: slab `s` holds
/// `order[starts[s]..starts[s + 1]]` (a counting sort).
fn slab_order<const D: usize>(grid: &Grid<D>, pos: &[Vector<D>]) -> (Vec<usize>, Vec<usize>) {
    let n = grid.dims[D - 1];
    // Particles are inside the domain; the clamp only keeps a stray point's index valid.
    let slab = |x: &Vector<D>| (x[D - 1].max(0.0) as usize).min(n - 1) / SLAB;
    let mut starts = vec![0; n.div_ceil(SLAB) + 1];
    pos.iter().for_each(|x| starts[slab(x) + 1] += 1);
    for s in 1..starts.len() {
        starts[s] += starts[s - 1];
    }
    let mut next = starts.clone();
    let mut order = vec![0; pos.len()];
    for (p, x) in pos.iter().enumerate() {
        let s = slab(x);
        order[next[s]] = p;
        next[s] += 1;
    }
    (starts, order)
}

/// The faces of component `axis` that the slabs of one parity write, one window per slab:
/// slab `s` covers cell layers `[s SLAB, (s + 1) SLAB)` along the last axis and writes face
/// layers `s SLAB - 1 ..= (s + 1) SLAB` (a particle in cell layer `z` reaches face layers
/// `z - 1 ..= z + 1`), clipped to the grid. Slabs of one parity are `2 SLAB` layers apart,
/// so their windows tile the component without overlap.
fn slab_windows<'a, const D: usize>(
    grid: &Grid<D>,
    axis: usize,
    faces: &'a mut [f64],
    parity: usize,
) -> Vec<(usize, &'a mut [f64])> {
    let layers = grid.face_dims(axis)[D - 1];
    let layer = faces.len() / layers;
    let slabs = grid.dims[D - 1].div_ceil(SLAB);
    let mut windows = vec![];
    let mut rest = faces;
    // The first face layer of `rest`.
    let mut first = 0;
    for s in (parity..slabs).step_by(2) {
        let lo = (s * SLAB).saturating_sub(1);
        let hi = ((s + 1) * SLAB + 1).min(layers);
        let (_, tail) = std::mem::take(&mut rest).split_at_mut((lo - first) * layer);
        let (window, tail) = tail.split_at_mut((hi - lo) * layer);
        windows.push((lo * layer, window));
        rest = tail;
        first = hi;
    }
    windows
}

/// Extrapolates face values into unknown faces, `layers` rings deep: each ring takes the
/// average of its known axis neighbours (in the same component) from the previous ring, and
/// the rings are filled in ascending face order. The first ring is sought among the `active`
/// faces only.
///
/// The first ring, the unknown faces next to a known one, is found by one parallel pass over
/// the faces, which reads only the flags; the later rings are the unknown neighbours of the
/// ring before. (Listing every known face as the first frontier instead cost 70-140 ms per
/// call at 128^3, twice a step: the faces of a deep pool are mostly known.)
pub fn extrapolate<const D: usize>(
    grid: &Grid<D>,
    field: &mut MacField<D>,
    known: &mut [Vec<bool>; D],
    layers: usize,
    active: &Active<D>,
) {
    for (a, (u, k)) in field.comp.iter_mut().zip(known.iter_mut()).enumerate() {
        let near =
            |i, c, f: &mut dyn FnMut(usize, Cell<D>)| for_each_axis_neighbor(grid, a, i, c, f);
        let mut ring = first_ring(grid, a, k, active);
        for layer in 0..layers {
            if layer > 0 {
                let mut next = vec![];
                for &(i, c) in &ring {
                    near(i, c, &mut |n, nc| {
                        if !k[n] {
                            next.push((n, nc));
                        }
                    });
                }
                next.sort_unstable_by_key(|&(i, _)| i);
                next.dedup_by_key(|&mut (i, _)| i);
                ring = next;
            }
            if ring.is_empty() {
                break;
            }
            let values: Vec<f64> = (ring.par_iter().with_min_len(PAR_GRAIN / 8))
                .map(|&(i, c)| {
                    let (mut s, mut n) = (0.0, 0);
                    near(i, c, &mut |j, _| {
                        if k[j] {
                            s += u[j];
                            n += 1;
                        }
                    });
                    s / n as f64
                })
                .collect();
            for (&(i, _), v) in ring.iter().zip(values) {
                u[i] = v;
                k[i] = true;
            }
        }
    }
}

/// The unknown `active` faces of component `a` with a known axis neighbour, in ascending
/// order, each with its coordinates: a parallel pass over the active lines.
fn first_ring<const D: usize>(
    grid: &Grid<D>,
    a: usize,
    k: &[bool],
    active: &Active<D>,
) -> Vec<(usize, Cell<D>)> {
    (active.faces(a).par_iter())
        .with_min_len(PAR_GRAIN.div_ceil(grid.dims[0]))
        .flat_map_iter(|r| {
            let coords = grid.face_coords_from(a, r.start);
            r.clone().zip(coords).filter(|&(i, c)| {
                let mut near_known = false;
                if !k[i] {
                    for_each_axis_neighbor(grid, a, i, c, &mut |j, _| near_known |= k[j]);
                }
                near_known
            })
        })
        .collect()
}

/// Calls `f(index, coords)` for each axis neighbour of face `i` (coordinates `c`) of
/// component `a`, in axis order, the lower before the upper.
fn for_each_axis_neighbor<const D: usize>(
    grid: &Grid<D>,
    a: usize,
    i: usize,
    c: Cell<D>,
    f: &mut dyn FnMut(usize, Cell<D>),
) {
    let fd = grid.face_dims(a);
    for ax in 0..D {
        let st = grid.face_stride(a, ax);
        let mut n = c;
        if c[ax] > 0 {
            n[ax] = c[ax] - 1;
            f(i - st, n);
        }
        if c[ax] + 1 < fd[ax] {
            n[ax] = c[ax] + 1;
            f(i + st, n);
        }
    }
}

/// How grid-to-particle sets a particle's velocity (alg. flip line 4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    /// The FLIP share of the FLIP/PIC blend.
    pub flip_ratio: f64,
    /// The speed bound (cells per second): a faster blended velocity is scaled down to it,
    /// its direction kept.
    pub max_speed: f64,
}

/// FLIP/PIC blend: `v_p <- flip (v_p + u(x_p) - u_old(x_p)) + (1 - flip) u(x_p)`, then the
/// speed bound. Writes `u(x_p)` per particle to `at` (whose allocation is reused).
pub fn grid_to_particles<const D: usize>(
    grid: &Grid<D>,
    new: &MacField<D>,
    old: &MacField<D>,
    blend: Blend,
    particles: &mut Particles<D>,
    at: &mut Vec<Vector<D>>,
) {
    let Blend {
        flip_ratio,
        max_speed,
    } = blend;
    at.resize(particles.len(), Vector::<D>::zeros());
    let n = PAR_GRAIN_PARTICLES;
    let vel = particles.vel.par_chunks_mut(n);
    let chunks = vel
        .zip(particles.pos.par_chunks(n))
        .zip(at.par_chunks_mut(n));
    // A plain loop per chunk, so that the body is inlined into it and the grid's sizes are
    // read once per chunk rather than once per particle.
    chunks.for_each(|((vel, pos), at)| {
        #[cfg(target_arch = "x86_64")]
        let done = match crate::grid::lanes::available(grid) {
            // SAFETY: the CPU has AVX2, checked just above.
            true => unsafe { lanes::blend(grid, new, old, blend, vel, pos, at) },
            false => 0,
        };
        #[cfg(not(target_arch = "x86_64"))]
        let done = 0;
        for ((v, x), at) in vel[done..]
            .iter_mut()
            .zip(&pos[done..])
            .zip(&mut at[done..])
        {
            let point = FacePoint::new(grid, x);
            // Blended in a local copy, stored once: stores to `v` per component followed by
            // the speed bound's read of the whole vector stall the store-to-load forwarding.
            let mut blended = *v;
            *at = Vector::<D>::from_fn(|a, _| {
                let st = FaceStencil::at(grid, &point, a);
                let (un, uo) = (st.apply(&new.comp[a]), st.apply(&old.comp[a]));
                blended[a] = flip_ratio * (blended[a] + un - uo) + (1.0 - flip_ratio) * un;
                un
            });
            *v = limited(blended, max_speed);
        }
    });
}

/// How [`grid_to_particles`] runs on this machine, for the headers of `bench` and `report`
/// (the four-lane code is about twice as fast).
pub fn grid_to_particles_mode() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    if crate::grid::lanes::cpu_has_lanes() {
        return "grid to particles 4 particles at a time (AVX2)";
    }
    "grid to particles 1 particle at a time (no AVX2)"
}

/// [`grid_to_particles`] four particles at a time, one per lane (`grid::lanes`): the same
/// operations per particle, so the same bits.
#[cfg(target_arch = "x86_64")]
mod lanes {
    use super::{limited, Blend, MacField};
    use crate::grid::{Grid, Vector};

    /// Blends the particles of whole groups of four and returns how many it did; the caller
    /// does the rest one by one.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 (see [`crate::grid::lanes::available`]).
    #[target_feature(enable = "avx2")]
    pub fn blend<const D: usize>(
        grid: &Grid<D>,
        new: &MacField<D>,
        old: &MacField<D>,
        blend: Blend,
        vel: &mut [Vector<D>],
        pos: &[Vector<D>],
        at: &mut [Vector<D>],
    ) -> usize {
        use crate::grid::lanes::{lanes, FacePoint4, FaceStencil4};
        use std::arch::x86_64::*;
        let n = pos.len() / 4 * 4;
        let flip = _mm256_set1_pd(blend.flip_ratio);
        let pic = _mm256_set1_pd(1.0 - blend.flip_ratio);
        let groups = (vel[..n].chunks_exact_mut(4))
            .zip(pos.chunks_exact(4))
            .zip(at.chunks_exact_mut(4));
        for ((v, x), at) in groups {
            let point = FacePoint4::new(grid, x.try_into().expect("groups of four"));
            let (mut blended, mut un4) = ([[0.0; 4]; D], [[0.0; 4]; D]);
            for a in 0..D {
                let st = FaceStencil4::at(grid, &point, a);
                let (un, uo) = st.apply_pair(&new.comp[a], &old.comp[a]);
                let va = _mm256_set_pd(v[3][a], v[2][a], v[1][a], v[0][a]);
                // `flip (v + un - uo) + (1 - flip) un`, evaluated as the one-particle code does.
                let flipped = _mm256_mul_pd(flip, _mm256_sub_pd(_mm256_add_pd(va, un), uo));
                blended[a] = lanes(_mm256_add_pd(flipped, _mm256_mul_pd(pic, un)));
                un4[a] = lanes(un);
            }
            for i in 0..4 {
                at[i] = Vector::<D>::from_fn(|a, _| un4[a][i]);
                v[i] = limited(Vector::<D>::from_fn(|a, _| blended[a][i]), blend.max_speed);
            }
        }
        n
    }
}

/// `v` scaled down to `max_speed` (cells per second) if faster, its direction kept.
#[inline]
fn limited<const D: usize>(v: Vector<D>, max_speed: f64) -> Vector<D> {
    // Squares compared first, so that most particles take no square root: `|v| > max_speed`
    // exactly when `|v|^2 > max_speed^2` rounded, except where `|v|` rounds to `max_speed`,
    // whose scale factor is exactly 1.
    let s2 = v.norm_squared();
    if s2 > max_speed * max_speed {
        v * (max_speed / s2.sqrt())
    } else {
        v
    }
}

/// Bounds every particle's speed by `max_speed` (see [`limited`]).
pub fn limit_speeds<const D: usize>(vel: &mut [Vector<D>], max_speed: f64) {
    vel.par_iter_mut()
        .with_min_len(PAR_GRAIN_PARTICLES)
        .for_each(|v| *v = limited(*v, max_speed));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_particle_velocity_transfers_exactly() {
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let v0 = Vector::<D>::from_fn(|a, _| 1.0 + a as f64);
            let pos: Vec<_> = (0..g.num_cells())
                .map(|c| g.center(g.cell_coords(c)))
                .collect();
            let vel = vec![v0; pos.len()];
            let (u, known) = particles_to_grid(&g, &pos, &vel);
            for a in 0..D {
                assert!(known[a].iter().all(|k| *k));
                assert!(u.comp[a].iter().all(|x| (x - v0[a]).abs() < 1e-12));
            }
            // G2P of an unchanged field leaves the particle velocity as it was.
            let mut p = Particles {
                pos,
                vel: vel.clone(),
            };
            let (mut at, fast) = (vec![], v0.norm() + 1.0);
            let blend = |max_speed| Blend {
                flip_ratio: 0.9,
                max_speed,
            };
            grid_to_particles(&g, &u, &u, blend(fast), &mut p, &mut at);
            assert_eq!(at, vel);
            assert_eq!(vel, p.vel);
            // The speed bound scales the blended velocity down, direction kept.
            grid_to_particles(&g, &u, &u, blend(0.5), &mut p, &mut at);
            assert_eq!(at, vel);
            assert!(p.vel.iter().all(|v| (v.norm() - 0.5).abs() < 1e-12));
            assert!(p
                .vel
                .iter()
                .all(|v| (v.normalize() - v0.normalize()).norm() < 1e-12));
        }
        check([5, 4]);
        check([3, 4, 5]);
    }

    /// Groups of four particles go through the four-lane code (AVX2), the rest one by one:
    /// both must give the same bits. Points in and beyond the domain, NaN coordinates, speeds
    /// above the bound, and an axis one cell thick (its faces along axis 0 are not neighbours
    /// in memory, so the lanes gather them).
    #[test]
    fn four_at_a_time_gives_the_bits_of_one_at_a_time() {
        use rand::{Rng, SeedableRng};
        fn check<const D: usize>(dims: [usize; D], rng: &mut rand::rngs::StdRng) {
            let g = Grid::new(dims);
            let field = |rng: &mut rand::rngs::StdRng| {
                let mut u = MacField::zeros(&g);
                (u.comp.iter_mut().flatten()).for_each(|x| *x = rng.random_range(-3.0..3.0));
                u
            };
            let (new, old) = (field(rng), field(rng));
            let n = 4 * 25 + 3;
            let pos: Vec<Vector<D>> = (0..n)
                .map(|i| {
                    Vector::<D>::from_fn(|k, _| match (i + k) % 17 {
                        0 => f64::NAN,
                        _ => rng.random_range(-1.0..dims[k] as f64 + 1.0),
                    })
                })
                .collect();
            let vel: Vec<Vector<D>> = (0..n)
                .map(|_| Vector::<D>::from_fn(|_, _| rng.random_range(-4.0..4.0)))
                .collect();
            let blend = Blend {
                flip_ratio: 0.95,
                max_speed: 4.0,
            };
            let mut all = Particles {
                pos: pos.clone(),
                vel: vel.clone(),
            };
            let mut at = vec![];
            grid_to_particles(&g, &new, &old, blend, &mut all, &mut at);
            for i in 0..n {
                let mut one = Particles {
                    pos: vec![pos[i]],
                    vel: vec![vel[i]],
                };
                let mut at_one = vec![];
                grid_to_particles(&g, &new, &old, blend, &mut one, &mut at_one);
                let bits = |v: &Vector<D>| v.map(f64::to_bits);
                assert_eq!(
                    bits(&all.vel[i]),
                    bits(&one.vel[0]),
                    "{dims:?}, particle {i}"
                );
                assert_eq!(bits(&at[i]), bits(&at_one[0]), "{dims:?}, particle {i}");
            }
        }
        #[cfg(target_arch = "x86_64")]
        if !crate::grid::lanes::available(&Grid::new([4, 4])) {
            eprintln!("no AVX2 here: the four-lane code was not exercised");
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        check([7, 5], &mut rng);
        check([1, 6], &mut rng);
        check([6, 5, 4], &mut rng);
        check([1, 5, 4], &mut rng);
        check([5, 1, 3], &mut rng);
    }

    /// The speed bound's comparison of squares gives, bit for bit, what comparing the norm
    /// gives, also for speeds within a few roundings of the bound.
    #[test]
    fn speed_bound_matches_the_norm_comparison() {
        use rand::{Rng, SeedableRng};
        fn by_norm<const D: usize>(v: Vector<D>, max_speed: f64) -> Vector<D> {
            let s = v.norm();
            if s > max_speed {
                v * (max_speed / s)
            } else {
                v
            }
        }
        fn check<const D: usize>(rng: &mut rand::rngs::StdRng) {
            let mut near = 0;
            for _ in 0..200_000 {
                let max_speed: f64 = rng.random_range(0.1..100.0);
                let dir = Vector::<D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
                let ulps = rng.random_range(-4i64..=4);
                let speed = f64::from_bits((max_speed.to_bits() as i64 + ulps) as u64);
                let v = dir.normalize() * speed;
                near += usize::from(v.norm() == max_speed);
                let (got, want) = (limited(v, max_speed), by_norm(v, max_speed));
                assert_eq!(
                    got.map(f64::to_bits),
                    want.map(f64::to_bits),
                    "{v:?} {max_speed}"
                );
            }
            // Speeds that round to the bound itself, the case the comparison of squares
            // handles differently (with a scale factor of exactly 1), were among them.
            assert!(near > 1000, "{near}");
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        check::<2>(&mut rng);
        check::<3>(&mut rng);
    }

    /// The weighted average of eq. P2G summed face by face, the plain way.
    fn reference_p2g<const D: usize>(
        g: &Grid<D>,
        pos: &[Vector<D>],
        vel: &[Vector<D>],
        mass: &[f64],
    ) -> [Vec<(f64, f64)>; D] {
        std::array::from_fn(|a| {
            let mut acc = vec![(0.0, 0.0); g.num_faces(a)];
            for ((x, v), m) in pos.iter().zip(vel).zip(mass) {
                for (i, w) in FaceStencil::new(g, a, x).weights() {
                    acc[i].0 += m * w * v[a];
                    acc[i].1 += m * w;
                }
            }
            acc
        })
    }

    #[test]
    fn slab_splat_matches_the_plain_sum_and_ignores_the_thread_count() {
        use rand::{Rng, SeedableRng};
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let mut rng = rand::rngs::StdRng::seed_from_u64(7);
            // Enough particles that slabs run as separate tasks (see PAR_GRAIN_PARTICLES).
            let n = (40 * g.num_cells()).max(8 * PAR_GRAIN_PARTICLES);
            let point = |rng: &mut rand::rngs::StdRng| {
                Vector::<D>::from_fn(|k, _| rng.random_range(0.0..dims[k] as f64))
            };
            let pos: Vec<_> = (0..n).map(|_| point(&mut rng)).collect();
            let vel: Vec<_> = (0..n).map(|_| point(&mut rng)).collect();
            let mass: Vec<f64> = (0..n).map(|_| rng.random_range(0.5..2.0)).collect();
            let want = reference_p2g(&g, &pos, &vel, &mass);
            let run = |threads| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| weighted_to_grid(&g, &pos, &vel, &mass))
            };
            let (u, known) = run(1);
            for a in 0..D {
                for (i, &(s, w)) in want[a].iter().enumerate() {
                    assert_eq!(known[a][i], w > 1e-12, "axis {a} face {i}");
                    if known[a][i] {
                        assert!((u.comp[a][i] - s / w).abs() < 1e-12 * (1.0 + (s / w).abs()));
                    }
                }
            }
            assert_eq!(run(3), (u, known));
        }
        // Odd layer counts, a single layer, and a grid with fewer layers than a slab.
        check([6, 7]);
        check([3, 1]);
        check([4, 3, 5]);
        check([2, 3, 1]);
    }

    #[test]
    fn extrapolation_fills_rings_from_known_faces() {
        let g = Grid::new([6, 6]);
        let mut u = MacField::zeros(&g);
        let mut known: [Vec<bool>; 2] = std::array::from_fn(|a| vec![false; g.num_faces(a)]);
        let i = g.face_index(0, [3, 3]);
        u.comp[0][i] = 2.0;
        known[0][i] = true;
        extrapolate(&g, &mut u, &mut known, 2, &Active::all(&g));
        assert_eq!(u.comp[0][g.face_index(0, [3, 5])], 2.0);
        assert_eq!(u.comp[0][g.face_index(0, [4, 4])], 2.0);
        assert!(!known[0][g.face_index(0, [0, 0])]);
        assert!(!known[1].iter().any(|k| *k));
    }
}
