//! The liquid's signed distance of narrow-band FLIP (Ferstl et al. 2016, sec. 4): a level set
//! on cell centres, in cells, negative inside the liquid.
//!
//! Each step it is the grid level set advected with the liquid, shrunk by one cell and united
//! with the particles' own level set (a union of spheres), then re-marched layer by layer away
//! from its zero crossing: inwards `R + 2` layers, outwards 3 (MantaFlow's
//! `scenes/flip05_nbflip.py` with `unionParticleLevelset` and `extrapolateLsSimple`). The
//! grid part carries the liquid where the band holds no particles; the particles carry the
//! surface.

use crate::grid::{for_each_cell_weight, AtGridPoints, Cell, Grid, MacField, Vector};
use crate::stages::markings::DepthLevel;
use rayon::prelude::*;

/// A level set on cell centres, in cells; negative inside.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LevelSet {
    pub phi: Vec<f64>,
}

/// Radius of a particle's sphere in the particle level set: half a cell diagonal plus 1 %, so
/// that the spheres of a cell's particles cover its centre (MantaFlow's
/// `calculateRadiusFactor` with radius factor 1: `sqrt(D) (1 + 0.01) / 2`).
pub fn particle_radius(dim: usize) -> f64 {
    0.5 * (dim as f64).sqrt() * 1.01
}

/// The level set above which a particle is "at the surface": one cell diagonal plus 1 %
/// (MantaFlow's `adjustNumber`, `SURFACE_LS`). Cells above it are not seeded, and their
/// particles are never thinned.
pub fn surface_layer(dim: usize) -> f64 {
    -2.0 * particle_radius(dim)
}

/// The level of cell `c` in a band `R` deep, read from the level set at its centre: surface
/// above [`surface_layer`], band down to the combine band `-(R - 1)`, interface down to `-R`
/// (particles, but the grid's velocity), deep below.
pub fn level<const D: usize>(phi: &LevelSet, solid: &[bool], r: f64, c: usize) -> DepthLevel {
    match phi.phi[c] {
        v if solid[c] || v >= 0.0 => DepthLevel::NotFluid,
        v if v > surface_layer(D) => DepthLevel::Surface,
        v if v >= -(r - 1.0) => DepthLevel::Band,
        v if v >= -r => DepthLevel::Interface,
        _ => DepthLevel::Deep,
    }
}

/// Which way [`LevelSet::remarch`] marches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Into the liquid (`phi < 0`): each layer one cell lower.
    Inside,
    /// Away from it: each layer one cell higher.
    Outside,
}

impl LevelSet {
    /// The union of spheres of radius [`particle_radius`] around the particles: at each cell
    /// centre, the distance to the nearest particle within a cell's reach minus the radius;
    /// `+radius` (outside) where none is that close.
    pub fn from_particles<const D: usize>(grid: &Grid<D>, pos: &[Vector<D>]) -> Self {
        let mut phi = Self {
            phi: vec![particle_radius(D); grid.num_cells()],
        };
        phi.unite_spheres(grid, pos);
        phi
    }

    /// The function `f` sampled at the cell centres.
    pub fn sampled<const D: usize>(grid: &Grid<D>, f: impl Fn(&Vector<D>) -> f64) -> Self {
        let phi = (0..grid.num_cells())
            .map(|c| f(&grid.center(grid.cell_coords(c))))
            .collect();
        Self { phi }
    }

    /// Multilinear interpolation at `x`, with points nearer a wall than the outermost cell
    /// centres clamped onto them.
    pub fn interpolate<const D: usize>(&self, grid: &Grid<D>, x: &Vector<D>) -> f64 {
        let x = Vector::<D>::from_fn(|k, _| x[k].clamp(0.5, grid.dims[k] as f64 - 0.5));
        let mut v = 0.0;
        for_each_cell_weight(grid, &x, |c, w| v += w * self.phi[c]);
        v
    }

