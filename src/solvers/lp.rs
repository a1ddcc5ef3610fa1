//! The reference solver: the LP relaxation of a bounded assignment problem, solved by the
//! pure-Rust simplex of `microlp` (the maintained fork of `minilp`), and its export as
//! free-format MPS so that any LP solver can check it.
//!
//! The constraint matrix is totally unimodular (paper prop. LPrelax), so the LP optimum is an
//! assignment; this module checks that it really is integral and reports it if not.
//!
//! Side constraints over the candidates (the band constraints eq. band_con, band_con2,
//! band_con3) break total unimodularity; with any of them the variables are declared binary and
//! microlp's branch and bound solves the integer program.

use crate::solvers::min_cost_flow::BoundedAssignment;
use microlp::{ComparisonOp, OptimizationDirection, Problem};
use std::fmt::Write as _;

/// A simplex run longer than this gives up; the caller falls back to a feasible assignment.
pub const TIME_LIMIT: std::time::Duration = std::time::Duration::from_secs(120);

/// Why the simplex gave no assignment.
#[derive(Clone, Debug, PartialEq)]
pub enum LpError {
    Solver(String),
    /// An item's variables are not one 1 and zeros (within 1e-6): the relaxation was not
    /// integral, against prop. LPrelax.
    NotIntegral {
        item: usize,
        values: Vec<f64>,
    },
}

impl std::fmt::Display for LpError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LpError::Solver(e) => write!(f, "simplex failed: {e}"),
            LpError::NotIntegral { item, values } => {
                write!(f, "LP solution not integral at item {item}: {values:?}")
            }
        }
    }
}

impl std::error::Error for LpError {}

/// Bins whose bounds can bind: a lower bound, or more candidates than room.
fn binding_bins(p: &BoundedAssignment) -> Vec<bool> {
    let mut arcs = vec![0u32; p.bins()];
    for &b in &p.cand_bin {
        arcs[b as usize] += 1;
    }
    (0..p.bins())
        .map(|b| p.lower[b] > 0 || arcs[b] > p.upper[b])
        .collect()
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
    let binding = binding_bins(p);
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

/// The MPS row type of a binding bin: `E` when its bounds meet (an inner cell that must keep
/// exactly its count), else `L` on the upper bound with the lower bound as a range.
fn bin_row_type(p: &BoundedAssignment, b: usize) -> char {
    if p.lower[b] == p.upper[b] {
        'E'
    } else {
        'L'
    }
}

/// The problem in free-format MPS (rows `item<i>` and `bin<b>`, columns `x<k>`), with
/// `comment` lines (e.g. the optimal objective) as `*` comments at the top. A bin row is `E`
/// when its bounds are equal, else `L` with a `RANGES` entry when it has a lower bound.
pub fn to_mps(p: &BoundedAssignment, name: &str, comment: &[String]) -> String {
    let mut s = String::new();
    for c in comment {
        let _ = writeln!(s, "* {c}");
    }
    let _ = writeln!(s, "NAME {name}\nROWS\n N cost");
    for i in 0..p.items() {
        let _ = writeln!(s, " E item{i}");
    }
    let binding = binding_bins(p);
    for b in (0..p.bins()).filter(|&b| binding[b]) {
        let _ = writeln!(s, " {} bin{b}", bin_row_type(p, b));
    }
    let _ = writeln!(s, "COLUMNS");
    for i in 0..p.items() {
        for k in p.candidates(i) {
            let b = p.cand_bin[k] as usize;
            let _ = write!(s, " x{k} cost {:e} item{i} 1", p.cand_cost[k]);
            if binding[b] {
                let _ = write!(s, "\n x{k} bin{b} 1");
            }
            s.push('\n');
        }
    }
    let _ = writeln!(s, "RHS");
    for i in 0..p.items() {
        let _ = writeln!(s, " rhs item{i} 1");
    }
    for b in (0..p.bins()).filter(|&b| binding[b]) {
        let _ = writeln!(s, " rhs bin{b} {}", p.upper[b]);
    }
    let _ = writeln!(s, "RANGES");
    let ranged = |b: usize| binding[b] && p.lower[b] > 0 && bin_row_type(p, b) == 'L';
    for b in (0..p.bins()).filter(|&b| ranged(b)) {
        let _ = writeln!(s, " rng bin{b} {}", p.upper[b] - p.lower[b]);
    }
    let _ = writeln!(s, "BOUNDS");
    for k in 0..p.cand_bin.len() {
        let _ = writeln!(s, " UP bnd x{k} 1");
    }
    s.push_str("ENDATA\n");
    s
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
        let mps = to_mps(&p, "t", &["optimal objective 1".into()]);
        assert!(mps.starts_with("* optimal objective 1\nNAME t\nROWS\n N cost\n E item0"));
        assert!(mps.contains(" L bin0") && !mps.contains(" L bin1") && mps.ends_with("ENDATA\n"));
    }

    #[test]
    fn mps_writes_equal_bounds_as_e_rows_and_lower_bounds_as_ranges() {
        // bin0 must hold exactly 1 (E), bin1 1..2 (L, range 1), bin2 at most 1 with two
        // candidates (L), bin3 cannot bind (no row).
        let p = BoundedAssignment {
            item_start: vec![0, 2, 5, 7],
            cand_bin: vec![0, 1, 0, 1, 2, 2, 3],
            cand_cost: vec![0.0, 0.5, 0.25, 0.0, 1.0, 0.0, 2.0],
            lower: vec![1, 1, 0, 0],
            upper: vec![1, 2, 1, 1],
        };
        let want = "\
* c
NAME t
ROWS
 N cost
 E item0
 E item1
 E item2
 E bin0
 L bin1
 L bin2
COLUMNS
 x0 cost 0e0 item0 1
 x0 bin0 1
 x1 cost 5e-1 item0 1
 x1 bin1 1
 x2 cost 2.5e-1 item1 1
 x2 bin0 1
 x3 cost 0e0 item1 1
 x3 bin1 1
 x4 cost 1e0 item1 1
 x4 bin2 1
 x5 cost 0e0 item2 1
 x5 bin2 1
 x6 cost 2e0 item2 1
RHS
 rhs item0 1
 rhs item1 1
 rhs item2 1
 rhs bin0 1
 rhs bin1 2
 rhs bin2 1
RANGES
 rng bin1 1
BOUNDS
 UP bnd x0 1
 UP bnd x1 1
 UP bnd x2 1
 UP bnd x3 1
 UP bnd x4 1
 UP bnd x5 1
 UP bnd x6 1
ENDATA
";
        assert_eq!(to_mps(&p, "t", &["c".into()]), want);
    }
}
