//! Fluid particles and their seeding: `mu = k^D` particles per cell on a stratified
//! `k^D` sub-grid with seeded jitter (paper sec. 8: 4 ppc in 2D, 8 ppc in 3D).

use crate::grid::{Cell, Grid, Vector};
use rand::Rng;

/// Positions (grid units) and velocities (cells per second) of the particles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Particles<const D: usize> {
    pub pos: Vec<Vector<D>>,
    pub vel: Vec<Vector<D>>,
}

impl<const D: usize> Particles<D> {
    pub fn len(&self) -> usize {
        self.pos.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pos.is_empty()
    }

    pub fn push(&mut self, x: Vector<D>, v: Vector<D>) {
        self.pos.push(x);
        self.vel.push(v);
    }
}

/// A region of space in grid units.
#[derive(Clone, Debug, PartialEq)]
pub enum Region<const D: usize> {
    Box { min: Vector<D>, max: Vector<D> },
    Ball { center: Vector<D>, radius: f64 },
}

impl<const D: usize> Region<D> {
    pub fn contains(&self, x: &Vector<D>) -> bool {
        match self {
            Region::Box { min, max } => (0..D).all(|k| x[k] >= min[k] && x[k] <= max[k]),
            Region::Ball { center, radius } => (x - center).norm_squared() <= radius * radius,
        }
    }

    /// Cells whose centre lies in the region, in increasing index order. Only the cells of
    /// the region's bounding box are visited.
    pub fn cells<'a>(&'a self, grid: &'a Grid<D>) -> impl Iterator<Item = usize> + 'a {
        let (lo, hi) = self.bounds();
        // Cells with centre in [lo, hi] along axis k: ceil(lo - 0.5) ..= floor(hi - 0.5).
        let first: [usize; D] = std::array::from_fn(|k| (lo[k] - 0.5).ceil().max(0.0) as usize);
        let end: [usize; D] = std::array::from_fn(|k| {
            ((hi[k] - 0.5).floor() + 1.0).clamp(0.0, grid.dims[k] as f64) as usize
        });
        let empty = (0..D).any(|k| first[k] >= end[k]);
        let count: usize = if empty {
            0
        } else {
            (0..D).map(|k| end[k] - first[k]).product()
        };
        (0..count)
            .map(move |mut i| {
                // Axis 0 fastest, as in cell indices: the order is increasing.
                let c: [usize; D] = std::array::from_fn(|k| {
                    let n = end[k] - first[k];
                    let v = first[k] + i % n;
                    i /= n;
                    v
                });
                grid.cell_index(c)
            })
            .filter(move |&c| self.contains(&grid.center(grid.cell_coords(c))))
    }

    /// The region moved by `d`.
    pub fn translated(&self, d: &Vector<D>) -> Self {
        match self {
            Region::Box { min, max } => Region::Box {
                min: min + d,
                max: max + d,
            },
            Region::Ball { center, radius } => Region::Ball {
                center: center + d,
                radius: *radius,
            },
        }
    }

    /// The smallest box holding the region: `(min, max)`.
    pub fn bounds(&self) -> (Vector<D>, Vector<D>) {
        match self {
            Region::Box { min, max } => (*min, *max),
            Region::Ball { center, radius } => {
                (center.add_scalar(-radius), center.add_scalar(*radius))
            }
        }
    }

    /// The centre of the region.
    pub fn center(&self) -> Vector<D> {
        match self {
            Region::Box { min, max } => (min + max) / 2.0,
            Region::Ball { center, .. } => *center,
        }
    }
}

/// The `k^D` stratified sample positions of cell `c`, each jittered by up to `jitter` of the
/// sub-cell spacing (`jitter` in [0, 0.5)).
pub fn stratified_samples<const D: usize>(
    c: Cell<D>,
    k: usize,
    jitter: f64,
    rng: &mut impl Rng,
) -> Vec<Vector<D>> {
    let n = k.pow(D as u32);
    (0..n)
        .map(|s| {
            let mut sub = s;
            Vector::<D>::from_fn(|a, _| {
                let i = sub % k;
                if a + 1 < D {
                    sub /= k;
                }
                let off = i as f64 + 0.5 + jitter * rng.random_range(-1.0..=1.0);
                c[a] as f64 + off / k as f64
            })
        })
        .collect()
}

/// Seeds particles in every non-solid cell, keeping the stratified samples that fall inside
/// one of `regions`; velocities start at zero.
pub fn seed<const D: usize>(
    grid: &Grid<D>,
    regions: &[Region<D>],
    solid: &[bool],
    per_axis: usize,
    jitter: f64,
    rng: &mut impl Rng,
) -> Particles<D> {
    let mut p = Particles::default();
    for c in 0..grid.num_cells() {
        if solid[c] {
            continue;
        }
        for x in stratified_samples(grid.cell_coords(c), per_axis, jitter, rng) {
            if regions.iter().any(|r| r.contains(&x)) {
                p.push(x, Vector::zeros());
            }
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn seeding_fills_a_box_with_exactly_mu_per_cell() {
        fn check<const D: usize>(dims: [usize; D], k: usize) {
            let g = Grid::new(dims);
            let mut rng = rand::rngs::StdRng::seed_from_u64(7);
            let r = Region::Box {
                min: Vector::<D>::zeros(),
                max: Vector::<D>::from_fn(|a, _| (dims[a] / 2) as f64),
            };
            let p = seed(&g, &[r], &vec![false; g.num_cells()], k, 0.2, &mut rng);
            let cells: usize = dims.iter().map(|d| d / 2).product();
            assert_eq!(p.len(), cells * k.pow(D as u32));
            let mut count = vec![0; g.num_cells()];
            for x in &p.pos {
                count[g.cell_index_of(x)] += 1;
            }
            assert!(count.iter().all(|&n| n == 0 || n == k.pow(D as u32)));
        }
        check([8, 6], 2);
        check([6, 4, 4], 2);
        check([5, 5], 1);
    }

    #[test]
    fn region_cells_are_the_cells_whose_centre_is_inside_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], r: Region<D>) {
            let g = Grid::new(dims);
            let all: Vec<usize> = (0..g.num_cells())
                .filter(|&c| r.contains(&g.center(g.cell_coords(c))))
                .collect();
            assert!(!all.is_empty());
            assert_eq!(r.cells(&g).collect::<Vec<_>>(), all);
        }
        check(
            [9, 7],
            Region::Ball {
                center: Vector::<2>::new(3.2, 4.9),
                radius: 2.6,
            },
        );
        // Reaching past the walls, and with faces exactly on cell centres.
        check(
            [6, 5, 4],
            Region::Box {
                min: Vector::<3>::new(-1.0, 1.5, 0.0),
                max: Vector::<3>::new(3.5, 9.0, 2.5),
            },
        );
    }

    #[test]
    fn seeding_is_deterministic_per_seed() {
        let g = Grid::new([10, 10]);
        let r = Region::Ball {
            center: Vector::<2>::new(5.0, 5.0),
            radius: 3.0,
        };
        let run = |s| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(s);
            seed(
                &g,
                std::slice::from_ref(&r),
                &[false; 100],
                2,
                0.3,
                &mut rng,
            )
        };
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }
}
