//! The cells narrow-band FLIP's level set is worked on in a step: whole tiles of
//! [`TILE`]`^D` cells around the surface, rebuilt every step (Ferstl et al. 2016, sec. 4, keep
//! their level set "only in a narrow band"; MantaFlow works on the whole grid). Cells outside
//! keep their values: far inside the liquid the level set is `-(R + 4)`, far outside `+5`
//! (the caps of the re-march), and a step does no work there.

use crate::grid::{Cell, Grid};

/// The edge of a tile in cells: the coarse grid of tiles is `TILE^D` times smaller than the
/// grid, so a pass over it is cheap, and a tile is small enough that the region hugs the
/// surface. (A choice of this code: 4 keeps the region within about `margin + 4` cells.)
pub const TILE: usize = 4;

/// The cells worked on, ascending: every cell, or those of the tiles within a margin of some
/// seed cells.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Region {
    /// Per tile (the coarse grid [`tiles`]), whether its cells are in.
    tiles: Vec<bool>,
    pub cells: Vec<usize>,
}

/// The coarse grid of tiles over `grid`.
fn tiles<const D: usize>(grid: &Grid<D>) -> Grid<D> {
    Grid::new(grid.dims.map(|n| n.div_ceil(TILE)))
}

/// The tile of cell `c`.
fn tile_of<const D: usize>(grid: &Grid<D>, tiles: &Grid<D>, c: usize) -> usize {
    tiles.cell_index(grid.cell_coords(c).map(|k| k / TILE))
}

impl Region {
    /// Every cell of the grid (the dense level set, and the first step).
    pub fn all<const D: usize>(grid: &Grid<D>) -> Self {
        Self {
            tiles: vec![true; tiles(grid).num_cells()],
            cells: (0..grid.num_cells()).collect(),
        }
    }

    /// The region of these tiles' cells (`tiles` as [`Region::tiles`] gave them).
    pub fn of_tiles<const D: usize>(grid: &Grid<D>, tiles: Vec<bool>) -> Option<Self> {
        let coarse = self::tiles(grid);
        (tiles.len() == coarse.num_cells()).then(|| Self {
            cells: cells_of_tiles(grid, &coarse, &tiles),
            tiles,
        })
    }

    /// Whether cell `c` is in the region.
    pub fn contains<const D: usize>(&self, grid: &Grid<D>, c: usize) -> bool {
        self.tiles[tile_of(grid, &tiles(grid), c)]
    }

    /// Per tile, whether its cells are in (what a checkpoint keeps of a region).
    pub fn tiles(&self) -> &[bool] {
        &self.tiles
    }

    /// The cells in either region.
    pub fn union<const D: usize>(&self, grid: &Grid<D>, other: &Region) -> Self {
        let active = self.tiles_with(other, |a, b| a || b);
        Self {
            cells: cells_of_tiles(grid, &tiles(grid), &active),
            tiles: active,
        }
    }

    /// The cells in this region and not in `other`, ascending.
    pub fn minus<const D: usize>(&self, grid: &Grid<D>, other: &Region) -> Vec<usize> {
        cells_of_tiles(grid, &tiles(grid), &self.tiles_with(other, |a, b| a && !b))
    }

    /// Per tile, `op` of whether it is in this region and whether it is in `other`.
    fn tiles_with(&self, other: &Region, op: impl Fn(bool, bool) -> bool) -> Vec<bool> {
        let pairs = self.tiles.iter().zip(&other.tiles);
        pairs.map(|(&a, &b)| op(a, b)).collect()
    }

    /// The cells of every tile within `margin.outside` cells (in every axis) of a tile holding a
    /// seed cell, and of every tile within `margin.inside` cells of one that holds a cell for
    /// which `inner` holds: each cell within `margin.outside` of a seed is in the region, and
    /// so is each cell of the inner side within `margin.inside`.
    pub fn around<const D: usize>(
        grid: &Grid<D>,
        seeds: impl Iterator<Item = Cell<D>>,
        margin: Margin,
        inner: impl Fn(usize) -> bool,
    ) -> Self {
        let tiles = tiles(grid);
        let mut seeded = vec![false; tiles.num_cells()];
        for c in seeds {
            seeded[tiles.cell_index(c.map(|k| k / TILE))] = true;
        }
        let [inside, outside] = [margin.inside, margin.outside]
            .map(|margin| dilate(&tiles, &seeded, margin.div_ceil(TILE)));
        let active: Vec<bool> = (0..tiles.num_cells())
            .map(|t| outside[t] || inside[t] && cells_of_tile(grid, &tiles, t).any(&inner))
            .collect();
        Self {
            cells: cells_of_tiles(grid, &tiles, &active),
            tiles: active,
        }
    }
}

/// How far from its seeds a region reaches, in cells along every axis: on the inner side
/// (the liquid's), and elsewhere.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Margin {
    pub inside: usize,
    pub outside: usize,
}