    /// The level set at the face of axis `a` with coordinates `f`, interpolated from the
    /// centres: the mean of the two cells' values, or the one cell's on the domain's boundary
    /// ([`LevelSet::interpolate`] at the face's centre, whose other weights are 0: the same
    /// value, up to the sign of a zero).
    pub fn at_face<const D: usize>(&self, grid: &Grid<D>, a: usize, f: Cell<D>) -> f64 {
        let mut cells = grid.face_cells_at(a, f).map(|c| self.phi[c]);
        match (cells.next(), cells.next()) {
            (Some(lower), Some(upper)) => 0.5 * lower + 0.5 * upper,
            (Some(only), None) => only,
            _ => unreachable!("a face has a cell on one side at least"),
        }
    }

    /// Semi-Lagrangian advection over `dt` (first order, as MantaFlow's scene advects `phi`),
    /// of the cells `cells` only: each of their centres in `out` takes the value of `self`
    /// found where the velocity traces it back from.
    pub fn advect_into<const D: usize>(
        &self,
        grid: &Grid<D>,
        u: &MacField<D>,
        dt: f64,
        cells: &[usize],
        out: &mut LevelSet,
    ) {
        let at_centres = AtGridPoints::centres(grid);
        let values: Vec<f64> = cells
            .par_iter()
            .map(|&c| {
                let cc = grid.cell_coords(c);
                let x = grid.center(cc);
                self.interpolate(grid, &(x - dt * at_centres.interpolate(grid, u, cc)))
            })
            .collect();
        for (&c, v) in cells.iter().zip(values) {
            out.phi[c] = v;
        }
    }

    /// Ferstl et al.'s combination of the two level sets on the cells `cells`: the advected
    /// one shrunk by one cell (so that liquid the particles left does not linger), united with
    /// the particles' ([`LevelSet::from_particles`]; every particle's cell and its neighbours
    /// must be among `cells`).
    pub fn unite_shrunk<const D: usize>(
        &mut self,
        grid: &Grid<D>,
        advected: &LevelSet,
        pos: &[Vector<D>],
        cells: &[usize],
    ) {
        let radius = particle_radius(D);
        for &c in cells {
            self.phi[c] = (advected.phi[c] + 1.0).min(radius);
        }
        self.unite_spheres(grid, pos);
    }

    /// The union with every particle's sphere, at the centres within a cell's reach, in place.
    /// A particle lowers only the layers (cells along the last axis, contiguous in memory) next
    /// to its own, so the particles are sorted into slabs of [`SLAB`] layers, and the slabs of
    /// one parity, whose reaches do not overlap, run in parallel on their own part of the level
    /// set, then those of the other. A minimum, so the result does not depend on the order;
    /// nothing is allocated per particle (collecting the lowered values took 4.8 GiB while
    /// the 11 M particles of deep-pool-3d at 128^3 were first thinned).
    fn unite_spheres<const D: usize>(&mut self, grid: &Grid<D>, pos: &[Vector<D>]) {
        let reach: Vec<([usize; D], isize)> = (0..3usize.pow(D as u32))
            .map(|code| {
                let digits = std::array::from_fn(|k| code / 3usize.pow(k as u32) % 3);
                let step = (0..D).map(|k| (digits[k] as isize - 1) * grid.cell_stride(k) as isize);
                (digits, step.sum())
            })
            .collect();
        let layers = grid.dims[D - 1];
        let per_layer = grid.num_cells() / layers;
        let mut slabs: Vec<Vec<u32>> = vec![vec![]; layers.div_ceil(SLAB)];
        for (i, x) in pos.iter().enumerate() {
            let cell = grid.cell_of(x).expect("particle inside the domain");
            slabs[cell[D - 1] / SLAB].push(i as u32);
        }
        // Slab k lowers layers [k SLAB - 1, (k + 1) SLAB + 1): with SLAB >= 2, those of k and
        // k + 2 are apart.
        let span = |k: usize| {
            (
                (k * SLAB).saturating_sub(1),
                ((k + 1) * SLAB + 1).min(layers),
            )
        };
        for parity in 0..2 {
            let mut jobs = vec![];
            let (mut rest, mut start) = (&mut self.phi[..], 0);
            for k in (parity..slabs.len()).step_by(2) {
                let (lo, hi) = span(k);
                let tail = std::mem::take(&mut rest)
                    .split_at_mut((lo - start) * per_layer)
                    .1;
                let (own, tail) = tail.split_at_mut((hi - lo) * per_layer);
                (rest, start) = (tail, hi);
                jobs.push((&slabs[k], lo * per_layer, own));
            }
            jobs.into_par_iter().for_each(|(particles, offset, phi)| {
                for &i in particles {
                    lower_by_sphere(grid, &reach, &pos[i as usize], &mut phi[..], offset);
                }
            });
        }
    }

