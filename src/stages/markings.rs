//! Cell markings (paper sec. 4 and 6): empty / fluid / solid, the surface and inner cells of
//! def. surface, bubbles (def. bubble), the depth of def. depth and the band levels of
//! sec. band_method (deep, band interface, band, surface).

use crate::grid::active::{hull, line_hulls, line_spans, par_runs, Active, EMPTY};
use crate::grid::{Cell, Grid, NearCells, Vector};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicI32, Ordering::Relaxed};

/// What occupies a cell (its number is how a checkpoint stores it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::NoUninit)]
#[repr(u8)]
pub enum CellKind {
    Empty = 0,
    Fluid = 1,
    Solid = 2,
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

/// How far the active cells reach beyond the fluid cells. After the projection, a step reads
/// the grid velocity within 2 cells of a fluid cell: a particle (always in a fluid cell) moves
/// at most `cfl <= 1` cell and its interpolation stencil reaches one cell further, and the
/// band's semi-Lagrangian trace back from a fluid cell's face reaches as far. Those faces take
/// their values from the extrapolation's 2 rings, which read known flags one face further
/// (5 cells); one cell more keeps them clear of the set's edge, where the passes stop and a
/// ring misses the neighbours beyond.
pub const ACTIVE_MARGIN: usize = 6;

/// The markings of every cell, derived from particle positions and solids.
#[derive(Clone, Debug, Default)]
pub struct Markings {
    pub kind: Vec<CellKind>,
    /// Particles per cell, `|gamma_c|`.
    pub count: Vec<u32>,
    /// Fluid cells with a non-fluid Moore neighbour inside the domain (def. surface).
    pub surface: Vec<bool>,
    /// The depth of each fluid cell ([`Markings::depth`]); the entries of other cells are not
    /// kept (a pass over the box would cost as much as the rest of the markings).
    pub(super) depth: Vec<i32>,
    /// One index range per line of cells along axis 0 that holds a fluid cell: the hull of its
    /// fluid cells. A pass that asks only about fluid cells visits these.
    fluid: Vec<Range<usize>>,
}

/// The solid cells markings are made around: every cell's flag, each line's hull of them (so
/// that the markings find them without a pass over the box) and the moving obstacles' cells.
#[derive(Clone, Copy)]
pub struct SolidCells<'a> {
    pub solid: &'a [bool],
    /// Per line of cells along axis 0, the hull `[lo, hi)` of its solid cells along the line
    /// (`lo >= hi` where there is none).
    pub lines: &'a [[u32; 2]],
    /// The moving obstacles' cells, when there are obstacles (without them nothing moves, and
    /// the markings need not look at every fluid cell's neighbours for one).
    pub moving: Option<&'a [bool]>,
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
        let lines = line_hulls(grid, |c| solid[c]);
        let solids = SolidCells {
            solid,
            lines: &lines,
            moving: None,
        };
        Self::compute_keeping(grid, positions, solids, None).0
    }

    /// As [`Self::compute`], with their active cells: those within [`ACTIVE_MARGIN`] of a
    /// fluid cell or a moving obstacle's cell. Cells of `keep` are fluid even without
    /// particles: with the band method (sec. band_method), the fluid cells below the surface
    /// of the previous markings, among them the deep, whose particles are imaginary. Fluid
    /// cells touching a moving obstacle's cell are surface, to give it room (sec. 7).
    ///
    /// No pass visits the box: kinds are found on each line's hull of its particles' cells
    /// (the whole line where `keep` holds a cell) and of its solid cells, empty elsewhere
    /// without a write; surface and depth on the active cells, which hold every fluid cell's
    /// neighbours.
    pub fn compute_keeping<const D: usize>(
        grid: &Grid<D>,
        positions: &[Vector<D>],
        solids: SolidCells,
        keep: Option<&NearCells>,
    ) -> (Self, Active<D>) {
        let mut count = vec![0u32; grid.num_cells()];
        for x in positions {
            count[grid.cell_index_of(x)] += 1;
        }
        let (kind, fluid, seeds) = kinds(grid, positions, &count, solids, keep);
        let active = Active::around_spans(grid, seeds, ACTIVE_MARGIN);
        let steps = moore_steps(grid);
        let surface = active.flags(grid, |c| {
            kind[c] == CellKind::Fluid
                && any_moore_neighbour(grid, &steps, c, |m| {
                    kind[m] == CellKind::Empty || solids.moving.is_some_and(|mv| mv[m])
                })
        });
        let depth = depth(grid, &kind, &surface, &active);
        let fluid = ranges(grid, &fluid);
        let markings = Self {
            kind,
            count,
            surface,
            depth,
            fluid,
        };
        (markings, active)
    }

    /// Markings of the given cells (from a checkpoint; `depth` must hold every fluid cell's).
    pub fn from_cells<const D: usize>(
        grid: &Grid<D>,
        kind: Vec<CellKind>,
        count: Vec<u32>,
        surface: Vec<bool>,
        depth: Vec<i32>,
    ) -> Self {
        let fluid = ranges(grid, &line_hulls(grid, |c| kind[c] == CellKind::Fluid));
        Self {
            kind,
            count,
            surface,
            depth,
            fluid,
        }
    }

    pub fn is_fluid(&self, c: usize) -> bool {
        self.kind[c] == CellKind::Fluid
    }

    /// The signed discrete distance of cell `c` from the surface (def. depth): 0 on the
    /// surface, -1, -2, ... inwards (`i32::MIN` in fluid no surface reaches, a closed, full
    /// container), [`DEPTH_NOT_FLUID`] in other cells.
    pub fn depth(&self, c: usize) -> i32 {
        match self.is_fluid(c) {
            true => self.depth[c],
            false => DEPTH_NOT_FLUID,
        }
    }

    /// The band level of cell `c` for band parameter `r`.
    pub fn level(&self, c: usize, r: u32) -> DepthLevel {
        DepthLevel::of(self.depth(c), r)
    }

    /// Whether `c` is in the band interface or the deep, `C_<=-R`: the region whose particle
    /// count the band constraint controls (eq. band_con).
    pub fn at_or_below_interface(&self, c: usize, r: u32) -> bool {
        self.is_fluid(c) && self.depth[c] <= -(r as i32)
    }

    /// Index ranges, ascending, that hold every fluid cell (one per line of cells along axis
    /// 0 that holds any, the hull of its fluid cells).
    pub fn fluid_ranges(&self) -> &[Range<usize>] {
        &self.fluid
    }

    /// Every cell's depth ([`Markings::depth`]) in order, reading only the fluid's lines.
    pub fn depths(&self) -> impl Iterator<Item = i32> + '_ {
        let not_fluid = |n| std::iter::repeat_n(DEPTH_NOT_FLUID, n);
        let mut at = 0;
        let fluid_lines = self.fluid.iter().flat_map(move |r| {
            let gap = not_fluid(r.start - at);
            at = r.end;
            gap.chain(r.clone().map(|c| self.depth(c)))
        });
        let end = self.fluid.last().map_or(0, |r| r.end);
        fluid_lines.chain(not_fluid(self.kind.len() - end))
    }

    pub fn fluid_cells(&self) -> usize {
        let fluid = self.fluid.par_iter().flat_map_iter(|r| r.clone());
        fluid.filter(|&c| self.is_fluid(c)).count()
    }
}

