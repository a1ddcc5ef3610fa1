//! The greedy path search of sec. push_part (the band variant `paths`): alg. find (a
//! multi-source Dijkstra over cells from the band's sources to sinks with room), alg. edge (the
//! cheapest particle per edge, by `sigma_edge` of eq. edge) and alg. update (moving each path's
//! particles one cell on), as the paper writes them.

use super::paths::{BandPath, BandScene, PathDirection};
use crate::grid::active::{Active, CellNumbers};
use crate::grid::{Cell, Grid, Vector};
use crate::solvers::cheapest::Cheapest;
use crate::solvers::NONE;
use crate::stages::advect::CELL_MARGIN;
use rayon::prelude::*;
use std::collections::BinaryHeap;

/// What pushing particles along paths did.
#[derive(Clone, Debug, Default)]
pub struct PathOutcome<const D: usize> {
    pub applied: usize,
    pub found: usize,
    pub find_calls: usize,
    pub paths: Vec<BandPath<D>>,
}

const ROOT: u32 = u32::MAX - 1;

/// A node of alg. find's priority queue (lowest cost first: [`Cheapest`]), ties broken by
/// cell, root and edge, in that order. It carries the numbers ([`Search`]) of its cell and
/// root, which follow from them and so break no tie.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Node {
    cell: u32,
    root: u32,
    edge: u32,
    k: u32,
    root_k: u32,
}

/// A path found by alg. find: the edge into its sink and the sink.
struct FoundPath {
    edge: u32,
    sink: u32,
    cost: f64,
}

/// alg. find's per-cell arrays, over the only cells a search can reach: those that hold a
/// particle when it starts and their neighbours that may take one.
struct Search {
    numbers: CellNumbers,
    /// `gamma_c` of the current positions, per numbered cell `k`:
    /// `members[start[k]..start[k + 1]]`, in particle order.
    start: Vec<usize>,
    members: Vec<u32>,
    /// Per numbered cell: `J`, the edge (particle) to its parent (`NONE` unvisited, `ROOT` a
    /// source); `sigma`, its cost; `finished`, whether its path (as a root) is found.
    parent: Vec<u32>,
    sigma: Vec<f64>,
    finished: Vec<bool>,
}

impl Search {
    /// Numbers the cells within one cell of a particle's previous position `x_bar` or of its
    /// position `pos`, which hold every cell a search reaches: a particle's cell is the one of
    /// `pos` until alg. update moves it, and alg. edge moves a particle only out of its previous
    /// cell or into it, so a cell a path enters is its previous cell or a neighbour of it.
    fn new<const D: usize>(grid: &Grid<D>, x_bar: &[Vector<D>], pos: &[Vector<D>]) -> Self {
        let active = Active::around_points(grid, x_bar.par_iter().chain(pos), 1);
        let numbers = active.numbers(grid);
        let n = numbers.len();
        Self {
            numbers,
            start: vec![0; n + 1],
            members: vec![],
            parent: vec![NONE; n],
            sigma: vec![f64::INFINITY; n],
            finished: vec![false; n],
        }
    }

    /// The number of cell `c`, which a search reaches.
    fn number(&self, c: u32) -> usize {
        self.numbers
            .get(c as usize)
            .expect("a cell a search reaches")
    }

    /// Lists `gamma_c` of the particles' cells `cell_of` (a counting sort).
    fn sort(&mut self, cell_of: &[u32]) {
        let number: Vec<usize> = cell_of.iter().map(|&c| self.number(c)).collect();
        self.start.fill(0);
        for &k in &number {
            self.start[k + 1] += 1;
        }
        for k in 1..self.start.len() {
            self.start[k] += self.start[k - 1];
        }
        let mut fill = self.start.clone();
        self.members.resize(cell_of.len(), 0);
        for (j, &k) in number.iter().enumerate() {
            self.members[fill[k]] = j as u32;
            fill[k] += 1;
        }
    }