    /// Re-marches the level set on one side of its zero crossing (MantaFlow's
    /// `extrapolateLsSimple`), over the cells `cells` only: the cells next to the other side
    /// keep their values; each further layer takes the mean of its neighbours in the layer
    /// before, one cell further from the surface; cells beyond `layers` layers get `layers + 2`
    /// cells. Solid cells are left out: a wall is not a surface, and the march does not run
    /// through a solid, so it never carries liquid into one nor across one (their values are
    /// [`LevelSet::extend_into_solids`]'). The march does not leave `cells`; `layer` is
    /// scratch space, kept between calls so that a call works on `cells` alone (all
    /// [`FROZEN`] outside a call).
    pub fn remarch<const D: usize>(
        &mut self,
        grid: &Grid<D>,
        march: March,
        solid: &[bool],
        cells: &[usize],
        layer: &mut Vec<u32>,
    ) {
        let sign = match march.side {
            Side::Inside => -1.0,
            Side::Outside => 1.0,
        };
        let other = |c: usize| !solid[c] && self.phi[c] * sign < 0.0;
        // FROZEN: not worked on, 0: not reached, 1: the other side, d + 1: layer d.
        layer.resize(grid.num_cells(), FROZEN);
        for &c in cells.iter().filter(|&&c| !solid[c]) {
            layer[c] = u32::from(other(c));
        }
        let mut ring: Vec<usize> = cells
            .par_iter()
            .copied()
            .filter(|&c| layer[c] == 0 && grid.face_neighbors(c).any(other))
            .collect();
        ring.iter().for_each(|&c| layer[c] = 2);
        for d in 2..=march.layers {
            // Layer `d + 1`: the cells not reached next to layer `d`, each marked and given
            // the mean of its layer-`d` neighbours as it is found. Its value reads layer `d`
            // only, so the order in which the cells are found does not change it.
            let mut next = vec![];
            for &c in &ring {
                for n in grid.face_neighbors(c) {
                    if layer[n] == 0 {
                        layer[n] = d + 1;
                        self.phi[n] = mean_of_layer(grid, &self.phi, layer, n, d) + sign;
                        next.push(n);
                    }
                }
            }
            ring = next;
        }
        let cap = march.cap();
        for &c in cells {
            if layer[c] == 0 {
                self.phi[c] = cap;
            }
            layer[c] = FROZEN;
        }
    }

    /// Carves the moving obstacles (their cells `obstacle`) out of the liquid: the liquid
    /// minus the solid, `max(phi, -phi_obstacle)`, as MantaFlow's scenes subtract an
    /// obstacle's level set from the liquid's (`phi.subtract(phiObs)`), with the obstacle's
    /// signed distance at the cell centres taken as `-1/2` in its cells and `+1/2` in the cells
    /// next to them that are not solid (half a cell: a centre to its face). So an obstacle is
    /// air to the level set: never liquid, the liquid next to it is at its surface (carried by
    /// particles, as the markings' surface there is, sec. soilds), and what it covers or leaves
    /// is not liquid until liquid flows in. The re-marches then measure from there (they leave
    /// only the static solids out). Without it the liquid a blocked obstacle's boundary
    /// velocity pushes out from under it stayed there in the level set as well: 217 % of `V*`
    /// on large-obstacle-2d.
    pub fn carve<const D: usize>(&mut self, grid: &Grid<D>, obstacle: &[usize], solid: &[bool]) {
        for &c in obstacle {
            self.phi[c] = self.phi[c].max(HALF_CELL);
            for n in grid.face_neighbors(c).filter(|&n| !solid[n]) {
                self.phi[n] = self.phi[n].max(-HALF_CELL);
            }
        }
    }

