//! Velocity transfer between particles and the MAC grid (paper alg. flip, lines 1 and 4):
//! particle-to-grid with tent weights on faces, extrapolation of face velocities into cells
//! without fluid, and grid-to-particle with a FLIP/PIC blend. The band method's velocity
//! combination is in [`crate::sim::band`].

use crate::grid::{for_each_face_weight, Grid, MacField, Vector};
use rayon::prelude::*;

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

fn splat<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    vel: &[Vector<D>],
    mass: Option<&[f64]>,
) -> (MacField<D>, [Vec<bool>; D]) {
    // A fixed number of contiguous chunks, each with its own accumulator, summed in chunk
    // order: a few grid-sized buffers, and bit-identical results whatever the thread count.
    const CHUNKS: usize = 4;
    let chunk = pos.len().div_ceil(CHUNKS).max(1);
    let partials: Vec<[(Vec<f64>, Vec<f64>); D]> = pos
        .par_chunks(chunk)
        .zip(vel.par_chunks(chunk))
        .enumerate()
        .map(|(k, (xs, vs))| {
            let mut acc: [(Vec<f64>, Vec<f64>); D] = std::array::from_fn(|a| {
                (vec![0.0; grid.num_faces(a)], vec![0.0; grid.num_faces(a)])
            });
            for (i, (x, v)) in xs.iter().zip(vs).enumerate() {
                let m = mass.map_or(1.0, |m| m[k * chunk + i]);
                for (a, (sum, wsum)) in acc.iter_mut().enumerate() {
                    for_each_face_weight(grid, a, x, |i, w| {
                        sum[i] += m * w * v[a];
                        wsum[i] += m * w;
                    });
                }
            }
            acc
        })
        .collect();
    let mut field = MacField::zeros(grid);
    let mut known: [Vec<bool>; D] = std::array::from_fn(|a| vec![false; grid.num_faces(a)]);
    for a in 0..D {
        field.comp[a]
            .par_iter_mut()
            .zip(known[a].par_iter_mut())
            .enumerate()
            .for_each(|(i, (u, k))| {
                let (s, w) = partials
                    .iter()
                    .fold((0.0, 0.0), |(s, w), p| (s + p[a].0[i], w + p[a].1[i]));
                if w > 1e-12 {
                    *u = s / w;
                    *k = true;
                }
            });
    }
    (field, known)
}

/// Extrapolates face values into unknown faces, `layers` rings deep: each ring takes the
/// average of its known axis neighbours (in the same component) from the previous ring. Only
/// the frontier of the known region is visited, so sparse fluid costs little.
pub fn extrapolate<const D: usize>(
    grid: &Grid<D>,
    field: &mut MacField<D>,
    known: &mut [Vec<bool>; D],
    layers: usize,
) {
    for (a, (u, k)) in field.comp.iter_mut().zip(known.iter_mut()).enumerate() {
        let fd = grid.face_dims(a);
        // Calls `f` with the index of each axis neighbour of face `i`.
        let neighbors = |i: usize, f: &mut dyn FnMut(usize)| {
            let c = grid.face_coords(a, i);
            for ax in 0..D {
                let st = grid.face_stride(a, ax);
                if c[ax] > 0 {
                    f(i - st);
                }
                if c[ax] + 1 < fd[ax] {
                    f(i + st);
                }
            }
        };
        let mut frontier: Vec<usize> = (0..u.len()).filter(|&i| k[i]).collect();
        let mut queued = vec![false; u.len()];
        for _ in 0..layers {
            let mut ring = vec![];
            for &i in &frontier {
                neighbors(i, &mut |n| {
                    if !k[n] && !queued[n] {
                        queued[n] = true;
                        ring.push(n);
                    }
                });
            }
            if ring.is_empty() {
                break;
            }
            ring.sort_unstable();
            let values: Vec<f64> = ring
                .iter()
                .map(|&i| {
                    let (mut s, mut n) = (0.0, 0);
                    neighbors(i, &mut |j| {
                        if k[j] {
                            s += u[j];
                            n += 1;
                        }
                    });
                    s / n as f64
                })
                .collect();
            for (&i, v) in ring.iter().zip(values) {
                u[i] = v;
                k[i] = true;
            }
            frontier = ring;
        }
    }
}

/// FLIP/PIC blend: `v_p <- flip (v_p + u(x_p) - u_old(x_p)) + (1 - flip) u(x_p)`.
pub fn grid_to_particles<const D: usize>(
    grid: &Grid<D>,
    new: &MacField<D>,
    old: &MacField<D>,
    flip_ratio: f64,
    pos: &[Vector<D>],
    vel: &mut [Vector<D>],
) {
    vel.par_iter_mut().zip(pos).for_each(|(v, x)| {
        let un = new.interpolate(grid, x);
        let uo = old.interpolate(grid, x);
        *v = flip_ratio * (*v + un - uo) + (1.0 - flip_ratio) * un;
    });
}

/// Bounds every particle's speed by `max_speed` (cells per second), keeping its direction.
pub fn limit_speeds<const D: usize>(vel: &mut [Vector<D>], max_speed: f64) {
    for v in vel.iter_mut() {
        let s = v.norm();
        if s > max_speed {
            *v *= max_speed / s;
        }
    }
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
            let mut vel2 = vel.clone();
            grid_to_particles(&g, &u, &u, 0.9, &pos, &mut vel2);
            assert_eq!(vel, vel2);
        }
        check([5, 4]);
        check([3, 4, 5]);
    }

    #[test]
    fn extrapolation_fills_rings_from_known_faces() {
        let g = Grid::new([6, 6]);
        let mut u = MacField::zeros(&g);
        let mut known: [Vec<bool>; 2] = std::array::from_fn(|a| vec![false; g.num_faces(a)]);
        let i = g.face_index(0, [3, 3]);
        u.comp[0][i] = 2.0;
        known[0][i] = true;
        extrapolate(&g, &mut u, &mut known, 2);
        assert_eq!(u.comp[0][g.face_index(0, [3, 5])], 2.0);
        assert_eq!(u.comp[0][g.face_index(0, [4, 4])], 2.0);
        assert!(!known[0][g.face_index(0, [0, 0])]);
        assert!(!known[1].iter().any(|k| *k));
    }
}
