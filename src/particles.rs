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

    /// Keeps the particles flagged in `keep` (one flag per particle), in order. When fewer than
    /// half remain (a band method thinning the seeded liquid to its band), the storage they no
    /// longer need goes back to the system: at the paper's scale the deep's 45 M seeded
    /// particles would otherwise keep 2 GiB resident for the whole run.
    pub fn retain_flagged(&mut self, keep: &[bool]) {
        let mut it = keep.iter();
        self.pos.retain(|_| *it.next().unwrap());
        let mut it = keep.iter();
        self.vel.retain(|_| *it.next().unwrap());
        if self.pos.capacity() > 2 * self.pos.len() {
            self.pos.shrink_to_fit();
            self.vel.shrink_to_fit();
        }
    }
}

/// A region of space in grid units.
#[derive(Clone, Debug, PartialEq)]
pub enum Region<const D: usize> {
    Box { min: Vector<D>, max: Vector<D> },
    Ball { center: Vector<D>, radius: f64 },
    Spiral(SpiralBlock<D>),
}

/// A block with a spiral channel carved into it, for the spiral scene of sec. 8 (the paper's
/// spiral mesh is not public). The region is the box `[min, max]` minus the channel.
///
/// The channel's centre line is the Archimedean spiral `r(t) = radius - pitch t / 2 pi`,
/// `t` in `[0, 2 pi turns]`, starting straight above `center` and winding clockwise inwards,
/// with `pitch = radius / (turns + 1/2)` so that its inner end stays clear of the centre. The
/// channel is `width` wide, measured radially; a straight mouth as wide joins its outer end to
/// the block's top face. Only axes 0 and 1 take part: in 3D the channel would be extruded.
#[derive(Clone, Debug, PartialEq)]
pub struct SpiralBlock<const D: usize> {
    pub min: Vector<D>,
    pub max: Vector<D>,
    pub center: Vector<D>,
    pub radius: f64,
    pub turns: f64,
    pub width: f64,
}

impl<const D: usize> SpiralBlock<D> {
    /// The distance between successive turns of the centre line.
    pub fn pitch(&self) -> f64 {
        pitch(self.radius, self.turns)
    }

    /// Whether `x` lies in the channel (or its mouth).
    pub fn channel_contains(&self, x: &Vector<D>) -> bool {
        use std::f64::consts::{FRAC_PI_2, TAU};
        let (dx, dy) = (x[0] - self.center[0], x[1] - self.center[1]);
        let half = self.width / 2.0;
        if dx.abs() <= half && dy >= self.radius - half {
            return true;
        }
        let rho = dx.hypot(dy);
        // The parameters t at which the centre line passes the angle of x, one per turn.
        let first = (FRAC_PI_2 - dy.atan2(dx)).rem_euclid(TAU);
        let pitch = self.pitch();
        (0..)
            .map(|k| first + TAU * k as f64)
            .take_while(|&t| t <= TAU * self.turns)
            .any(|t| (rho - (self.radius - pitch * t / TAU)).abs() <= half)
    }
}

fn in_box<const D: usize>(x: &Vector<D>, min: &Vector<D>, max: &Vector<D>) -> bool {
    (0..D).all(|k| x[k] >= min[k] && x[k] <= max[k])
}

/// The pitch of a [`SpiralBlock`] of this outer radius and number of turns (any length unit).
pub fn pitch(radius: f64, turns: f64) -> f64 {
    radius / (turns + 0.5)
}

impl<const D: usize> Region<D> {
    pub fn contains(&self, x: &Vector<D>) -> bool {
        match self {
            Region::Box { min, max } => in_box(x, min, max),
            Region::Ball { center, radius } => (x - center).norm_squared() <= radius * radius,
            Region::Spiral(s) => in_box(x, &s.min, &s.max) && !s.channel_contains(x),
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
            Region::Spiral(s) => Region::Spiral(SpiralBlock {
                min: s.min + d,
                max: s.max + d,
                center: s.center + d,
                ..s.clone()
            }),
        }
    }

    /// The smallest box holding the region: `(min, max)`.
    pub fn bounds(&self) -> (Vector<D>, Vector<D>) {
        match self {
            Region::Box { min, max } | Region::Spiral(SpiralBlock { min, max, .. }) => (*min, *max),
            Region::Ball { center, radius } => {
                (center.add_scalar(-radius), center.add_scalar(*radius))
            }
        }
    }