/// Per tile, whether it lies within `reach` tiles, along every axis, of a tile of `from`: the
/// box around each, found one axis after the other (a box is the product of its intervals).
fn dilate<const D: usize>(tiles: &Grid<D>, from: &[bool], reach: usize) -> Vec<bool> {
    let mut near = from.to_vec();
    for a in 0..D {
        let stride = tiles.cell_stride(a);
        let before = near.clone();
        for t in (0..before.len()).filter(|&t| before[t]) {
            let i = tiles.cell_coords(t)[a];
            let line = t - i * stride;
            for j in i.saturating_sub(reach)..(i + reach + 1).min(tiles.dims[a]) {
                near[line + j * stride] = true;
            }
        }
    }
    near
}

/// The cells of tile `t`, clipped to the grid.
fn cells_of_tile<'a, const D: usize>(
    grid: &'a Grid<D>,
    tiles: &Grid<D>,
    t: usize,
) -> impl Iterator<Item = usize> + 'a {
    let lo = tiles.cell_coords(t).map(|k| k * TILE);
    let hi = lo.map(|k| k + TILE - 1);
    let mut cells = vec![];
    for_each_in_box(grid, lo, hi, |c| cells.push(c));
    cells.into_iter()
}

/// Calls `f` with the index of every cell of `grid` with coordinates in `lo..=hi` (clipped to
/// the grid), in ascending order.
fn for_each_in_box<const D: usize>(
    grid: &Grid<D>,
    lo: [usize; D],
    hi: [usize; D],
    mut f: impl FnMut(usize),
) {
    let hi: [usize; D] = std::array::from_fn(|k| hi[k].min(grid.dims[k] - 1));
    let mut c = lo;
    loop {
        f(grid.cell_index(c));
        let Some(k) = (0..D).find(|&k| c[k] < hi[k]) else {
            return;
        };
        c[k] += 1;
        (0..k).for_each(|j| c[j] = lo[j]);
    }
}

/// The cells of the active tiles, ascending: row by row along axis 0, a row's runs of active
/// tiles, read from a list per row of tiles (work per row of cells and per active tile, not
/// per tile of every row).
fn cells_of_tiles<const D: usize>(grid: &Grid<D>, tiles: &Grid<D>, active: &[bool]) -> Vec<usize> {
    let n0 = tiles.dims[0];
    let in_row: Vec<Vec<usize>> = (active.chunks(n0))
        .map(|row| (0..n0).filter(|&t| row[t]).collect())
        .collect();
    let mut out = vec![];
    for first in (0..grid.num_cells()).step_by(grid.dims[0]) {
        for &t in &in_row[tile_of(grid, tiles, first) / n0] {
            let start = first + t * TILE;
            out.extend(start..(start + TILE).min(first + grid.dims[0]));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_region_covers_the_margin_around_its_seeds_and_no_far_cell_2d_and_3d() {
        /// A seed with the inner side below `floor` along the last axis.
        fn check<const D: usize>(dims: [usize; D], seed: [usize; D], margin: Margin, floor: usize) {
            let g = Grid::new(dims);
            let inner = |c: usize| g.cell_coords(c)[D - 1] < floor;
            let r = Region::around(&g, std::iter::once(seed), margin, inner);
            assert!(
                r.cells.windows(2).all(|w| w[0] < w[1]),
                "ascending, no repeats"
            );
            for c in 0..g.num_cells() {
                let cc = g.cell_coords(c);
                let far = (0..D).map(|k| cc[k].abs_diff(seed[k])).max().unwrap();
                let inside = r.cells.binary_search(&c).is_ok();
                let need = match inner(c) {
                    true => margin.inside.max(margin.outside),
                    false => margin.outside,
                };
                assert!(far > need || inside, "{cc:?} missing");
                // Beyond the larger margin plus two tiles: out; beyond the outer one plus two
                // tiles, only the cells of a tile that has inner ones.
                let tile_inner = cc[D - 1] / TILE * TILE < floor;
                let widest = margin.inside.max(margin.outside);
                assert!(!inside || far <= widest + 2 * TILE, "{cc:?} too far");
                let near = far <= margin.outside + 2 * TILE;
                assert!(!inside || near || tile_inner, "{cc:?} too far outside");
            }
        }
        let even = |m| Margin {
            inside: m,
            outside: m,
        };
        let sided = Margin {
            inside: 9,
            outside: 3,
        };
        check([37, 30], [20, 3], even(5), 0);
        check([37, 30], [20, 13], sided, 12);
        let g = Grid::new([37, 30]);
        let around = |c| Region::around(&g, std::iter::once(c), even(1), |_| false);
        let (a, b) = (around([2, 2]), around([30, 25]));
        let both = a.union(&g, &b);
        assert_eq!(both.cells.len(), a.cells.len() + b.cells.len());
        assert_eq!(both.minus(&g, &a), b.cells);
        assert!(a.minus(&g, &both).is_empty());
        check([19, 22, 17], [9, 15, 16], even(6), 0);
        check([19, 22, 37], [9, 15, 16], sided, 15);
        let g = Grid::new([9, 7, 5]);
        assert_eq!(Region::all(&g).cells.len(), g.num_cells());
        let none = Region::around(&g, std::iter::empty(), even(3), |_| true);
        assert!(none.cells.is_empty());
    }
}