/// Each cell's kind, with per line of cells along axis 0 the hull of its fluid cells and that
/// of its fluid cells and moving obstacles' cells (the seeds of the active cells). A line is
/// visited only on the hull of its particles' cells (the whole line where `keep` holds a
/// cell) and on that of its solid cells: no other cell can be fluid or solid.
fn kinds<const D: usize>(
    grid: &Grid<D>,
    positions: &[Vector<D>],
    count: &[u32],
    solids: SolidCells,
    keep: Option<&NearCells>,
) -> (Vec<CellKind>, Vec<[u32; 2]>, Vec<[u32; 2]>) {
    let n0 = grid.dims[0];
    let cells = positions
        .par_iter()
        .map(|x| grid.cell_of(x).expect("counted, so inside"));
    let held = line_spans(&grid.dims, cells);
    let mut kind = empty_kinds(grid.num_cells());
    let (fluid, seeds) = (kind.par_chunks_mut(n0).enumerate())
        .with_min_len(crate::PAR_GRAIN.div_ceil(n0))
        .map(|(l, line)| {
            let (at, [lo, hi]) = (l * n0, solids.lines[l]);
            let mut moving = EMPTY;
            for x in lo..hi {
                let c = at + x as usize;
                if solids.solid[c] {
                    line[x as usize] = CellKind::Solid;
                    if solids.moving.is_some_and(|m| m[c]) {
                        moving = hull(moving, [x, x + 1]);
                    }
                }
            }
            let [lo, hi] = match keep {
                Some(k) if k.line_holds(l) => [0, n0 as u32],
                _ => held[l],
            };
            let mut fluid = EMPTY;
            for x in lo..hi {
                let c = at + x as usize;
                let filled = count[c] > 0 || keep.is_some_and(|k| k.holds(c));
                if filled && !solids.solid[c] {
                    line[x as usize] = CellKind::Fluid;
                    fluid = hull(fluid, [x, x + 1]);
                }
            }
            (fluid, hull(fluid, moving))
        })
        .unzip();
    (kind, fluid, seeds)
}

