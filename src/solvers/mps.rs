//! Bounded assignment problems as free-format MPS, so that any LP solver (HiGHS, GLPK, or
//! LEMON's network simplex through a reader) can check an exported correction, and back, so
//! that `cellflip solve` can time our solvers on the very file a peer solves.
//!
//! The file: rows `item<i>` (`E`, right-hand side 1), `bin<b>` for the bins whose bounds can
//! bind (`E` when lower and upper meet, else `L` on the upper bound with the lower bound as a
//! range), columns `x<k>` with their cost, item and bin entries, all bounded above by 1.

use crate::solvers::min_cost_flow::BoundedAssignment;
use std::fmt::Write as _;

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
pub fn write(p: &BoundedAssignment, name: &str, comment: &[String]) -> String {
    let mut s = String::new();
    for c in comment {
        let _ = writeln!(s, "* {c}");
    }
    let _ = writeln!(s, "NAME {name}\nROWS\n N cost");
    for i in 0..p.items() {
        let _ = writeln!(s, " E item{i}");
    }
    let binding = p.binding_bins();
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

/// A line of an MPS file that [`read`] cannot take, with its 1-based number.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("line {line}: {reason}")]
pub struct MpsError {
    pub line: usize,
    pub reason: String,
}

/// A problem read back by [`read`], with the objective its file records, if any.
#[derive(Clone, Debug, PartialEq)]
pub struct MpsProblem {
    pub problem: BoundedAssignment,
    /// The value of a leading `* optimal objective <value>` comment.
    pub recorded_optimum: Option<f64>,
}

/// One column: its item, its binding bin (a row index, if any) and its cost.
#[derive(Clone, Copy)]
struct Column {
    item: u32,
    bin: Option<u32>,
    cost: f64,
}

/// Reads a file that [`write`] wrote. A column with no bin row gets a bin of its own with
/// room for it (its bin could not bind), which leaves the optimum unchanged.
pub fn read(text: &str) -> Result<MpsProblem, MpsError> {
    let mut r = Reader::default();
    for (n, line) in text.lines().enumerate() {
        r.line = n + 1;
        if let Some(c) = line.strip_prefix('*') {
            let value = c.trim().strip_prefix("optimal objective ");
            if let Some(v) = value.and_then(|v| v.split_whitespace().next()) {
                r.recorded_optimum = Some(r.number(v)?);
            }
        } else if !line.starts_with(' ') {
            r.section = line.split_whitespace().next().unwrap_or("").to_string();
        } else {
            r.entry(&line.split_whitespace().collect::<Vec<_>>())?;
        }
    }
    r.finish()
}

#[derive(Default)]
struct Reader {
    line: usize,
    section: String,
    recorded_optimum: Option<f64>,
    items: usize,
    /// Per bin row: `E` or `L`, right-hand side and range.
    bins: Vec<(bool, Option<f64>, Option<f64>)>,
    bin_of_name: std::collections::HashMap<u64, u32>,
    columns: Vec<Column>,
    last_column: Option<String>,
}

impl Reader {
    fn fail<T>(&self, reason: impl Into<String>) -> Result<T, MpsError> {
        Err(MpsError {
            line: self.line,
            reason: reason.into(),
        })
    }

    fn number(&self, s: &str) -> Result<f64, MpsError> {
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => self.fail(format!("{s:?} is not a finite number")),
        }
    }

    /// The index in a row name `<prefix><index>`.
    fn index(&self, name: &str, prefix: &str) -> Option<u64> {
        name.strip_prefix(prefix)?.parse().ok()
    }

    fn bin_row(&self, name: &str) -> Result<u32, MpsError> {
        match self
            .index(name, "bin")
            .and_then(|b| self.bin_of_name.get(&b))
        {
            Some(&b) => Ok(b),
            None => self.fail(format!("row {name:?} is not a declared bin row")),
        }
    }

    fn entry(&mut self, f: &[&str]) -> Result<(), MpsError> {
        match (self.section.as_str(), f) {
            ("ROWS", ["N", "cost"]) => Ok(()),
            ("ROWS", ["E", name]) if name.starts_with("item") => {
                if self.index(name, "item") != Some(self.items as u64) {
                    return self.fail(format!("item row {name:?} out of order"));
                }
                self.items += 1;
                Ok(())
            }
            ("ROWS", [kind @ ("E" | "L"), name]) => match self.index(name, "bin") {
                Some(b) => {
                    self.bin_of_name.insert(b, self.bins.len() as u32);
                    self.bins.push((*kind == "E", None, None));
                    Ok(())
                }
                None => self.fail(format!("row {name:?}: expected item<i> or bin<b>")),
            },
            ("COLUMNS", [name, pairs @ ..]) if !pairs.is_empty() && pairs.len() % 2 == 0 => {
                self.column(name, pairs)
            }
            ("RHS", [_, row, value]) => self.rhs(row, value),
            ("RANGES", [_, row, value]) => {
                let (b, v) = (self.bin_row(row)?, self.number(value)?);
                self.bins[b as usize].2 = Some(v);
                Ok(())
            }
            ("BOUNDS", ["UP", _, _, "1"]) => Ok(()),
            (section, _) => self.fail(format!("unexpected entry in section {section:?}")),
        }
    }

    fn column(&mut self, name: &str, pairs: &[&str]) -> Result<(), MpsError> {
        if self.last_column.as_deref() != Some(name) {
            self.last_column = Some(name.to_string());
            self.columns.push(Column {
                item: u32::MAX,
                bin: None,
                cost: 0.0,
            });
        }
        for pair in pairs.chunks(2) {
            let (row, value) = (pair[0], self.number(pair[1])?);
            if row == "cost" {
                self.columns.last_mut().expect("pushed").cost = value;
                continue;
            }
            if value != 1.0 {
                return self.fail(format!("coefficient {value} in row {row:?}: expected 1"));
            }
            let item = self.index(row, "item");
            let bin = row
                .starts_with("bin")
                .then(|| self.bin_row(row))
                .transpose()?;
            let c = self.columns.last_mut().expect("pushed");
            match (item, bin) {
                (Some(i), _) if c.item == u32::MAX => c.item = i as u32,
                (_, Some(b)) if c.bin.is_none() => c.bin = Some(b),
                _ => return self.fail(format!("column {name:?}: unexpected row {row:?}")),
            }
        }
        Ok(())
    }

    fn rhs(&mut self, row: &str, value: &str) -> Result<(), MpsError> {
        let v = self.number(value)?;
        if row.starts_with("item") {
            return if v == 1.0 {
                Ok(())
            } else {
                self.fail(format!(
                    "item row {row:?} has right-hand side {v}, expected 1"
                ))
            };
        }
        let b = self.bin_row(row)?;
        self.bins[b as usize].1 = Some(v);
        Ok(())
    }

    /// The problem: candidates in item order, then the bins of the rows and one free bin per
    /// column without a row.
    fn finish(mut self) -> Result<MpsProblem, MpsError> {
        self.line = 0;
        let mut p = BoundedAssignment::default();
        for (kind_e, rhs, range) in &self.bins {
            let upper = rhs.unwrap_or(0.0);
            let lower = match (kind_e, range) {
                (true, _) => upper,
                (false, Some(r)) => upper - r.abs(),
                (false, None) => 0.0,
            };
            if upper < 0.0 || lower < 0.0 || upper.fract() != 0.0 || lower.fract() != 0.0 {
                return self.fail(format!("bin bounds [{lower}, {upper}] are not counts"));
            }
            p.lower.push(lower as u32);
            p.upper.push(upper as u32);
        }
        if let Some(c) = self.columns.iter().find(|c| c.item as usize >= self.items) {
            return self.fail(format!("a column has no declared item row ({})", c.item));
        }
        self.columns.sort_by_key(|c| c.item);
        p.item_start = vec![0; self.items + 1];
        for c in &self.columns {
            p.item_start[c.item as usize + 1] += 1;
            let bin = c.bin.unwrap_or_else(|| {
                p.lower.push(0);
                p.upper.push(1);
                p.lower.len() as u32 - 1
            });
            p.cand_bin.push(bin);
            p.cand_cost.push(c.cost);
        }
        for i in 0..self.items {
            if p.item_start[i + 1] == 0 {
                return self.fail(format!("item {i} has no column"));
            }
            p.item_start[i + 1] += p.item_start[i];
        }
        Ok(MpsProblem {
            problem: p,
            recorded_optimum: self.recorded_optimum,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert_eq!(write(&p, "t", &["c".into()]), want);
    }

    #[test]
    fn read_gives_back_the_written_problem() {
        // As in the test above, plus a bin with a lower bound but no range (bin 4, E row).
        let p = BoundedAssignment {
            item_start: vec![0, 2, 5, 7, 8],
            cand_bin: vec![0, 1, 0, 1, 2, 2, 3, 4],
            cand_cost: vec![0.0, 0.5, 0.25, 0.0, 1.0, 0.0, 2.0, 0.125],
            lower: vec![1, 1, 0, 0, 1],
            upper: vec![1, 2, 1, 1, 1],
        };
        let text = write(&p, "t", &["optimal objective 1.5e0 (flow solver)".into()]);
        let back = read(&text).unwrap();
        assert_eq!(back.recorded_optimum, Some(1.5));
        let q = back.problem;
        // Rows come back in file order; bin 3 cannot bind and comes back as a free bin.
        assert_eq!(q.item_start, p.item_start);
        assert_eq!(q.cand_cost, p.cand_cost);
        assert_eq!(q.cand_bin, vec![0, 1, 0, 1, 2, 2, 4, 3]);
        assert_eq!(q.lower, vec![1, 1, 0, 1, 0]);
        assert_eq!(q.upper, vec![1, 2, 1, 1, 1]);
    }

    #[test]
    fn read_names_the_line_it_cannot_take() {
        let p = BoundedAssignment {
            item_start: vec![0, 1],
            cand_bin: vec![0],
            cand_cost: vec![1.0],
            lower: vec![1],
            upper: vec![1],
        };
        let text = write(&p, "t", &[]).replace(" x0 cost 1e0", " x0 cost one");
        let e = read(&text).unwrap_err();
        assert_eq!(e.line, 7, "{e}");
        assert!(e.reason.contains("\"one\" is not a finite number"), "{e}");
    }
}
