//! The reference solver: the LP relaxation of a bounded assignment problem, solved by the
//! pure-Rust simplex of `microlp` (the maintained fork of `minilp`).
//!
//! The constraint matrix is totally unimodular (paper prop. LPrelax), so the LP optimum is an
//! assignment; this module checks that it really is integral and reports it if not.
//!
//! Side constraints over the candidates (the band constraints eq. band_con, band_con2,
//! band_con3) break total unimodularity; with any of them the variables are declared binary and
//! microlp's branch and bound solves the integer program.

use crate::solvers::min_cost_flow::BoundedAssignment;
use microlp::{ComparisonOp, OptimizationDirection, Problem};

/// A simplex run longer than this gives up; the caller falls back to a feasible assignment.
pub const TIME_LIMIT: std::time::Duration = std::time::Duration::from_secs(120);

/// Why the simplex gave no assignment.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LpError {
    #[error("simplex failed: {0}")]
    Solver(String),
    /// An item's variables are not one 1 and zeros (within 1e-6): the relaxation was not
    /// integral, against prop. LPrelax.
    #[error("LP solution not integral at item {item}: {values:?}")]
    NotIntegral { item: usize, values: Vec<f64> },
}

/// A linear constraint `min <= sum coef * b_k <= max` over candidate variables `b_k`.
#[derive(Clone, Debug, PartialEq)]
pub struct SideConstraint {
    /// `(candidate index, coefficient)`.
    pub terms: Vec<(usize, f64)>,
    pub min: f64,
    pub max: f64,
}

/// Solves the LP relaxation and returns the chosen candidate of every item.
pub fn solve(p: &BoundedAssignment) -> Result<Vec<u32>, LpError> {
    solve_with(p, &[])
}

/// Solves the problem with extra side constraints; with any, as an integer program.
pub fn solve_with(p: &BoundedAssignment, side: &[SideConstraint]) -> Result<Vec<u32>, LpError> {
    let mut lp = Problem::new(OptimizationDirection::Minimize);
    lp.set_time_limit(TIME_LIMIT);
    let vars: Vec<_> = p
        .cand_cost
        .iter()
        .map(|&c| {
            if side.is_empty() {
                lp.add_var(c, (0.0, 1.0))
            } else {
                lp.add_binary_var(c)
            }
        })
        .collect();
    for sc in side {
        let row: Vec<_> = sc.terms.iter().map(|&(k, a)| (vars[k], a)).collect();
        if sc.min == sc.max {
            lp.add_constraint(row.as_slice(), ComparisonOp::Eq, sc.min);
        } else {
            lp.add_constraint(row.as_slice(), ComparisonOp::Ge, sc.min);
            lp.add_constraint(row.as_slice(), ComparisonOp::Le, sc.max);
        }
    }
    for i in 0..p.items() {
        let row: Vec<_> = p.candidates(i).map(|k| (vars[k], 1.0)).collect();
        lp.add_constraint(row.as_slice(), ComparisonOp::Eq, 1.0);
    }
    let binding = p.binding_bins();
    let mut rows: Vec<Vec<(microlp::Variable, f64)>> = vec![vec![]; p.bins()];
    for (k, &b) in p.cand_bin.iter().enumerate() {
        if binding[b as usize] {
            rows[b as usize].push((vars[k], 1.0));
        }
    }
    for (b, row) in rows.iter().enumerate().filter(|(b, _)| binding[*b]) {
        lp.add_constraint(row.as_slice(), ComparisonOp::Le, p.upper[b] as f64);
        if p.lower[b] > 0 {
            lp.add_constraint(row.as_slice(), ComparisonOp::Ge, p.lower[b] as f64);
        }
    }
    let solution = lp
        .solve()
        .map_err(|e| LpError::Solver(e.to_string()))?
        .into_solution()
        .map_err(|_| {
            LpError::Solver(format!(
                "no optimum within the {} s time limit",
                TIME_LIMIT.as_secs()
            ))
        })?;
    (0..p.items())
        .map(|i| {
            let values: Vec<f64> = p
                .candidates(i)
                .map(|k| solution.var_value(vars[k]))
                .collect();
            let ones: Vec<usize> = (0..values.len())
                .filter(|&j| (values[j] - 1.0).abs() <= 1e-6)
                .collect();
            let integral = ones.len() == 1
                && values
                    .iter()
                    .all(|v| v.abs() <= 1e-6 || (v - 1.0).abs() <= 1e-6);
            if integral {
                Ok((p.item_start[i] + ones[0]) as u32)
            } else {
                Err(LpError::NotIntegral { item: i, values })
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplex_solves_a_small_assignment_integrally() {
        // Two items, one seat in bin 0: the cheaper detour wins.
        let p = BoundedAssignment {
            item_start: vec![0, 2, 4],
            cand_bin: vec![0, 1, 0, 2],
            cand_cost: vec![0.0, 3.0, 0.0, 1.0],
            lower: vec![0, 0, 0],
            upper: vec![1, 1, 1],
        };
        let choice = solve(&p).unwrap();
        p.check(&choice).unwrap();
        assert_eq!(p.objective(&choice), 1.0);
    }
}
