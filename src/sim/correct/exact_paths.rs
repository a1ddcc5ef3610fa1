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

use super::band::PathDirection;
use super::problem::CorrectionProblem;
use crate::sim::markings::Markings;
use crate::solvers::min_cost_flow::{self, BoundedAssignment, FlowStats, Solution};

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
    ) -> Result<Self, String> {
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
            return Err(format!(
                "the sources hold {ghosts} particles, fewer than the {n_move} to move"
            ));
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
    ) -> Result<(Vec<u32>, FlowStats), String> {
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
        }
        .map_err(|e| e.to_string())?;
        let mut choice = solved.choice;
        choice.truncate(self.particles);
        Ok((choice, solved.stats))
    }
}
