//! The volume measure of paper eq. volume: how much liquid the markings hold, in cells.

use crate::grid::active::Active;
use crate::stages::markings::{CellKind, Markings};

/// Total fluid volume `V = sum_c V_c` in cells (paper eq. volume), each cell's `V_c` from
/// [`cell_volume`], summed in cell order over `active`, which holds every fluid cell (the
/// others add exactly zero).
pub fn volume_cells<const D: usize>(markings: &Markings, mu: u32, active: &Active<D>) -> f64 {
    (active.each_cell()).fold(0.0, |v, c| v + cell_volume(markings, mu, c))
}

/// Cell `c`'s fluid volume `V_c` in cells (paper eq. volume): 0 for non-fluid cells (depth >
/// 0), `min(1, |gamma_c| / mu)` for cells at depth -1 or 0, and 1 for deeper fluid cells.
/// Solid cells count as pure solid, whatever they hold.
pub fn cell_volume(markings: &Markings, mu: u32, c: usize) -> f64 {
    if markings.kind[c] != CellKind::Fluid {
        return 0.0;
    }
    match markings.depth(c) {
        d if d >= -1 => (markings.count[c] as f64 / mu as f64).min(1.0),
        _ => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{Grid, Vector};

    #[test]
    fn volume_counts_near_surface_cells_by_fill_and_deep_cells_as_full() {
        // 6x6 tank, fluid in the bottom 4 rows; one deep cell holds a single particle (a
        // bubble: counts 1), one surface cell holds 2 of mu = 4, one holds 6 (overflow: 1).
        let g = Grid::new([6, 6]);
        let mu = 4;
        let mut pos = vec![];
        for c in 0..g.num_cells() {
            let cc = g.cell_coords(c);
            if cc[1] >= 4 {
                continue;
            }
            let n = match cc {
                [0, 0] => 1,
                [2, 3] => 2,
                [3, 3] => 6,
                _ => mu,
            };
            for k in 0..n {
                pos.push(Vector::<2>::new(
                    cc[0] as f64 + 0.1 + 0.1 * k as f64,
                    cc[1] as f64 + 0.5,
                ));
            }
        }
        let m = Markings::compute(&g, &pos, &[false; 36]);
        assert_eq!(m.depth(g.cell_index([0, 0])), -3);
        let v = volume_cells(&m, mu, &Active::all(&g));
        assert!((v - (24.0 - 0.5)).abs() < 1e-12, "{v}");
    }
}