    /// The values of the solid cells of `cells`, after the re-marches: a solid cell next to
    /// cells that are not solid (its Moore neighbourhood, which is what an interpolation
    /// within a cell of them reads) takes the mean of theirs, the others the air's cap
    /// `outside`. So the level set extends into a solid as MantaFlow's, whose re-march passes
    /// through obstacles, and interpolation next to a wall reads the liquid's own values; a
    /// solid cell is never liquid whatever its value (liquid is `phi < 0` outside solids: the
    /// markings, resampling and the zero crossing all ask `solid` first). A solid cell next
    /// to air takes at least 0: the surface meets the wall there, and a cell of air next to
    /// it must not read the depth of liquid beyond the wall (a wall between deep liquid and
    /// air otherwise grows liquid along it). The
    /// values are found first and written after, so they read no other solid's new value.
    pub fn extend_into_solids<const D: usize>(
        &mut self,
        grid: &Grid<D>,
        solid: &[bool],
        cells: &[usize],
        outside: f64,
    ) {
        let solids: Vec<usize> = cells.iter().copied().filter(|&c| solid[c]).collect();
        let values: Vec<f64> = (solids.par_iter().with_min_len(crate::PAR_GRAIN))
            .map(|&c| {
                let open = grid.moore_neighbors(grid.cell_coords(c));
                let open = open.map(|m| grid.cell_index(m)).filter(|&m| !solid[m]);
                let (sum, n, air) = open.fold((0.0, 0, false), |(s, k, air), m| {
                    (s + self.phi[m], k + 1, air || self.phi[m] >= 0.0)
                });
                match (n, air) {
                    (0, _) => outside,
                    (_, false) => sum / n as f64,
                    (_, true) => (sum / n as f64).max(0.0),
                }
            })
            .collect();
        for (c, v) in solids.into_iter().zip(values) {
            self.phi[c] = v;
        }
    }

    /// The cells of `cells` at the zero crossing, ascending: liquid cells (not solid,
    /// `phi < 0`) next to a cell that is neither; found in parallel.
    pub fn crossing<const D: usize>(
        &self,
        grid: &Grid<D>,
        solid: &[bool],
        cells: &[usize],
    ) -> Vec<usize> {
        let liquid = |c: usize| !solid[c] && self.phi[c] < 0.0;
        (cells.par_iter().with_min_len(crate::PAR_GRAIN))
            .copied()
            .filter(|&c| liquid(c) && grid.face_neighbors(c).any(|n| !liquid(n)))
            .collect()
    }
}

/// A re-march: the side and how many layers deep.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct March {
    pub side: Side,
    pub layers: u32,
}

impl March {
    /// The value of cells beyond the march: `layers + 2` cells from the surface.
    pub fn cap(&self) -> f64 {
        let cap = (self.layers + 2) as f64;
        match self.side {
            Side::Inside => -cap,
            Side::Outside => cap,
        }
    }
}

/// Layers of cells per slab of [`LevelSet::unite_spheres`] (at least 2, so that the slabs of
/// one parity lower disjoint layers).
const SLAB: usize = 4;

/// How much further than `phi + radius` [`lower_by_sphere`] looks for a sphere that lowers a
/// centre, in cells: far above the rounding error of distances of a few cells, so that the
/// test skips only spheres whose distance would not lower the centre.
const SPHERE_TEST_SLACK: f64 = 1e-9;

/// The distance from a cell's centre to its faces, cells.
const HALF_CELL: f64 = 0.5;

/// [`LevelSet::remarch`]'s mark of a cell it does not work on.
pub const FROZEN: u32 = u32::MAX;

