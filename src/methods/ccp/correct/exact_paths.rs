//! `exact-paths` (beyond the paper): the second step of the band variant `paths` (sec.
//! push_part) solved to optimality.
//!
//! After the first solve `b*` of eq. problem3, `n_move` particles must cross into `C_<=-R` (or
//! out of it). Alg. find and alg. update push them greedily along non-crossing cell paths (a
//! Dijkstra search without potentials over edge costs that can be negative, as the paper
//! says). The problem those paths solve is: among the final assignments in which
//!
//! - the sources ([`PathDirection::is_source`]) lose `n_move` particles in all,
//! - the sinks ([`PathDirection::is_sink`]) gain particles, each up to `mu`,
//! - every other cell keeps its count of `b*`,
//! - every particle ends in one of its eq. problem3 candidates (its previous cell or a
//!   neighbour of it, never a solid),
//!
//! find one of least eq. problem3 objective (`sigma_solid_obj` included). Every result of the
//! paths is one of these assignments, so this optimum is never above theirs.
//!
//! The total over the sources is not a per-cell bound, so it is written with ghost items: a
//! source holding `n_c` particles gets `k_c = min(n_c, n_move)` ghosts, each free (cost 0) to
//! sit in its source or in one extra ghost bin `G` that holds exactly `sum k_c - n_move`. A
//! source holds exactly `n_c` items, so the `n_move` ghosts in the sources stand in for
//! `n_move` particles that left them. The result is a bounded assignment problem: exported as
//! MPS, solvable by any LP solver, and by the exact min-cost-flow solver. That solver starts
//! from `b*` with every ghost in `G` and the first solve's prices: `G` is then `n_move` over
//! full, and each unit leaves it along a shortest path `G -> source -> ... -> sink` with
//! potentials: exactly `n_move` searches, and an optimal result (successive shortest paths),
//! where alg. find's greedy paths are not. The price is one search per particle moved, each
//! settling every cell nearer than the nearest sink with room (on dam-3d at 100^3 about 10,000
//! cells per search, against one alg. find per batch of paths).
//!
//! Without the first solve's prices (the simplex solved `b*`, or the solver failed) the
//! problem is solved from scratch.

use super::paths::{BandPath, PathDirection};
use super::problem::CorrectionProblem;
use super::SolveError;
use crate::grid::Grid;
use crate::solvers::min_cost_flow::{self, BoundedAssignment, FlowStats, Solution};
use crate::stages::markings::Markings;
use std::collections::BTreeMap;

/// The second step as a bounded assignment: the particles (items `0..particles`) with their
/// eq. problem3 candidates and costs, then the ghosts.
#[derive(Clone, Debug)]
pub struct SecondStep {
    pub problem: BoundedAssignment,
    particles: usize,
    /// The bins of the sources, those that got ghosts.
    sources: Vec<u32>,
}

/// Where the cells of eq. problem3's bins stand in the second step.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Source,
    Sink,
    Fixed,
}

impl SecondStep {
    /// The second step after `b_star` (a choice of `p`), moving `n_move` particles in
    /// `direction`, with the previous markings and band parameter `r` deciding sources and
    /// sinks.
    pub fn build<const D: usize>(
        p: &CorrectionProblem<D>,
        b_star: &[u32],
        previous: &Markings,
        (r, mu): (u32, u32),
        direction: PathDirection,
        n_move: usize,
    ) -> Result<Self, SolveError> {
        let a = &p.assignment;
        let mut load = vec![0u32; a.bins()];
        for &k in b_star {
            load[a.cand_bin[k as usize] as usize] += 1;
        }
        let role = |b: usize| {
            let c = p.bin_cell[b];
            if load[b] > 0 && direction.is_source(previous, r, c) {
                Role::Source
            } else if direction.is_sink(previous, r, c) {
                Role::Sink
            } else {
                Role::Fixed
            }
        };
        let mut problem = BoundedAssignment {
            item_start: a.item_start.clone(),
            cand_bin: a.cand_bin.clone(),
            cand_cost: a.cand_cost.clone(),
            lower: load.clone(),
            upper: load.clone(),
        };
        // The bin `G` of the unused ghosts: the last.
        let ghost_bin = a.bins() as u32;
        let mut sources = vec![];
        for (b, &n) in load.iter().enumerate() {
            match role(b) {
                Role::Source => {
                    sources.push(b as u32);
                    for _ in 0..n.min(n_move as u32) {
                        problem.cand_bin.extend([ghost_bin, b as u32]);
                        problem.cand_cost.extend([0.0, 0.0]);
                        problem.item_start.push(problem.cand_bin.len());
                    }
                }
                Role::Sink => problem.upper[b] = n.max(mu),
                Role::Fixed => {}
            }
        }
        let ghosts = problem.items() - a.items();
        if ghosts < n_move {
            return Err(SolveError::TooFewAtSources {
                held: ghosts,
                needed: n_move,
            });
        }
        let unused = (ghosts - n_move) as u32;
        problem.lower.push(unused);
        problem.upper.push(unused);
        Ok(Self {
            problem,
            particles: a.items(),
            sources,
        })
    }