    /// `gamma_c` of numbered cell `k`.
    fn gamma(&self, k: usize) -> &[u32] {
        &self.members[self.start[k]..self.start[k + 1]]
    }

    /// Forgets the last search.
    fn clear(&mut self) {
        self.parent.fill(NONE);
        self.sigma.fill(f64::INFINITY);
        self.finished.fill(false);
    }
}

/// The state alg. find, alg. edge and alg. update work on: the band's scene, its depth `R`
/// and the paths' direction.
pub struct PathSearch<'a, const D: usize> {
    sc: &'a BandScene<'a, D>,
    r: u32,
    direction: PathDirection,
}

impl<'a, const D: usize> PathSearch<'a, D> {
    pub fn new(sc: &'a BandScene<'a, D>, r: u32, direction: PathDirection) -> Self {
        Self { sc, r, direction }
    }

    fn is_source(&self, c: usize) -> bool {
        self.direction.is_source(self.sc.previous, self.r, c)
    }

    /// Whether `c` can end a path. Cells an obstacle wants (`C_new_solid`, sec. 7) only with
    /// `allow_wanted`: a path into one blocks the obstacle, so they are the last resort.
    fn is_sink(&self, c: usize, allow_wanted: bool) -> bool {
        let wanted = self.sc.penalty.is_some_and(|p| p[c] > 0.0);
        (allow_wanted || !wanted)
            && !self.sc.solid[c]
            && self.direction.is_sink(self.sc.previous, self.r, c)
    }

    /// `sigma_edge(j, c)` of eq. edge: the cost of particle `j` at its best point of cell `c`
    /// minus the cost of where it is now.
    fn sigma_edge(&self, j: usize, c: Cell<D>, x: &Vector<D>) -> f64 {
        let xh = &self.sc.x_hat[j];
        (self.sc.grid.closest_in_cell(xh, c, CELL_MARGIN) - xh).norm_squared()
            - (x - xh).norm_squared()
    }

    /// Pushes `n_move` particles along paths (sec. push_part): alg. find, then alg. update
    /// for each path found until `n_move` are applied, and again while more are needed and
    /// alg. find still finds some. Paths into cells an obstacle wants are searched for only
    /// when no other path is left (reverting `b*` must stay possible, sec. push_part).
    pub fn push(&self, pos: &mut [Vector<D>], n_move: usize) -> PathOutcome<D> {
        let grid = self.sc.grid;
        let cells = |xs: &[Vector<D>]| -> Vec<u32> {
            xs.iter().map(|x| grid.cell_index_of(x) as u32).collect()
        };
        let mut cell_of = cells(pos);
        // Each particle's previous cell, which alg. edge reads for every move it considers.
        let home = cells(self.sc.x_bar);
        let mut search = Search::new(grid, self.sc.x_bar, pos);
        let mut out = PathOutcome::default();
        let mut allow_wanted = self.sc.penalty.is_none();
        while out.applied < n_move {
            search.sort(&cell_of);
            let want = n_move - out.applied;
            let found = self.find(&mut search, pos, &cell_of, &home, allow_wanted, want);
            out.find_calls += 1;
            out.found += found.len();
            if found.is_empty() {
                if allow_wanted {
                    break;
                }
                allow_wanted = true;
                continue;
            }
            for path in found {
                let path = self.update(&search, &path, pos, &mut cell_of);
                out.paths.push(path);
                out.applied += 1;
            }
        }
        out
    }

