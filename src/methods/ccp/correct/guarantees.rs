//! The guarantees of the correction step, checked after every correction from the final
//! positions alone (cheap: one pass over the particles and one over the cells).

use super::problem::cell_bounds;
use crate::grid::{Grid, Vector};
use crate::metrics::InvariantViolation;
use crate::sim::markings::Markings;
use crate::PAR_GRAIN;
use rayon::prelude::*;

/// The guarantees of the correction step (paper eq. problem3, or eq. band_con_update with the
/// band parameter `band_r`), checked from the final positions alone: every cell's count lies
/// within its bounds ([`cell_bounds`]: at most `mu`, or what it held if that was more; inner
/// cells keep their count) and no solid cell holds anything.
pub fn check_cell_counts<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    previous: &Markings,
    solid: &[bool],
    mu: u32,
    band_r: Option<u32>,
) -> Result<(), InvariantViolation> {
    let mut count = vec![0u32; grid.num_cells()];
    for x in pos {
        count[grid.cell_index_of(x)] += 1;
    }
    let breaks = |c: usize| {
        let (n, (lower, upper)) = (count[c], cell_bounds(previous, c, mu, band_r));
        n > upper || n < lower || (solid[c] && n > 0)
    };
    // The first broken cell, whatever the thread count: blocks in parallel, each searched by a
    // plain loop (rayon's per-item `find_first` cost several times the reads).
    let n = count.len();
    let r = (0..n.div_ceil(PAR_GRAIN))
        .into_par_iter()
        .find_map_first(|b| (b * PAR_GRAIN..n.min((b + 1) * PAR_GRAIN)).find(|&c| breaks(c)));
    let Some(c) = r else {
        return Ok(());
    };
    let (n, prev, cell) = (count[c], previous.count[c], grid.cell_coords(c));
    let (lower, upper) = cell_bounds(previous, c, mu, band_r);
    Err(InvariantViolation(if n > upper {
        format!(
            "cell {cell:?} holds {n} particles after the correction (mu = {mu}, before: {prev})"
        )
    } else if n < lower {
        format!("inner cell {cell:?} lost particles in the correction: {prev} -> {n}")
    } else {
        format!("solid cell {cell:?} holds {n} particles")
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One particle per cell of a full tank, then one moved: the check names the first broken
    /// cell in index order, with the reason, whatever the thread count.
    fn cell_count_check_names_the_first_broken_cell<const D: usize>() {
        let g = Grid::new([4; D]);
        let centers: Vec<_> = (0..g.num_cells())
            .map(|c| g.center(g.cell_coords(c)))
            .collect();
        let solid = vec![false; g.num_cells()];
        let prev = Markings::compute(&g, &centers, &solid);
        let check = |pos: &[Vector<D>], solid: &[bool]| {
            check_cell_counts(&g, pos, &prev, solid, 1, None).map_err(|e| e.0)
        };
        assert_eq!(check(&centers, &solid), Ok(()));
        let (inner, other) = (g.cell_index([1; D]), g.cell_index([2; D]));
        let mut moved = centers.clone();
        moved[inner] = centers[other];
        let e = check(&moved, &solid).unwrap_err();
        assert!(e.contains(&format!("inner cell {:?} lost", [1; D])), "{e}");
        let mut moved = centers.clone();
        moved[other] = centers[inner];
        let e = check(&moved, &solid).unwrap_err();
        assert!(
            e.contains(&format!("cell {:?} holds 2 particles", [1; D])),
            "{e}"
        );
        let mut walls = solid.clone();
        walls[g.cell_index([3; D])] = true;
        let e = check(&centers, &walls).unwrap_err();
        assert!(
            e.contains(&format!("solid cell {:?} holds 1", [3; D])),
            "{e}"
        );
    }

    #[test]
    fn cell_count_check_names_the_first_broken_cell_2d_and_3d() {
        cell_count_check_names_the_first_broken_cell::<2>();
        cell_count_check_names_the_first_broken_cell::<3>();
    }

    /// A grid of several search blocks (the last one partial): the first broken cell is found
    /// across blocks, in the last block too, on one thread or two.
    #[test]
    fn cell_count_check_searches_every_block_in_order() {
        let g = Grid::new([211, 211]);
        assert!(g.num_cells() > 2 * PAR_GRAIN && g.num_cells() % PAR_GRAIN != 0);
        let centers: Vec<_> = (0..g.num_cells())
            .map(|c| g.center(g.cell_coords(c)))
            .collect();
        let open = vec![false; g.num_cells()];
        let prev = Markings::compute(&g, &centers, &open);
        let first_broken = |walls: &[usize], threads: usize| {
            let mut solid = open.clone();
            walls.iter().for_each(|&c| solid[c] = true);
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
            let check = || check_cell_counts(&g, &centers, &prev, &solid, 1, None);
            pool.expect("a thread pool").install(check).unwrap_err().0
        };
        let (late, early, last) = (2 * PAR_GRAIN + 5, PAR_GRAIN + 7, g.num_cells() - 1);
        for threads in [1, 2] {
            let named = |c: usize| format!("solid cell {:?} holds 1", g.cell_coords(c));
            assert!(first_broken(&[late, early], threads).contains(&named(early)));
            assert!(first_broken(&[last], threads).contains(&named(last)));
        }
    }
}