    /// The centre of the region.
    pub fn center(&self) -> Vector<D> {
        match self {
            Region::Box { min, max } | Region::Spiral(SpiralBlock { min, max, .. }) => {
                (min + max) / 2.0
            }
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
    fn thinning_keeps_the_order_and_returns_the_storage() {
        let mut p = Particles::<3>::default();
        for i in 0..1000 {
            p.push(Vector::repeat(i as f64), Vector::repeat(-(i as f64)));
        }
        // A tenth kept: the storage shrinks to what they need.
        let keep: Vec<bool> = (0..1000).map(|i| i % 10 == 3).collect();
        p.retain_flagged(&keep);
        assert_eq!(p.len(), 100);
        assert!(p.pos.iter().zip(&p.vel).enumerate().all(|(k, (x, v))| {
            let i = (10 * k + 3) as f64;
            x[0] == i && v[2] == -i
        }));
        assert!(p.pos.capacity() <= 2 * p.len() && p.vel.capacity() <= 2 * p.len());
        // Most kept: no reallocation.
        let capacity = p.pos.capacity();
        p.retain_flagged(&(0..100).map(|i| i != 0).collect::<Vec<_>>());
        assert_eq!((p.len(), p.pos.capacity()), (99, capacity));
    }

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

    /// The spiral scene's block at 128 cells: channel 6.4 cells wide, walls 6.4 thick.
    fn spiral() -> SpiralBlock<2> {
        SpiralBlock {
            min: Vector::<2>::new(0.0, 0.0),
            max: Vector::<2>::new(128.0, 64.0),
            center: Vector::<2>::new(64.0, 32.0),
            radius: 25.6,
            turns: 1.5,
            width: 6.4,
        }
    }

    /// The length of the spiral's centre line, by the midpoint rule.
    fn centre_line_length(s: &SpiralBlock<2>) -> f64 {
        use std::f64::consts::TAU;
        let n = 100_000;
        let dt = TAU * s.turns / n as f64;
        let dr = s.pitch() / TAU;
        (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * dt;
                (s.radius - dr * t).hypot(dr) * dt
            })
            .sum()
    }

    #[test]
    fn the_spiral_channel_is_as_long_and_wide_as_its_centre_line_says() {
        let s = spiral();
        // Area of the channel by sampling the block on a fine lattice.
        let k = 20;
        let (w, h) = (128 * k, 64 * k);
        let inside = (0..w * h)
            .filter(|&i| {
                let x = Vector::<2>::new(
                    ((i % w) as f64 + 0.5) / k as f64,
                    ((i / w) as f64 + 0.5) / k as f64,
                );
                s.channel_contains(&x)
            })
            .count();
        let area = inside as f64 / (k * k) as f64;
        let mouth = s.max[1] - s.center[1] - s.radius;
        let expected = s.width * (centre_line_length(&s) + mouth);
        assert!(
            (area / expected - 1.0).abs() < 0.02,
            "channel area {area}, width x length {expected}"
        );
        // Clockwise from the top: the centre line passes right of the centre a quarter turn
        // in (and again a turn later), below it half a turn in, left of it three quarters in;
        // the walls between lie halfway. Pitch 12.8, width 6.4.
        let at = |r: f64, angle: f64| {
            Vector::<2>::new(s.center[0] + r * angle.cos(), s.center[1] + r * angle.sin())
        };
        use std::f64::consts::{FRAC_PI_2, PI};
        for (angle, channel, wall) in [
            (0.0, vec![22.4, 9.6], vec![28.8, 16.0, 3.2]),
            (-FRAC_PI_2, vec![19.2], vec![25.6, 12.8]),
            (PI, vec![16.0], vec![22.4, 9.6]),
        ] {
            for r in channel {
                assert!(
                    s.channel_contains(&at(r, angle)),
                    "channel at r {r}, angle {angle}"
                );
            }
            for r in wall {
                assert!(
                    !s.channel_contains(&at(r, angle)),
                    "wall at r {r}, angle {angle}"
                );
            }
        }
        // The mouth meets the channel at its full width.
        let quarter = s.width / 4.0;
        for dx in [-quarter, quarter] {
            let x = s.center + Vector::<2>::new(dx, s.radius - quarter);
            assert!(s.channel_contains(&x), "mouth at {dx}");
        }
    }

    #[test]
    fn the_rasterised_spiral_is_one_passage_with_no_shortcut_through_its_walls() {
        let s = spiral();
        let g = Grid::new([128, 64]);
        let solid: Vec<bool> = {
            let mut m = vec![false; g.num_cells()];
            Region::Spiral(s.clone())
                .cells(&g)
                .for_each(|c| m[c] = true);
            m
        };
        let open: Vec<usize> = (0..g.num_cells()).filter(|&c| !solid[c]).collect();
        // Breadth-first from the mouth's cells on the top row.
        let mut dist = vec![usize::MAX; g.num_cells()];
        let mut queue: std::collections::VecDeque<usize> = open
            .iter()
            .copied()
            .filter(|&c| g.cell_coords(c)[1] == 63)
            .collect();
        assert!(
            !queue.is_empty() && queue.len() <= 7,
            "mouth: {} cells",
            queue.len()
        );
        queue.iter().for_each(|&c| dist[c] = 0);
        while let Some(c) = queue.pop_front() {
            for nb in g.face_neighbors(c) {
                if !solid[nb] && dist[nb] == usize::MAX {
                    dist[nb] = dist[c] + 1;
                    queue.push_back(nb);
                }
            }
        }
        assert!(
            open.iter().all(|&c| dist[c] != usize::MAX),
            "the channel is not one piece"
        );
        // The farthest cell is at the inner end, as far along as the centre line goes.
        let far = open.iter().map(|&c| dist[c]).max().unwrap() as f64;
        let length = centre_line_length(&s) + (s.max[1] - s.center[1] - s.radius);
        assert!(
            far > 0.9 * length && far < 1.3 * length,
            "{far} steps to the inner end, centre line {length}"
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