    /// Solves the second step exactly. With `prices` of the first solve (a [`Solution`]'s for
    /// `b_star`) it starts from `b_star`, otherwise from scratch. Returns the particles' choice
    /// (candidates of eq. problem3) and the solver's counts.
    pub fn solve(
        &self,
        b_star: &[u32],
        prices: Option<&[f64]>,
    ) -> Result<(Vec<u32>, FlowStats), SolveError> {
        let q = &self.problem;
        let solved = match prices {
            Some(prices) => {
                let ghosts = self.particles..q.items();
                let mut choice = b_star.to_vec();
                choice.extend(ghosts.map(|i| q.item_start[i] as u32));
                // Every ghost move G -> source must cost >= 0 reduced: G's price is the least.
                let least = self.sources.iter().map(|&b| prices[b as usize]);
                let mut prices = prices.to_vec();
                prices.push(least.fold(f64::INFINITY, f64::min));
                let start = Solution {
                    choice,
                    prices,
                    sink_price: 0.0,
                    stats: FlowStats::default(),
                };
                min_cost_flow::solve_from(q, start)
            }
            None => min_cost_flow::solve_priced(q),
        }?;
        let mut choice = solved.choice;
        choice.truncate(self.particles);
        Ok((choice, solved.stats))
    }
}

/// The particles' cell changes from `b_star` to `choice` (choices of `p`) as paths through cell
/// centres, for the recording: a flow decomposition, first into chains from a cell that lost
/// particles to one that gained them (`n_move` of them after the second step: sources only
/// lose, sinks only gain, every other cell keeps its count), then into cycles (first cell =
/// last), if any. A path's cost is the change of eq. problem3's cost over its moves. Moves
/// are taken in particle order and cells in index order: the same paths on any thread count.
pub fn paths_of<const D: usize>(
    grid: &Grid<D>,
    p: &CorrectionProblem<D>,
    b_star: &[u32],
    choice: &[u32],
) -> Vec<BandPath<D>> {
    let q = &p.assignment;
    let cell = |k: u32| p.bin_cell[q.cand_bin[k as usize] as usize];
    // Per cell: its moves out (the last popped first) and its moves out minus moves in.
    let mut out: BTreeMap<usize, Vec<(usize, f64)>> = BTreeMap::new();
    let mut net: BTreeMap<usize, i64> = BTreeMap::new();
    for (&a, &b) in b_star.iter().zip(choice).rev() {
        let (from, to) = (cell(a), cell(b));
        if from != to {
            let cost = q.cand_cost[b as usize] - q.cand_cost[a as usize];
            out.entry(from).or_default().push((to, cost));
            *net.entry(from).or_default() += 1;
            *net.entry(to).or_default() -= 1;
        }
    }
    let path = |(cells, cost): (Vec<usize>, f64)| BandPath {
        cells: cells
            .iter()
            .map(|&c| grid.center(grid.cell_coords(c)))
            .collect(),
        cost,
    };
    let mut paths = vec![];
    let sources: Vec<(usize, i64)> = net.iter().map(|(&c, &n)| (c, n)).collect();
    for (source, surplus) in sources {
        for _ in 0..surplus.max(0) {
            let chain = walk(&mut out, source, |c| net[&c] < 0);
            *net.get_mut(chain.0.last().expect("a walk has a start"))
                .unwrap() += 1;
            paths.push(path(chain));
        }
    }
    let starts: Vec<usize> = out.keys().copied().collect();
    for start in starts {
        while out[&start].last().is_some() {
            paths.push(path(walk(&mut out, start, |c| c == start)));
        }
    }
    paths
}

