//! Cell markings (paper sec. 4 and 6): empty / fluid / solid, the surface and inner cells of
//! def. surface, bubbles (def. bubble), the depth of def. depth and the band levels of
//! sec. band_method (deep, band interface, band, surface).

use crate::grid::{Cell, Grid, Vector};
use rayon::prelude::*;
use std::sync::atomic::{AtomicI32, Ordering::Relaxed};

/// What occupies a cell (its number is how a checkpoint stores it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum CellKind {
    Empty = 0,
    Fluid = 1,
    Solid = 2,
}

/// Class ids used in recordings (one byte per cell).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum MarkingClass {
    Empty = 0,
    Surface = 1,
    Inner = 2,
    /// An inner cell holding fewer than `mu` particles (def. bubble).
    Bubble = 3,
    Solid = 4,
}

impl MarkingClass {
    pub const ALL: [MarkingClass; 5] = [
        MarkingClass::Empty,
        MarkingClass::Surface,
        MarkingClass::Inner,
        MarkingClass::Bubble,
        MarkingClass::Solid,
    ];

    pub fn label(self) -> &'static str {
        match self {
            MarkingClass::Empty => "empty",
            MarkingClass::Surface => "surface",
            MarkingClass::Inner => "inner",
            MarkingClass::Bubble => "bubble",
            MarkingClass::Solid => "solid",
        }
    }
}

/// The band levels of sec. band_method for a band of thickness `R + 1` (fig. band), as class
/// ids for recordings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum DepthLevel {
    /// Empty or solid (depth > 0).
    NotFluid = 0,
    /// `beta = 0`.
    Surface = 1,
    /// `-R < beta < 0`.
    Band = 2,
    /// `beta = -R`, the band interface `C_-R`.
    Interface = 3,
    /// `beta < -R`, simulated on the grid only.
    Deep = 4,
}

impl DepthLevel {
    pub const ALL: [DepthLevel; 5] = [
        DepthLevel::NotFluid,
        DepthLevel::Surface,
        DepthLevel::Band,
        DepthLevel::Interface,
        DepthLevel::Deep,
    ];

    /// The level of a cell at depth `beta` for band parameter `r` (R >= 1).
    pub fn of(beta: i32, r: u32) -> Self {
        let r = r as i32;
        match beta {
            b if b > 0 => DepthLevel::NotFluid,
            0 => DepthLevel::Surface,
            b if b > -r => DepthLevel::Band,
            b if b == -r => DepthLevel::Interface,
            _ => DepthLevel::Deep,
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            DepthLevel::NotFluid => "not fluid",
            DepthLevel::Surface => "surface",
            DepthLevel::Band => "band",
            DepthLevel::Interface => "band interface",
            DepthLevel::Deep => "deep",
        }
    }
}

/// Depth assigned to non-fluid cells (def. depth: "an arbitrary positive number").
pub const DEPTH_NOT_FLUID: i32 = 1;

/// The markings of every cell, derived from particle positions and solids.
#[derive(Clone, Debug, Default)]
pub struct Markings {
    pub kind: Vec<CellKind>,
    /// Particles per cell, `|gamma_c|`.
    pub count: Vec<u32>,
    /// Fluid cells with a non-fluid Moore neighbour inside the domain (def. surface).
    pub surface: Vec<bool>,
    /// Signed discrete distance from the surface (def. depth): 0 on the surface, -1, -2, ...
    /// inwards, [`DEPTH_NOT_FLUID`] elsewhere.
    pub depth: Vec<i32>,
}

impl Markings {
    /// Marks cells from particle positions (`gamma_c` is the set of particles in `c`) and the
    /// solid mask. A cell is fluid when it holds a particle and is not solid. Static solids,
    /// like the domain walls, do not make their fluid neighbours surface (paper sec. 4.1).
    pub fn compute<const D: usize>(
        grid: &Grid<D>,
        positions: &[Vector<D>],
        solid: &[bool],
    ) -> Self {
        Self::compute_keeping(grid, positions, solid, None, None)
    }

    /// As [`Self::compute`], but cells flagged in `keep` are fluid even without particles: with
    /// the band method (sec. band_method), the fluid cells below the surface of the previous
    /// markings, among them the deep, whose particles are imaginary. Fluid cells touching a
    /// cell of `moving` (a moving obstacle) are surface, to give it room (sec. 7).
    pub fn compute_keeping<const D: usize>(
        grid: &Grid<D>,
        positions: &[Vector<D>],
        solid: &[bool],
        keep: Option<&[bool]>,
        moving: Option<&[bool]>,
    ) -> Self {
        let n = grid.num_cells();
        let mut count = vec![0u32; n];
        for x in positions {
            count[grid.cell_index_of(x)] += 1;
        }
        let kind: Vec<CellKind> = (0..n)
            .into_par_iter()
            .with_min_len(crate::PAR_GRAIN)
            .map(|c| {
                if solid[c] {
                    CellKind::Solid
                } else if count[c] > 0 || keep.is_some_and(|k| k[c]) {
                    CellKind::Fluid
                } else {
                    CellKind::Empty
                }
            })
            .collect();
        let steps = moore_steps(grid);
        let surface: Vec<bool> = (0..n)
            .into_par_iter()
            .with_min_len(crate::PAR_GRAIN)
            .map(|c| {
                kind[c] == CellKind::Fluid
                    && any_moore_neighbour(grid, &steps, c, |m| {
                        kind[m] == CellKind::Empty || moving.is_some_and(|mv| mv[m])
                    })
            })
            .collect();
        let depth = depth(grid, &kind, &surface);
        Self {
            kind,
            count,
            surface,
            depth,
        }
    }

