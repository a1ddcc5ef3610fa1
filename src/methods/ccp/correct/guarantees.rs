//! The guarantees of the correction step, checked after every correction from the final
//! positions alone (cheap: one pass over the particles and one over the active cells).

use super::problem::cell_bounds;
use crate::grid::active::Active;
use crate::grid::{Grid, Vector};
use crate::stages::invariants::InvariantViolation;
use crate::stages::markings::Markings;

/// The guarantees of the correction step (paper eq. problem3, or eq. band_con_update with the
/// band parameter `band_r`), checked from the final positions alone: every cell's count lies
/// within its bounds ([`cell_bounds`]: at most `mu`, or what it held if that was more; inner
/// cells keep their count) and no solid cell holds anything.
///
/// Only a cell that was fluid (a lower bound above 0) or holds a particle (a count above 0)
/// can break them. `active` must hold every fluid cell of `previous` (the state's active set
/// does); the search visits its cells and the cells off it that hold a particle.
pub fn check_cell_counts<const D: usize>(
    grid: &Grid<D>,
    pos: &[Vector<D>],
    previous: &Markings,
    solid: &[bool],
    mu: u32,
    band_r: Option<u32>,
    active: &Active<D>,
) -> Result<(), InvariantViolation> {
    let numbers = active.numbers(grid);
    let (mut count, mut off) = (vec![0u32; grid.num_cells()], vec![]);
    for x in pos {
        let cell = grid
            .cell_of(x)
            .unwrap_or_else(|| panic!("particle at {:?} is outside the domain", x.as_slice()));
        let c = grid.cell_index(cell);
        count[c] += 1;
        if numbers.at(cell).is_none() {
            off.push(c);
        }
    }
    let breaks = |c: usize| {
        let (n, (lower, upper)) = (count[c], cell_bounds(previous, c, mu, band_r));
        n > upper || n < lower || (solid[c] && n > 0)
    };
    // The first broken cell, whatever the thread count: on the set and off it.
    let in_set = active.first_cell(breaks);
    let off_set = off.into_iter().filter(|&c| breaks(c)).min();
    let Some(c) = in_set.into_iter().chain(off_set).min() else {
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
            check_cell_counts(&g, pos, &prev, solid, 1, None, &Active::all(&g)).map_err(|e| e.0)
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

    /// A grid of many lines, searched in parallel pieces (of 64 lines): the first broken cell
    /// is found in order across them, in the last line too, on one thread or two.
    #[test]
    fn cell_count_check_searches_every_line_in_order() {
        let g = Grid::new([211, 211]);
        let centers: Vec<_> = (0..g.num_cells())
            .map(|c| g.center(g.cell_coords(c)))
            .collect();
        let open = vec![false; g.num_cells()];
        let prev = Markings::compute(&g, &centers, &open);
        let first_broken = |walls: &[usize], threads: usize| {
            let mut solid = open.clone();
            walls.iter().for_each(|&c| solid[c] = true);
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
            let all = Active::all(&g);
            let check = || check_cell_counts(&g, &centers, &prev, &solid, 1, None, &all);
            pool.expect("a thread pool").install(check).unwrap_err().0
        };
        let (late, early) = (g.cell_index([5, 150]), g.cell_index([7, 70]));
        let last = g.num_cells() - 1;
        for threads in [1, 2] {
            let named = |c: usize| format!("solid cell {:?} holds 1", g.cell_coords(c));
            assert!(first_broken(&[late, early], threads).contains(&named(early)));
            assert!(first_broken(&[last], threads).contains(&named(last)));
        }
    }

    /// A pool in the lower half, active within 2 cells of it: a surface cell may give its
    /// particle away, but a cell far off the set that receives it breaks the bounds (solid,
    /// or holding more than mu), and the first broken cell is named across the set and off it.
    #[test]
    fn cell_count_check_finds_broken_cells_off_the_active_set() {
        let g = Grid::new([32, 32]);
        let wet = |c: usize| g.cell_coords(c)[1] < 16;
        let pool: Vec<_> = (0..g.num_cells())
            .filter(|&c| wet(c))
            .map(|c| g.center(g.cell_coords(c)))
            .collect();
        let open = vec![false; g.num_cells()];
        let prev = Markings::compute(&g, &pool, &open);
        let active = Active::around(&g, wet, 2);
        let check = |pos: &[Vector<2>], solid: &[bool]| {
            check_cell_counts(&g, pos, &prev, solid, 1, None, &active).map_err(|e| e.0)
        };
        assert_eq!(check(&pool, &open), Ok(()));
        let (surface, far) = (g.cell_index([5, 15]), [9, 30]);
        let mut moved = pool.clone();
        moved[surface] = g.center(far);
        assert_eq!(check(&moved, &open), Ok(()));
        let mut walls = open.clone();
        walls[g.cell_index(far)] = true;
        let e = check(&moved, &walls).unwrap_err();
        assert!(e.contains(&format!("solid cell {far:?} holds 1")), "{e}");
        moved[surface + 1] = g.center(far);
        let e = check(&moved, &open).unwrap_err();
        assert!(
            e.contains(&format!("cell {far:?} holds 2 particles")),
            "{e}"
        );
        // A broken inner cell on the set comes first in index order.
        moved[g.cell_index([3, 3])] = g.center(far);
        let e = check(&moved, &open).unwrap_err();
        assert!(e.contains(&format!("inner cell {:?} lost", [3, 3])), "{e}");
    }
}