/// [`LevelSet::unite_spheres`] for the particle at `x`: the centres of its cell's Moore
/// neighbourhood (`reach`: per axis the offset plus one, and the index step) lowered to the
/// distance from `x` minus [`particle_radius`], in `phi`, the part of the level set from cell
/// `offset` on. The bounds are checked only for a cell on the domain's boundary. The squared
/// distances are summed from the `3 D` squared differences along the axes, in axis order:
/// bit for bit `norm_squared` of the difference of the centre and `x`, which sums the same
/// squares in the same order.
fn lower_by_sphere<const D: usize>(
    grid: &Grid<D>,
    reach: &[([usize; D], isize)],
    x: &Vector<D>,
    phi: &mut [f64],
    offset: usize,
) {
    let radius = particle_radius(D);
    let cell = grid.cell_of(x).expect("particle inside the domain");
    let own = grid.cell_index(cell) as isize - offset as isize;
    let inner = (0..D).all(|k| 0 < cell[k] && cell[k] + 1 < grid.dims[k]);
    // Per axis, the squared difference to the centres one below `x`'s cell, in it and above
    // (centre `cell + j - 1 + 1/2`, exact).
    let squares: [[f64; 3]; D] = std::array::from_fn(|k| {
        std::array::from_fn(|j| {
            let d = ((cell[k] + j) as f64 - 0.5) - x[k];
            d * d
        })
    });
    for (digits, step) in reach {
        let within = |k: usize| (cell[k] + digits[k]).wrapping_sub(1) < grid.dims[k];
        if inner || (0..D).all(within) {
            let c = (own + step) as usize;
            // The sphere lowers the centre only if its distance is below `phi + radius`
            // (rounding errors are far below the slack): no root for most centres.
            let reach = phi[c] + radius + SPHERE_TEST_SLACK;
            let d2 = (1..D).fold(squares[0][digits[0]], |s, k| s + squares[k][digits[k]]);
            if reach > 0.0 && d2 < reach * reach {
                phi[c] = phi[c].min(d2.sqrt() - radius);
            }
        }
    }
}