    pub fn is_fluid(&self, c: usize) -> bool {
        self.kind[c] == CellKind::Fluid
    }

    pub fn class(&self, c: usize, mu: u32) -> MarkingClass {
        match self.kind[c] {
            CellKind::Empty => MarkingClass::Empty,
            CellKind::Solid => MarkingClass::Solid,
            CellKind::Fluid if self.surface[c] => MarkingClass::Surface,
            CellKind::Fluid if self.count[c] < mu => MarkingClass::Bubble,
            CellKind::Fluid => MarkingClass::Inner,
        }
    }

    /// The band level of cell `c` for band parameter `r`.
    pub fn level(&self, c: usize, r: u32) -> DepthLevel {
        DepthLevel::of(self.depth[c], r)
    }

    /// Whether `c` is in the band interface or the deep, `C_<=-R`: the region whose particle
    /// count the band constraint controls (eq. band_con).
    pub fn at_or_below_interface(&self, c: usize, r: u32) -> bool {
        self.kind[c] == CellKind::Fluid && self.depth[c] <= -(r as i32)
    }

    pub fn fluid_cells(&self) -> usize {
        self.kind.iter().filter(|k| **k == CellKind::Fluid).count()
    }
}

/// Breadth-first depth over the von Neumann neighbourhood from the surface cells (def. depth).
/// Fluid cells that no surface reaches (a closed, completely full container) get `i32::MIN`.
///
/// Level by level, a large level's cells in parallel: each unvisited fluid neighbour is claimed
/// once, by an atomic exchange, for the next level. A cell's depth is its distance from the
/// surface, the same whichever cell claims it, so the result does not depend on the threads.
fn depth<const D: usize>(grid: &Grid<D>, kind: &[CellKind], surface: &[bool]) -> Vec<i32> {
    let mut depth: Vec<i32> = (kind.par_iter().zip(surface).with_min_len(crate::PAR_GRAIN))
        .map(|(k, &s)| match (*k == CellKind::Fluid, s) {
            (true, true) => 0,
            (true, false) => i32::MIN,
            (false, _) => DEPTH_NOT_FLUID,
        })
        .collect();
    // Cells carry their coordinates: no division per cell.
    let mut level: Vec<(usize, Cell<D>)> = (0..kind.len())
        .into_par_iter()
        .with_min_len(crate::PAR_GRAIN)
        .filter(|&c| surface[c])
        .map(|c| (c, grid.cell_coords(c)))
        .collect();
    const _: () = assert!(std::mem::align_of::<AtomicI32>() == std::mem::align_of::<i32>());
    // SAFETY: `AtomicI32` has the size and bit validity of `i32` and (asserted above) its
    // alignment, and `depth` is borrowed mutably for as long as the view lives.
    let claim: &[AtomicI32] =
        unsafe { &*(depth.as_mut_slice() as *mut [i32] as *const [AtomicI32]) };
    let mut beta = 0;
    while !level.is_empty() {
        beta -= 1;
        let next = |&(c, cc): &(usize, Cell<D>)| {
            // The step written out rather than `Grid::neighbor`, which measured 40-50 ms
            // slower here at 300^3 (marked inline or not).
            (0..2 * D).filter_map(move |k| {
                let (a, up) = (k / 2, k % 2 == 1);
                let mut nc = cc;
                nc[a] = match up {
                    true => Some(cc[a] + 1).filter(|&v| v < grid.dims[a])?,
                    false => cc[a].checked_sub(1)?,
                };
                let stride = grid.cell_stride(a);
                let n = if up { c + stride } else { c - stride };
                let claimed = kind[n] == CellKind::Fluid
                    && (claim[n].compare_exchange(i32::MIN, beta, Relaxed, Relaxed)).is_ok();
                claimed.then_some((n, nc))
            })
        };
        level = match level.len() < crate::PAR_GRAIN / 8 {
            true => level.iter().flat_map(next).collect(),
            false => (level.par_iter().with_min_len(crate::PAR_GRAIN / 8))
                .flat_map_iter(next)
                .collect(),
        };
    }
    depth
}

/// The index steps from a cell to the others of its Moore neighbourhood.
fn moore_steps<const D: usize>(grid: &Grid<D>) -> Vec<isize> {
    let three = Grid::new([3; D]);
    let offsets = three.moore_neighbors([1; D]);
    let step = |m: Cell<D>| (0..D).map(move |k| (m[k] as isize - 1) * grid.cell_stride(k) as isize);
    offsets.map(|m| step(m).sum()).collect()
}