/// Follows unused moves from `start` until `stop` holds at a cell reached (or no move is left):
/// the cells visited and the moves' summed cost.
fn walk(
    out: &mut BTreeMap<usize, Vec<(usize, f64)>>,
    start: usize,
    stop: impl Fn(usize) -> bool,
) -> (Vec<usize>, f64) {
    let (mut cells, mut cost, mut at) = (vec![start], 0.0, start);
    while let Some((to, c)) = out.get_mut(&at).and_then(Vec::pop) {
        (at, cost) = (to, cost + c);
        cells.push(to);
        if stop(to) {
            break;
        }
    }
    (cells, cost)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of three moves along the bottom row (cells x = 0 -> 1 -> 2 -> 3) and two swaps
    /// of particles (cycles), one of them out of the chain's last cell, on a grid 4 x 2 (x 1):
    /// the chain ends where the particle was gained (not on through the swap), then the
    /// cycles in cell order, each with its cost.
    fn chain_and_cycle<const D: usize>() {
        let g = Grid::<D>::new(std::array::from_fn(|k| [4, 2, 1][k]));
        let at = |x: usize, y: usize| g.cell_index(std::array::from_fn(|k| [x, y, 0][k]));
        // (from, to, cost there): the candidates are (from, cost 0) and (to, cost).
        let moves = [
            ((0, 0), (1, 0), 1.0),
            ((1, 0), (2, 0), 0.5),
            ((2, 0), (3, 0), -0.25),
            ((0, 1), (1, 1), 0.1),
            ((1, 1), (0, 1), 0.2),
            ((3, 0), (3, 1), 0.01),
            ((3, 1), (3, 0), 0.02),
            ((3, 0), (2, 0), 7.0),
        ];
        let bin_cell: Vec<usize> = (0..g.num_cells()).collect();
        let mut q = BoundedAssignment {
            item_start: vec![0],
            lower: vec![0; g.num_cells()],
            upper: vec![9; g.num_cells()],
            ..Default::default()
        };
        for ((fx, fy), (tx, ty), cost) in moves {
            q.cand_bin.extend([at(fx, fy) as u32, at(tx, ty) as u32]);
            q.cand_cost.extend([0.0, cost]);
            q.item_start.push(q.cand_bin.len());
        }
        let p = CorrectionProblem::<D> {
            assignment: q,
            bin_cell,
            stay: vec![],
            band_sign: vec![],
        };
        let n = moves.len() as u32;
        let b_star: Vec<u32> = (0..n).map(|i| 2 * i).collect();
        // All but the last particle (which stays) take their second candidate.
        let choice: Vec<u32> = (0..n).map(|i| 2 * i + u32::from(i + 1 < n)).collect();
        let paths = paths_of(&g, &p, &b_star, &choice);
        let centre = |x: usize, y: usize| g.center(g.cell_coords(at(x, y)));
        let want = [
            (
                vec![centre(0, 0), centre(1, 0), centre(2, 0), centre(3, 0)],
                1.25,
            ),
            (vec![centre(3, 0), centre(3, 1), centre(3, 0)], 0.03),
            (vec![centre(0, 1), centre(1, 1), centre(0, 1)], 0.3),
        ];
        assert_eq!(paths.len(), want.len(), "{D}D: {paths:?}");
        for (path, (cells, cost)) in paths.iter().zip(want) {
            assert_eq!(path.cells, cells, "{D}D");
            assert!((path.cost - cost).abs() < 1e-15, "{D}D: {path:?}");
        }
    }

    #[test]
    fn cell_changes_decompose_into_a_chain_and_a_cycle_2d_and_3d() {
        chain_and_cycle::<2>();
        chain_and_cycle::<3>();
    }
}
