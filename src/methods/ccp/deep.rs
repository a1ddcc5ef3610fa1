//! The deep's bookkeeping of the band method (paper sec. band_method, alg. band line 9), part
//! of method ccp: particles in the deep (`beta < -R`) are imaginary and counted in `n_deep`.
//!
//! After each correction and the new markings, particles that reached the deep are removed
//! and counted, and when the deep holds more than it has room for,
//! `n_excess = n_deep - mu |C_<-R|` particles are added to the band interface: its cells are
//! visited in a seeded random order and filled up to `mu`, each new particle at a random point
//! of its cell with the grid velocity there.
//!
//! One addition to the paper: the depth of a cell can rise by two levels in one step (the
//! surface is found over the Moore neighbourhood, depth over the von Neumann one), so a deep
//! cell can land in the band above the interface without particles, and would then turn empty
//! and open a hole in the fluid. Such cells, former interface or deep cells that the new
//! markings put above the interface, are filled from the excess along with the interface.

use crate::grid::active::Active;
use crate::grid::{Grid, MacField, Vector};
use crate::particles::Particles;
use crate::stages::advect::CELL_MARGIN;
use crate::stages::band::Band;
use crate::stages::markings::{DepthLevel, Markings};
use rand::seq::SliceRandom;
use rand::Rng;

/// What one exchange with the deep did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeepExchange {
    /// Particles that reached the deep and were removed.
    pub removed: usize,
    /// Particles added to the band interface from the deep's excess.
    pub added: usize,
    /// Excess particles for which the band interface had no room (kept in `n_deep`). The paper
    /// says this never happens.
    pub unplaced: usize,
    /// Cells of the deep, and cells that excess particles may fill: the band interface and
    /// former interface or deep cells now above it.
    pub deep_cells: usize,
    pub interface_cells: usize,
}

impl DeepExchange {
    /// Both exchanges of one step together (after emission and after the correction); the
    /// cell counts are the later one's.
    pub fn merged(self, earlier: Option<DeepExchange>) -> Self {
        let e = earlier.unwrap_or_default();
        Self {
            removed: self.removed + e.removed,
            added: self.added + e.added,
            unplaced: self.unplaced + e.unplaced,
            ..self
        }
    }
}