/// The mean of `phi` over the von Neumann neighbours of cell `c` in layer `d` of a re-march
/// (`layer`), summed in [`Grid::face_neighbors`]' order.
fn mean_of_layer<const D: usize>(
    grid: &Grid<D>,
    phi: &[f64],
    layer: &[u32],
    c: usize,
    d: u32,
) -> f64 {
    let (sum, n) = grid
        .face_neighbors(c)
        .filter(|&n| layer[n] == d)
        .fold((0.0, 0), |(s, k), n| (s + phi[n], k + 1));
    sum / n as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_particle_gives_its_sphere_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let x = Vector::<D>::from_element(2.3);
            let ls = LevelSet::from_particles(&g, &[x]);
            let r = particle_radius(D);
            for c in 0..g.num_cells() {
                let d = (g.center(g.cell_coords(c)) - x).norm();
                // Within a cell's reach: the sphere's distance, at most r; farther: r.
                let want = if g.cell_coords(c).iter().all(|&k| k.abs_diff(2) <= 1) {
                    (d - r).min(r)
                } else {
                    r
                };
                assert!((ls.phi[c] - want).abs() < 1e-12, "{:?}", g.cell_coords(c));
            }
            // A particle anywhere in a cell puts that cell's centre inside.
            let corner = Vector::<D>::from_element(3.001);
            let ls = LevelSet::from_particles(&g, &[corner]);
            assert!(ls.phi[g.cell_index([3; D])] < 0.0);
        }
        check([6, 5]);
        check([6, 5, 4]);
    }

    /// A flat surface at height `h` along the last axis: `phi = x_last - h`.
    fn plane<const D: usize>(g: &Grid<D>, h: f64) -> LevelSet {
        LevelSet::sampled(g, |x| x[D - 1] - h)
    }

    #[test]
    fn a_plane_is_transported_by_a_uniform_flow_and_interpolates_exactly_3d() {
        let g = Grid::new([4, 5, 12]);
        let mut u = MacField::zeros(&g);
        u.comp[2].iter_mut().for_each(|v| *v = -2.0);
        let mut ls = LevelSet {
            phi: vec![f64::NAN; g.num_cells()],
        };
        let all: Vec<usize> = (0..g.num_cells()).collect();
        plane(&g, 6.2).advect_into(&g, &u, 0.5, &all, &mut ls);
        let want = plane(&g, 5.2);
        for c in 0..g.num_cells() {
            // The trace-back leaves the domain above the top centre: clamped there.
            if g.cell_coords(c)[2] < 10 {
                assert!((ls.phi[c] - want.phi[c]).abs() < 1e-12);
            }
        }
        let x = Vector::<3>::new(1.7, 2.2, 4.9);
        assert!((want.interpolate(&g, &x) - (4.9 - 5.2)).abs() < 1e-12);
        assert!((want.at_face(&g, 2, [1, 1, 4]) - (4.0 - 5.2)).abs() < 1e-12);
    }

    #[test]
    fn the_level_set_at_a_face_is_its_interpolation_there_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let ls = LevelSet {
                phi: (0..g.num_cells())
                    .map(|c| ((c * 13) as f64 * 0.71).sin() * 9.0)
                    .collect(),
            };
            for a in 0..D {
                for i in 0..g.num_faces(a) {
                    let f = g.face_coords(a, i);
                    let want = ls.interpolate(&g, &g.face_point(a, f));
                    assert_eq!(ls.at_face(&g, a, f), want, "axis {a}, face {f:?}");
                }
            }
        }
        check([5, 4]);
        check([1, 3]);
        check([4, 3, 5]);
    }

    #[test]
    fn remarching_gives_one_cell_per_layer_and_caps_beyond_2d() {
        // A wrong interior (all -0.1) under a plane at height 7.2: re-marched inwards 3
        // layers, the first inside layer (y = 6) keeps its value, the next two step down by one
        // cell each, and the rest is capped at -(3 + 2).
        let g = Grid::new([5, 12]);
        let mut ls = plane(&g, 7.2);
        for c in 0..g.num_cells() {
            if ls.phi[c] < -1.0 {
                ls.phi[c] = -0.1;
            }
        }
        let all: Vec<usize> = (0..g.num_cells()).collect();
        let inside = March {
            side: Side::Inside,
            layers: 3,
        };
        ls.remarch(&g, inside, &vec![false; g.num_cells()], &all, &mut vec![]);
        for c in 0..g.num_cells() {
            let y = g.cell_coords(c)[1];
            let want = match y {
                4.. => y as f64 + 0.5 - 7.2,
                _ => -5.0,
            };
            assert!((ls.phi[c] - want).abs() < 1e-12, "y = {y}: {}", ls.phi[c]);
        }
    }

    #[test]
    fn a_wall_does_not_start_a_march_3d() {
        // Liquid filling a tank whose floor is a layer of solid cells with positive values:
        // re-marched inwards, the liquid's values depend only on the free surface above.
        let g = Grid::new([3, 3, 10]);
        let solid: Vec<bool> = (0..g.num_cells())
            .map(|c| g.cell_coords(c)[2] == 0)
            .collect();
        let mut ls = plane(&g, 6.0);
        for c in 0..g.num_cells() {
            if solid[c] {
                ls.phi[c] = 4.0;
            }
        }
        let all: Vec<usize> = (0..g.num_cells()).collect();
        let march = |side, layers| March { side, layers };
        let mut layer = vec![];
        ls.remarch(&g, march(Side::Inside, 10), &solid, &all, &mut layer);
        assert!(layer.iter().all(|&l| l == FROZEN), "scratch left as found");
        for c in 0..g.num_cells() {
            let z = g.cell_coords(c)[2];
            if (1..6).contains(&z) {
                assert_eq!(ls.phi[c], z as f64 + 0.5 - 6.0, "z = {z}");
            }
        }
        // Outwards, from the liquid: the air above steps up by one cell per layer.
        ls.phi.iter_mut().for_each(|v| *v += 0.25);
        ls.remarch(&g, march(Side::Outside, 2), &solid, &all, &mut layer);
        assert_eq!(ls.phi[g.cell_index([1, 1, 6])], 0.75);
        assert_eq!(ls.phi[g.cell_index([1, 1, 7])], 1.75);
        assert_eq!(ls.phi[g.cell_index([1, 1, 9])], 4.0);
    }

    #[test]
    fn the_march_leaves_solids_alone_and_the_extension_reads_their_open_neighbours_2d_and_3d() {
        // A wall (solid column x = 2) between deep liquid (x < 2) and air (x > 2), under a
        // free surface at height 3.2 on the liquid's side: the inward march does not cross the
        // wall, the wall keeps its value through both marches, and the extension then gives a
        // wall cell the mean of its open Moore neighbours, at least 0 next to air.
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let at = |c: usize| g.cell_coords(c);
            let solid: Vec<bool> = (0..g.num_cells()).map(|c| at(c)[0] == 2).collect();
            let mut ls = LevelSet::sampled(&g, |x| if x[0] < 2.0 { x[1] - 3.2 } else { 7.0 });
            let wall = g.cell_index(std::array::from_fn(|k| if k == 0 { 2 } else { 1 }));
            ls.phi[wall] = -123.0;
            let all: Vec<usize> = (0..g.num_cells()).collect();
            let (mut layer, inside) = (
                vec![],
                March {
                    side: Side::Inside,
                    layers: 6,
                },
            );
            ls.remarch(&g, inside, &solid, &all, &mut layer);
            ls.remarch(&g, OUTWARDS_3, &solid, &all, &mut layer);
            assert_eq!(
                ls.phi[wall], -123.0,
                "{D}D: the march reached into the wall"
            );
            for c in (0..g.num_cells()).filter(|&c| at(c)[0] > 2) {
                assert!(ls.phi[c] > 0.0, "{D}D: liquid marched across the wall");
            }
            ls.extend_into_solids(&g, &solid, &all, 5.0);
            for c in (0..g.num_cells()).filter(|&c| solid[c]) {
                let open: Vec<f64> = g
                    .moore_neighbors(at(c))
                    .map(|m| g.cell_index(m))
                    .filter(|&m| !solid[m])
                    .map(|m| ls.phi[m])
                    .collect();
                let mean = open.iter().sum::<f64>() / open.len() as f64;
                let want = if open.iter().any(|&v| v >= 0.0) {
                    mean.max(0.0)
                } else {
                    mean
                };
                assert!((ls.phi[c] - want).abs() < 1e-12, "{D}D {:?}", at(c));
            }
        }
        check([5, 6]);
        check([5, 6, 3]);
    }

    /// The outward march of three layers.
    const OUTWARDS_3: March = March {
        side: Side::Outside,
        layers: 3,
    };

    #[test]
    fn carving_makes_an_obstacle_air_and_its_open_neighbours_its_surface_2d_and_3d() {
        // Deep liquid everywhere (-7), an obstacle in the middle cell, a static solid beside
        // it: the obstacle's cell is +1/2, its open face neighbours -1/2, the static solid and
        // every other cell as they were.
        fn check<const D: usize>(dims: [usize; D]) {
            let g = Grid::new(dims);
            let mut ls = LevelSet {
                phi: vec![-7.0; g.num_cells()],
            };
            let obstacle = g.cell_index([2; D]);
            let wall = g.cell_index(std::array::from_fn(|k| if k == 0 { 3 } else { 2 }));
            let mut solid = vec![false; g.num_cells()];
            solid[obstacle] = true;
            solid[wall] = true;
            ls.carve(&g, &[obstacle], &solid);
            let faces: Vec<usize> = g.face_neighbors(obstacle).collect();
            for c in 0..g.num_cells() {
                let want = match c {
                    c if c == obstacle => 0.5,
                    c if c != wall && faces.contains(&c) => -0.5,
                    _ => -7.0,
                };
                assert_eq!(ls.phi[c], want, "{D}D {:?}", g.cell_coords(c));
            }
            // Air stays air: carving only raises the level set.
            ls.phi.iter_mut().for_each(|v| *v = 3.0);
            ls.carve(&g, &[obstacle], &solid);
            assert!(ls.phi.iter().all(|&v| v == 3.0));
        }
        check([5, 5]);
        check([5, 5, 5]);
    }
}
