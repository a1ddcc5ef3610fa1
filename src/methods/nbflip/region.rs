//! The cells narrow-band FLIP's level set is worked on in a step: whole tiles of
//! [`TILE`]`^D` cells around the surface, rebuilt every step (Ferstl et al. 2016, sec. 4, keep
//! their level set "only in a narrow band"; MantaFlow works on the whole grid). Cells outside
//! keep their values: far inside the liquid the level set is `-(R + 4)`, far outside `+5`
//! (the caps of the re-march), and a step does no work there.

use crate::grid::Grid;

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

    /// The cells of every tile within `margin` cells (in every axis) of a tile holding a seed
    /// cell: each cell within `margin` of a seed is in the region.
    pub fn around<const D: usize>(
        grid: &Grid<D>,
        seeds: impl Iterator<Item = usize>,
        margin: usize,
    ) -> Self {
        let tiles = tiles(grid);
        let reach = margin.div_ceil(TILE);
        let mut seeded = vec![false; tiles.num_cells()];
        for c in seeds {
            seeded[tile_of(grid, &tiles, c)] = true;
        }
        let mut active = vec![false; tiles.num_cells()];
        for t in (0..tiles.num_cells()).filter(|&t| seeded[t]) {
            let tc = tiles.cell_coords(t);
            for_each_in_box(
                &tiles,
                tc.map(|k| k.saturating_sub(reach)),
                tc.map(|k| k + reach),
                |n| active[n] = true,
            );
        }
        Self {
            cells: cells_of_tiles(grid, &tiles, &active),
            tiles: active,
        }
    }
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
/// tiles (work per row of cells, not per cell outside the region).
fn cells_of_tiles<const D: usize>(grid: &Grid<D>, tiles: &Grid<D>, active: &[bool]) -> Vec<usize> {
    let mut out = vec![];
    let rows = grid.num_cells() / grid.dims[0];
    for row in 0..rows {
        let first = row * grid.dims[0];
        let tile_row = tile_of(grid, tiles, first);
        for t in 0..tiles.dims[0] {
            if active[tile_row + t] {
                let start = first + t * TILE;
                out.extend(start..(start + TILE).min(first + grid.dims[0]));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_region_covers_the_margin_around_its_seeds_and_no_far_cell_2d_and_3d() {
        fn check<const D: usize>(dims: [usize; D], seed: [usize; D], margin: usize) {
            let g = Grid::new(dims);
            let r = Region::around(&g, std::iter::once(g.cell_index(seed)), margin);
            assert!(
                r.cells.windows(2).all(|w| w[0] < w[1]),
                "ascending, no repeats"
            );
            for c in 0..g.num_cells() {
                let cc = g.cell_coords(c);
                let far = (0..D).map(|k| cc[k].abs_diff(seed[k])).max().unwrap();
                let inside = r.cells.binary_search(&c).is_ok();
                // Within the margin: in; beyond the margin plus two tiles: out.
                assert!(far > margin || inside, "{cc:?} missing");
                assert!(far <= margin + 2 * TILE || !inside, "{cc:?} too far");
            }
        }
        check([37, 30], [20, 3], 5);
        let g = Grid::new([37, 30]);
        let a = Region::around(&g, std::iter::once(g.cell_index([2, 2])), 1);
        let b = Region::around(&g, std::iter::once(g.cell_index([30, 25])), 1);
        let both = a.union(&g, &b);
        assert_eq!(both.cells.len(), a.cells.len() + b.cells.len());
        assert_eq!(both.minus(&g, &a), b.cells);
        assert!(a.minus(&g, &both).is_empty());
        check([19, 22, 17], [9, 15, 16], 6);
        let g = Grid::new([9, 7, 5]);
        assert_eq!(Region::all(&g).cells.len(), g.num_cells());
        assert!(Region::around(&g, std::iter::empty(), 3).cells.is_empty());
    }
}