/// Whether a cell of the Moore neighbourhood of cell `c` satisfies `hit`: by the index steps
/// of [`moore_steps`] for a cell off the domain's walls, by coordinates next to them.
fn any_moore_neighbour<const D: usize>(
    grid: &Grid<D>,
    steps: &[isize],
    c: usize,
    hit: impl Fn(usize) -> bool,
) -> bool {
    let cc = grid.cell_coords(c);
    if (0..D).all(|k| 0 < cc[k] && cc[k] + 1 < grid.dims[k]) {
        steps.iter().any(|&s| hit(c.wrapping_add_signed(s)))
    } else {
        grid.moore_neighbors(cc).any(|m| hit(grid.cell_index(m)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_of_fluid_has_surface_ring_and_depth_2d() {
        // A 5x4 block of fluid in the corner of an 8x8 tank: the tank walls do not count as
        // surface, so only the top and right sides of the block are surface.
        let g = Grid::new([8, 8]);
        let mut pos = vec![];
        for i in 0..5 {
            for j in 0..4 {
                pos.push(Vector::<2>::new(i as f64 + 0.5, j as f64 + 0.5));
            }
        }
        let m = Markings::compute(&g, &pos, &[false; 64]);
        assert_eq!(m.fluid_cells(), 20);
        assert!(m.surface[g.cell_index([4, 0])]);
        assert!(m.surface[g.cell_index([0, 3])]);
        assert!(!m.surface[g.cell_index([0, 0])]);
        assert!(!m.surface[g.cell_index([3, 2])]);
        assert_eq!(m.depth[g.cell_index([3, 2])], -1);
        assert_eq!(m.depth[g.cell_index([2, 1])], -2);
        assert_eq!(m.depth[g.cell_index([0, 0])], -3);
        assert_eq!(m.depth[g.cell_index([6, 6])], DEPTH_NOT_FLUID);
    }

    #[test]
    fn diagonal_empty_neighbour_makes_surface_3d() {
        // Moore neighbourhood: a fluid cell whose only empty neighbour is diagonal is surface.
        let g = Grid::new([3, 3, 3]);
        let mut pos = vec![];
        for c in 0..27 {
            if c != g.cell_index([2, 2, 2]) {
                pos.push(g.center(g.cell_coords(c)));
            }
        }
        let m = Markings::compute(&g, &pos, &[false; 27]);
        assert!(m.surface[g.cell_index([1, 1, 1])]);
        assert!(!m.surface[g.cell_index([0, 0, 0])]);
        assert_eq!(m.depth[g.cell_index([0, 0, 0])], -3);
        assert_eq!(m.class(g.cell_index([0, 0, 0]), 2), MarkingClass::Bubble);
        assert_eq!(m.class(g.cell_index([0, 0, 0]), 1), MarkingClass::Inner);
    }

    /// The depth is each fluid cell's von Neumann distance from the nearest surface cell (by a
    /// plain breadth-first search here), `i32::MIN` where none reaches, on one thread or two,
    /// in 2D and 3D: random fluid with pockets of air and solid, large enough that levels run
    /// in parallel.
    #[test]
    fn depth_is_the_distance_from_the_surface_on_any_thread_count_2d_and_3d() {
        use rand::{Rng, SeedableRng};
        fn check<const D: usize>(dims: [usize; D], seed: u64) {
            let g = Grid::new(dims);
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let kind: Vec<CellKind> = (0..g.num_cells())
                .map(|_| match rng.random::<f64>() {
                    u if u < 0.002 => CellKind::Empty,
                    u if u < 0.01 => CellKind::Solid,
                    _ => CellKind::Fluid,
                })
                .collect();
            let surface: Vec<bool> = (0..g.num_cells())
                .map(|c| kind[c] == CellKind::Fluid && rng.random::<f64>() < 0.001)
                .collect();
            let mut want: Vec<i32> = (0..g.num_cells())
                .map(|c| match (kind[c], surface[c]) {
                    (CellKind::Fluid, true) => 0,
                    (CellKind::Fluid, false) => i32::MIN,
                    _ => DEPTH_NOT_FLUID,
                })
                .collect();
            let mut queue: std::collections::VecDeque<usize> =
                (0..g.num_cells()).filter(|&c| surface[c]).collect();
            while let Some(c) = queue.pop_front() {
                for a in 0..D {
                    for dir in [-1, 1] {
                        let Some(n) = g.neighbor(g.cell_coords(c), a, dir) else {
                            continue;
                        };
                        let n = g.cell_index(n);
                        if kind[n] == CellKind::Fluid && want[n] == i32::MIN {
                            want[n] = want[c] - 1;
                            queue.push_back(n);
                        }
                    }
                }
            }
            assert!(want.iter().any(|&d| d < -3), "deep enough to test");
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
                let got = pool
                    .expect("a thread pool")
                    .install(|| depth(&g, &kind, &surface));
                assert_eq!(got, want, "{D}D, {threads} threads");
            }
        }
        check([300, 280], 1);
        check([60, 50, 70], 2);
    }
}