    /// alg. find: non-intersecting cheapest paths from every non-empty source, one per source,
    /// each ending at the first sink with room that its search reaches. Returns the paths in
    /// the order found and leaves in `search` `J`, each cell's edge (particle) to its parent.
    ///
    /// The search stops once `want` paths are found: alg. update applies the paths in the order
    /// found, only as many as are still needed, and a path's cells and edges are final when its
    /// sink is reached (a visited cell is never revisited), so the paths that would be found
    /// later could not change the ones applied.
    ///
    /// One deviation from the listing: a node extends its path from its own cost rather than
    /// from `sigma[c]`, which a cheaper node of an already finished root may have lowered.
    fn find(
        &self,
        search: &mut Search,
        pos: &[Vector<D>],
        cell_of: &[u32],
        home: &[u32],
        allow_wanted: bool,
        want: usize,
    ) -> Vec<FoundPath> {
        let grid = self.sc.grid;
        search.clear();
        let mut queue = BinaryHeap::new();
        for (k, c) in search.numbers.cells().enumerate() {
            if self.is_source(c) && !search.gamma(k).is_empty() {
                search.parent[k] = ROOT;
                search.sigma[k] = 0.0;
                let node = Node {
                    cell: c as u32,
                    root: c as u32,
                    edge: ROOT,
                    k: k as u32,
                    root_k: k as u32,
                };
                queue.push(Cheapest {
                    cost: 0.0,
                    tie: node,
                });
            }
        }
        let mut paths = vec![];
        while let Some(Cheapest { cost, tie: a }) = queue.pop() {
            let (c, k) = (a.cell as usize, a.k as usize);
            if search.parent[k] != NONE && search.parent[k] != ROOT {
                continue; // visited
            }
            if search.finished[a.root_k as usize] {
                continue;
            }
            search.parent[k] = a.edge;
            search.sigma[k] = cost;
            let gamma = search.gamma(k);
            if self.is_sink(c, allow_wanted) && (gamma.len() as u32) < self.sc.mu {
                search.finished[a.root_k as usize] = true;
                paths.push(FoundPath {
                    edge: a.edge,
                    sink: a.cell,
                    cost,
                });
                if paths.len() == want {
                    break;
                }
                continue;
            }
            let cc = grid.cell_coords(c);
            for axis in 0..D {
                for dir in [-1, 1] {
                    let Some(nb) = grid.neighbor(cc, axis, dir) else {
                        continue;
                    };
                    let c2 = grid.cell_index(nb);
                    // Off the numbered cells no particle of `c` may move to `c2` (see
                    // [`Search::new`]).
                    let Some(k2) = search.numbers.at(nb) else {
                        continue;
                    };
                    if search.parent[k2] != NONE || self.sc.solid[c2] {
                        continue; // visited, a source or solid
                    }
                    // alg. edge: the cheapest particle of c that may move to c2, i.e. one whose
                    // previous cell is c or c2.
                    let mut best: Option<(f64, u32)> = None;
                    for &j in search.gamma(k) {
                        let home = home[j as usize] as usize;
                        if home != c && home != c2 {
                            continue;
                        }
                        let e = self.sigma_edge(j as usize, nb, &pos[j as usize]);
                        if best.is_none_or(|(b, _)| e < b) {
                            best = Some((e, j));
                        }
                    }
                    let Some((e, j)) = best else {
                        continue;
                    };
                    debug_assert_eq!(cell_of[j as usize] as usize, c);
                    let t = cost + e;
                    if t >= search.sigma[k2] {
                        continue;
                    }
                    search.sigma[k2] = t;
                    let node = Node {
                        cell: c2 as u32,
                        root: a.root,
                        edge: j,
                        k: k2 as u32,
                        root_k: a.root_k,
                    };
                    queue.push(Cheapest { cost: t, tie: node });
                }
            }
        }
        paths
    }