/// Removes particles in deep cells (into `n_deep`) and fills the band interface from the
/// deep's excess (alg. band, line 9), and with it the cells that were interface or deep in the
/// `previous` markings and are now above the interface. Keeps `markings.count` up to date;
/// kinds and depths do not change. `active` holds every fluid cell of `markings`.
#[allow(clippy::too_many_arguments)]
pub fn exchange_with_deep<const D: usize>(
    grid: &Grid<D>,
    active: &Active<D>,
    particles: &mut Particles<D>,
    markings: &mut Markings,
    previous: Option<&Markings>,
    band: Band,
    mu: u32,
    n_deep: &mut usize,
    velocity: &MacField<D>,
    rng: &mut impl Rng,
) -> DeepExchange {
    let level = |m: &Markings, c: usize| band.level(m, c);
    let mut out = DeepExchange::default();
    let before = particles.len();
    let keep: Vec<bool> = particles
        .pos
        .iter()
        .map(|x| level(markings, grid.cell_index_of(x)) != DepthLevel::Deep)
        .collect();
    particles.retain_flagged(&keep);
    out.removed = before - particles.len();
    *n_deep += out.removed;
    // Former interface or deep cells now above the interface first, then the interface.
    let (mut risen, mut interface) = (vec![], vec![]);
    for c in active.each_cell() {
        match level(markings, c) {
            DepthLevel::Deep => {
                out.deep_cells += 1;
                markings.count[c] = 0;
            }
            DepthLevel::Interface => interface.push(c),
            DepthLevel::Band | DepthLevel::Surface
                if previous.is_some_and(|p| p.at_or_below_interface(c, band.r)) =>
            {
                risen.push(c)
            }
            _ => {}
        }
    }
    out.interface_cells = risen.len() + interface.len();
    let capacity = mu as usize * out.deep_cells;
    let mut excess = n_deep.saturating_sub(capacity);
    if excess > 0 {
        risen.shuffle(rng);
        interface.shuffle(rng);
        for &c in risen.iter().chain(&interface) {
            if excess == 0 {
                break;
            }
            let cell = grid.cell_coords(c);
            while markings.count[c] < mu && excess > 0 {
                let x = Vector::<D>::from_fn(|k, _| {
                    cell[k] as f64 + rng.random_range(CELL_MARGIN..1.0 - CELL_MARGIN)
                });
                particles.push(x, velocity.interpolate(grid, &x));
                markings.count[c] += 1;
                excess -= 1;
                out.added += 1;
            }
        }
    }
    *n_deep -= out.added;
    out.unplaced = excess;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    /// A full 10x10 block of fluid at mu = 1 in a 10x12 tank: the top row is surface, and with
    /// R = 2 rows 6..=7 are band, row 7 the interface, rows 0..=6 deep.
    fn block_2d() -> (Grid<2>, Particles<2>) {
        let g = Grid::new([10, 12]);
        let mut p = Particles::default();
        for i in 0..10 {
            for j in 0..10 {
                p.push(g.center([i, j]), Vector::<2>::zeros());
            }
        }
        (g, p)
    }

    #[test]
    fn deep_particles_are_removed_and_counted_2d() {
        let (g, mut p) = block_2d();
        let solid = vec![false; g.num_cells()];
        let mut m = Markings::compute(&g, &p.pos, &solid);
        let mut n_deep = 0;
        let mut rng = StdRng::seed_from_u64(1);
        let u = MacField::zeros(&g);
        let x = exchange_with_deep(
            &g,
            &Active::all(&g),
            &mut p,
            &mut m,
            None,
            Band { r: 2 },
            1,
            &mut n_deep,
            &u,
            &mut rng,
        );
        // Surface row 9, band row 8, interface row 7: 30 particles stay, 70 go deep.
        assert_eq!((x.removed, x.added, x.unplaced), (70, 0, 0));
        assert_eq!((x.deep_cells, x.interface_cells), (70, 10));
        assert_eq!((p.len(), n_deep), (30, 70));
        assert!(m
            .count
            .iter()
            .enumerate()
            .all(|(c, &n)| n as usize == p.pos.iter().filter(|x| g.cell_index_of(x) == c).count()));
    }

    #[test]
    fn excess_of_the_deep_fills_the_interface_up_to_mu_3d() {
        // A 4x4x6 block at mu = 1, R = 1: top layer surface, layer 4 interface, 0..=3 deep.
        let g = Grid::new([4, 4, 8]);
        let mut p = Particles::default();
        for c in 0..g.num_cells() {
            let cc = g.cell_coords(c);
            if cc[2] < 6 {
                p.push(g.center(cc), Vector::<3>::zeros());
            }
        }
        // The block fills the tank's 4x4 footprint and walls make no surface: only its top
        // layer (z = 5) is surface.
        let solid = vec![false; g.num_cells()];
        let mut m = Markings::compute(&g, &p.pos, &solid);
        assert_eq!(m.level(g.cell_index([1, 1, 5]), 1), DepthLevel::Surface);
        assert_eq!(m.level(g.cell_index([1, 1, 4]), 1), DepthLevel::Interface);
        let mut rng = StdRng::seed_from_u64(7);
        let mut u = MacField::zeros(&g);
        u.comp[2].iter_mut().for_each(|v| *v = -3.0);
        let mut n_deep = 0;
        // The exchange at mu = 1, R = 1, with nothing risen from below the interface.
        let mut exchange = |p: &mut Particles<3>, m: &mut Markings, n_deep: &mut usize| {
            let all = Active::all(&g);
            exchange_with_deep(&g, &all, p, m, None, Band { r: 1 }, 1, n_deep, &u, &mut rng)
        };
        exchange(&mut p, &mut m, &mut n_deep);
        assert_eq!((p.len(), n_deep), (32, 64));
        // Empty 5 interface cells and say the deep holds 5 more than its 64 cells: the 5 go
        // back into the interface, one per empty cell, with the grid velocity.
        let mut removed = 0;
        let mut keep = vec![];
        for x in &p.pos {
            let cc = g.cell_coords(g.cell_index_of(x));
            let drop = cc[2] == 4 && cc[0] == 0 && removed < 4 || cc == [3, 3, 4];
            if drop {
                removed += 1;
            }
            keep.push(!drop);
        }
        assert_eq!(removed, 5);
        p.retain_flagged(&keep);
        for c in [[0, 0, 4], [0, 1, 4], [0, 2, 4], [0, 3, 4], [3, 3, 4]] {
            m.count[g.cell_index(c)] = 0;
        }
        n_deep += 5;
        let x = exchange(&mut p, &mut m, &mut n_deep);
        assert_eq!((x.removed, x.added, x.unplaced), (0, 5, 0));
        assert_eq!((p.len(), n_deep), (32, 64));
        assert!(m.count.iter().all(|&n| n <= 1));
        assert!(p
            .vel
            .iter()
            .rev()
            .take(5)
            .all(|v| (v[2] + 3.0).abs() < 1e-12));
        // With no room left, more excess stays in the deep and is reported.
        n_deep += 2;
        let x = exchange(&mut p, &mut m, &mut n_deep);
        assert_eq!((x.added, x.unplaced), (0, 2));
        assert_eq!(n_deep, 66);
    }
}