/// `n` empty cells, zeroed by the allocator: the pages no pass writes are never touched.
fn empty_kinds(n: usize) -> Vec<CellKind> {
    const _: () = assert!(CellKind::Empty as u8 == 0);
    let mut bytes = std::mem::ManuallyDrop::new(vec![0u8; n]);
    // SAFETY: `CellKind` is `repr(u8)`, so it has the size and alignment of `u8`, and a zero
    // byte is `CellKind::Empty` (asserted above); the allocation passes whole, with its
    // length and capacity, from the forgotten vector to the new one.
    unsafe { Vec::from_raw_parts(bytes.as_mut_ptr().cast(), bytes.len(), bytes.capacity()) }
}

/// The index ranges of one span per line of cells along axis 0 (empty spans left out).
fn ranges<const D: usize>(grid: &Grid<D>, spans: &[[u32; 2]]) -> Vec<Range<usize>> {
    let n0 = grid.dims[0];
    (spans.iter().enumerate())
        .filter(|(_, s)| s[0] < s[1])
        .map(|(l, s)| l * n0 + s[0] as usize..l * n0 + s[1] as usize)
        .collect()
}

/// Breadth-first depth over the von Neumann neighbourhood from the surface cells (def. depth),
/// over the cells of `active`, which holds every fluid cell. Fluid cells that no surface
/// reaches (a closed, completely full container) get `i32::MIN`; other cells keep 0.
///
/// Level by level, a large level's cells in parallel: each unvisited fluid neighbour is claimed
/// once, by an atomic exchange, for the next level. A cell's depth is its distance from the
/// surface, the same whichever cell claims it, so the result does not depend on the threads.
fn depth<const D: usize>(
    grid: &Grid<D>,
    kind: &[CellKind],
    surface: &[bool],
    active: &Active<D>,
) -> Vec<i32> {
    let mut depth = vec![0; kind.len()];
    par_runs(active.cells(), &mut depth).for_each(|(r, run)| {
        for (c, d) in r.zip(run) {
            if kind[c] == CellKind::Fluid && !surface[c] {
                *d = i32::MIN;
            }
        }
    });
    // Cells carry their coordinates: no division per cell in the search.
    let mut level: Vec<(usize, Cell<D>)> = (active.cells().par_iter())
        .flat_map_iter(|r| r.clone().filter(|&c| surface[c]))
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
        assert_eq!(m.depth(g.cell_index([3, 2])), -1);
        assert_eq!(m.depth(g.cell_index([2, 1])), -2);
        assert_eq!(m.depth(g.cell_index([0, 0])), -3);
        assert_eq!(m.depth(g.cell_index([6, 6])), DEPTH_NOT_FLUID);
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
        assert_eq!(m.depth(g.cell_index([0, 0, 0])), -3);
    }

    /// Markings found without a pass over the box are those of every cell, by brute force: the
    /// kinds (solid cells far from any fluid among them), surface, depths and active cells, and
    /// the fluid's line ranges hold every fluid cell (and give every cell's depth in order); in
    /// 2D and 3D, with a blob of particles, stray ones, solids everywhere, moving ones and cells
    /// kept without particles.
    #[test]
    fn markings_on_the_active_cells_are_those_of_every_cell_2d_and_3d() {
        use rand::{Rng, SeedableRng};
        fn check<const D: usize>(dims: [usize; D], seed: u64) {
            let g = Grid::new(dims);
            let n = g.num_cells();
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let near_corner = |c: usize| (0..D).all(|k| g.cell_coords(c)[k] < dims[k] / 3);
            let solid: Vec<bool> = (0..n).map(|_| rng.random::<f64>() < 0.02).collect();
            let by_blob = |c: usize| (0..D).all(|k| (10..16).contains(&g.cell_coords(c)[k]));
            let moving: Vec<bool> = (0..n).map(|c| solid[c] && by_blob(c)).collect();
            let keep: Vec<bool> = (0..n).map(|c| near_corner(c) && c % 5 < 3).collect();
            let mut pos: Vec<Vector<D>> = (0..n)
                .filter(|&c| (0..D).all(|k| (g.cell_coords(c)[k] as f64 - 8.0).abs() < 5.0))
                .map(|c| g.center(g.cell_coords(c)))
                .collect();
            let stray = |_| Vector::<D>::from_fn(|k, _| rng.random::<f64>() * dims[k] as f64);
            pos.extend((0..3).map(stray));
            let lines = line_hulls(&g, |c| solid[c]);
            let solids = SolidCells {
                solid: &solid,
                lines: &lines,
                moving: Some(&moving),
            };
            let near = NearCells::new(&g, keep.clone());
            let (m, active) = Markings::compute_keeping(&g, &pos, solids, Some(&near));
            // By brute force, every cell.
            let mut count = vec![0u32; n];
            pos.iter().for_each(|x| count[g.cell_index_of(x)] += 1);
            let kind: Vec<CellKind> = (0..n)
                .map(|c| match (solid[c], count[c] > 0 || keep[c]) {
                    (true, _) => CellKind::Solid,
                    (false, true) => CellKind::Fluid,
                    (false, false) => CellKind::Empty,
                })
                .collect();
            let surface: Vec<bool> = (0..n)
                .map(|c| {
                    let open = |m: Cell<D>| {
                        let m = g.cell_index(m);
                        kind[m] == CellKind::Empty || moving[m]
                    };
                    kind[c] == CellKind::Fluid && g.moore_neighbors(g.cell_coords(c)).any(open)
                })
                .collect();
            let fluid = |c: usize| kind[c] == CellKind::Fluid;
            let want = depth(&g, &kind, &surface, &Active::all(&g));
            let at = format!("{D}D");
            let differs = |c: &usize| m.kind[*c] != kind[*c] || m.surface[*c] != surface[*c];
            let wrong = (0..n).find(differs).map(|c| g.cell_coords(c));
            assert_eq!(
                wrong, None,
                "{at}: the first cell of another kind or surface"
            );
            for c in (0..n).filter(|&c| fluid(c)) {
                assert_eq!(m.depth(c), want[c], "{at}: depth of {:?}", g.cell_coords(c));
                assert!(
                    m.fluid_ranges().iter().any(|r| r.contains(&c)),
                    "{at}: {c} in a range"
                );
            }
            // Every cell's depth in order, as a checkpoint writes them.
            let every: Vec<i32> = (0..n).map(|c| m.depth(c)).collect();
            assert!(m.depths().eq(every), "{at}: depths in order");
            let around = Active::around(&g, |c| fluid(c) || moving[c], ACTIVE_MARGIN);
            assert_eq!(active, around, "{at}: active cells");
            assert!(active.num_cells() < n, "{at}: some cells inactive");
            assert!(
                (0..n).any(|c| solid[c] && !around.each_cell().any(|a| a == c)),
                "{at}: a solid cell off the active set"
            );
        }
        check([64, 48], 3);
        check([40, 30, 36], 4);
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
                for n in g.face_neighbors(c) {
                    if kind[n] == CellKind::Fluid && want[n] == i32::MIN {
                        want[n] = want[c] - 1;
                        queue.push_back(n);
                    }
                }
            }
            assert!(want.iter().any(|&d| d < -3), "deep enough to test");
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
                let got = pool
                    .expect("a thread pool")
                    .install(|| depth(&g, &kind, &surface, &Active::all(&g)));
                // Only the fluid's depths are kept.
                let got: Vec<i32> = (got.into_iter().zip(&kind))
                    .map(|(d, &k)| {
                        if k == CellKind::Fluid {
                            d
                        } else {
                            DEPTH_NOT_FLUID
                        }
                    })
                    .collect();
                assert_eq!(got, want, "{D}D, {threads} threads");
            }
        }
        check([300, 280], 1);
        check([60, 50, 70], 2);
    }
}