    /// alg. update: walks the path back from its sink, moving each edge's particle into the
    /// cell after it, and returns the path's cell centres from source to sink.
    fn update(
        &self,
        search: &Search,
        path: &FoundPath,
        pos: &mut [Vector<D>],
        cell_of: &mut [u32],
    ) -> BandPath<D> {
        let grid = self.sc.grid;
        let (mut j, mut c) = (path.edge, path.sink as usize);
        let mut cells = vec![grid.center(grid.cell_coords(c))];
        while j != ROOT {
            let from = cell_of[j as usize] as usize;
            let ju = j as usize;
            pos[ju] = grid.closest_in_cell(&self.sc.x_hat[ju], grid.cell_coords(c), CELL_MARGIN);
            cell_of[ju] = c as u32;
            cells.push(grid.center(grid.cell_coords(from)));
            j = search.parent[search.number(from as u32)];
            c = from;
        }
        cells.reverse();
        BandPath {
            cells,
            cost: path.cost,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::stages::markings::{CellKind, Markings, DEPTH_NOT_FLUID};

    /// A hand-made 2D scene of `mu = 1` from rows of characters, top row first: `#` solid, `.`
    /// empty, `i`/`I`/`J` a band interface cell (depth -R) with 0/1/2 particles, `b` a band
    /// cell above it (depth -1, one particle), `s`/`S` a surface cell (depth 0) with 1/2
    /// particles. Every particle sits at its cell's centre, where it also was (`x_bar`) and
    /// wanted to go (`x_hat`).
    struct Scene {
        grid: Grid<2>,
        previous: Markings,
        solid: Vec<bool>,
        x: Vec<Vector<2>>,
        penalty: Option<Vec<f64>>,
    }

    const R: u32 = 2;

    impl Scene {
        fn new(rows: &[&str]) -> Self {
            let (w, h) = (rows[0].len(), rows.len());
            let grid = Grid::<2>::new([w, h]);
            let n = grid.num_cells();
            let (mut kinds, mut counts) = (vec![CellKind::Empty; n], vec![0; n]);
            let (mut surface, mut depths) = (vec![false; n], vec![DEPTH_NOT_FLUID; n]);
            let (mut solid, mut x) = (vec![false; n], vec![]);
            for (row, line) in rows.iter().enumerate() {
                for (i, ch) in line.chars().enumerate() {
                    let cell = [i, h - 1 - row];
                    let c = grid.cell_index(cell);
                    let (kind, depth, count) = match ch {
                        '#' => (CellKind::Solid, DEPTH_NOT_FLUID, 0),
                        '.' => (CellKind::Empty, DEPTH_NOT_FLUID, 0),
                        'i' | 'I' | 'J' => (CellKind::Fluid, -(R as i32), "iIJ".find(ch).unwrap()),
                        'b' => (CellKind::Fluid, -1, 1),
                        's' | 'S' => (CellKind::Fluid, 0, 1 + "sS".find(ch).unwrap()),
                        _ => panic!("unknown cell '{ch}'"),
                    };
                    (kinds[c], depths[c], counts[c]) = (kind, depth, count as u32);
                    (solid[c], surface[c]) = (ch == '#', depth == 0);
                    x.extend(std::iter::repeat_n(grid.center(cell), count));
                }
            }
            Self {
                previous: Markings::from_cells(&grid, kinds, counts, surface, depths),
                grid,
                solid,
                x,
                penalty: None,
            }
        }

        /// Pushes `n_move` particles in `direction`: the outcome and the final positions.
        fn push(
            &self,
            direction: PathDirection,
            n_move: usize,
        ) -> (PathOutcome<2>, Vec<Vector<2>>) {
            let sc = BandScene {
                grid: &self.grid,
                x_bar: &self.x,
                x_hat: &self.x,
                previous: &self.previous,
                solid: &self.solid,
                penalty: self.penalty.as_deref(),
                mu: 1,
            };
            let mut pos = self.x.clone();
            let out = PathSearch::new(&sc, R, direction).push(&mut pos, n_move);
            (out, pos)
        }

        fn cell(&self, x: &Vector<2>) -> [usize; 2] {
            self.grid.cell_coords(self.grid.cell_index_of(x))
        }

        /// A path's first and last cells.
        fn ends(&self, p: &BandPath<2>) -> ([usize; 2], [usize; 2]) {
            (self.cell(&p.cells[0]), self.cell(p.cells.last().unwrap()))
        }

        /// Every particle moved at most one cell from where it was (alg. edge's rule).
        fn check_moves(&self, pos: &[Vector<2>]) {
            for (a, b) in self.x.iter().zip(pos) {
                let (a, b) = (self.cell(a), self.cell(b));
                assert!(
                    a[0].abs_diff(b[0]) + a[1].abs_diff(b[1]) <= 1,
                    "{a:?} -> {b:?}"
                );
            }
        }
    }

    /// The paper's fig. v_paths: two cheap paths start in two neighbouring cells in the middle
    /// of the band interface and leave along the two narrow passages between an obstacle and
    /// the tank's walls, a V. They share no cell, and between them they block every other way
    /// out: a third particle needs another call of alg. find, which here finds none (each
    /// passage's particles have moved on and may not move twice).
    #[test]
    fn a_v_of_two_paths_blocks_the_rest() {
        let s = Scene::new(&[
            "......", //
            "b####b", //
            "b####b", //
            "bbbbbb", //
            "iiJJii", //
        ]);
        let (out, pos) = s.push(PathDirection::Out, 3);
        assert_eq!((out.find_calls, out.found, out.applied), (2, 2, 2));
        let mut ends: Vec<_> = out.paths.iter().map(|p| s.ends(p)).collect();
        ends.sort();
        assert_eq!(ends, [([2, 0], [0, 4]), ([3, 0], [5, 4])]);
        let cells =
            |p: &BandPath<2>| -> Vec<[usize; 2]> { p.cells.iter().map(|x| s.cell(x)).collect() };
        let (a, b) = (cells(&out.paths[0]), cells(&out.paths[1]));
        assert!(
            a.iter().all(|c| !b.contains(c)),
            "{a:?} and {b:?} share a cell"
        );
        assert_eq!(a.len(), 7, "{a:?}: the shortest way out");
        s.check_moves(&pos);
        // Each path moved one particle into its sink and one out of its source.
        let count = |cell: [usize; 2]| pos.iter().filter(|x| s.cell(x) == cell).count();
        assert_eq!(
            [count([0, 4]), count([5, 4]), count([2, 0]), count([3, 0])],
            [1, 1, 1, 1]
        );
    }

    /// Paths into the band interface end in a cell with room, and one that an obstacle wants
    /// (`C_new_solid`, a penalty there) is the last resort: taken only by a second call of
    /// alg. find when no other sink is left.
    #[test]
    fn paths_in_avoid_cells_an_obstacle_wants_until_nothing_else_is_left() {
        let mut s = Scene::new(&[
            "...", //
            ".s.", //
            "iIi", //
        ]);
        let (left, right) = (s.grid.cell_index([0, 0]), s.grid.cell_index([2, 0]));
        let (out, pos) = s.push(PathDirection::In, 1);
        assert_eq!((out.find_calls, out.applied), (1, 1));
        let first_choice = s.ends(&out.paths[0]).1;
        assert!([[0, 0], [2, 0]].contains(&first_choice), "{first_choice:?}");
        s.check_moves(&pos);

        let wanted = if first_choice == [0, 0] { left } else { right };
        let mut penalty = vec![0.0; s.grid.num_cells()];
        penalty[wanted] = 1000.0;
        s.penalty = Some(penalty.clone());
        let (out, _) = s.push(PathDirection::In, 1);
        assert_eq!((out.find_calls, out.applied), (1, 1));
        assert_ne!(s.grid.cell_index(s.ends(&out.paths[0]).1), wanted);

        penalty[left] = 1000.0;
        penalty[right] = 1000.0;
        s.penalty = Some(penalty);
        let (out, _) = s.push(PathDirection::In, 1);
        assert_eq!((out.find_calls, out.found, out.applied), (2, 1, 1));
        assert_eq!(s.ends(&out.paths[0]), ([1, 1], first_choice));
    }
}
