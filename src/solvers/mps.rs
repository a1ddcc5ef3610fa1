//! Bounded assignment problems as free-format MPS, so that any LP solver (HiGHS, GLPK, or
//! LEMON's network simplex through a reader) can check an exported correction, and back, so
//! that `cellflip solve` can time our solvers on the very file a peer solves.
//!
//! The file: rows `item<i>` (`E`, right-hand side 1), `bin<b>` for the bins whose bounds can
//! bind (`E` when lower and upper meet, else `L` on the upper bound with the lower bound as a
//! range), columns `x<k>` with their cost, item and bin entries, all bounded above by 1.
//! [`read`] takes the objective row under any name, as other tools write it, and refuses
//! what is not such a problem, naming the line and what it expected there.

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

/// A line of an MPS file that [`read`] cannot take, with its 1-based number: the line past
/// the last one for what the file as a whole lacks (a ROWS section, items, a column per item).
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

/// The sections [`read`] takes, each with the entries it expects in it.
const SECTIONS: [(&str, &str); 7] = [
    ("NAME", "none (the name goes on the NAME line)"),
    ("ROWS", "a row type and a row name, e.g. `E item0`"),
    ("COLUMNS", "a column, rows and values, e.g. `x0 item0 1`"),
    ("RHS", "a set, a row and a value, e.g. `rhs item0 1`"),
    ("RANGES", "a set, a bin row and a value, e.g. `rng bin1 1`"),
    ("BOUNDS", "`UP <set> <column> 1`"),
    ("ENDATA", "none (the data has ended)"),
];

/// The row types [`read`] takes, for its errors.
const ROW_TYPES: &str = "N (the objective), E (item<i> or bin<b>) or L (bin<b>)";

/// Reads a file that [`write`] wrote, or another tool wrote for the same problem: its `N` row
/// is the objective whatever its name, and a second `N` row is refused rather than dropped.
/// A column with no bin row gets a bin of its own with room for it (its bin could not bind),
/// which leaves the optimum unchanged. Refused, naming the line and what it expected: control
/// characters (binary data), an entry before any section, a section other than NAME, ROWS,
/// COLUMNS, RHS, RANGES, BOUNDS and ENDATA, a row type other than N, E and L, rows other than
/// the objective, `item<i>` and `bin<b>`, and a file with no ROWS section or no item.
pub fn read(text: &str) -> Result<MpsProblem, MpsError> {
    let mut r = Reader::default();
    for (n, line) in text.lines().enumerate() {
        r.line = n + 1;
        if let Some(c) = line.chars().find(|&c| c.is_control() && c != '\t') {
            return r.fail(format!("binary data ({c:?}): expected a text file"));
        }
        let words: Vec<_> = line.split_whitespace().collect();
        match (line.strip_prefix('*'), words.first()) {
            (Some(c), _) => r.comment(c)?,
            (None, None) => {} // a blank line
            (None, Some(_)) if line.starts_with(char::is_whitespace) => r.entry(&words)?,
            (None, Some(name)) => r.header(name)?,
        }
    }
    r.finish()
}

#[derive(Default)]
struct Reader {
    line: usize,
    section: String,
    recorded_optimum: Option<f64>,
    rows_seen: bool,
    /// The name of the `N` row.
    objective: Option<String>,
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

    /// A comment, which records the optimum when it reads `optimal objective <value>`.
    fn comment(&mut self, c: &str) -> Result<(), MpsError> {
        let value = c.trim().strip_prefix("optimal objective ");
        if let Some(v) = value.and_then(|v| v.split_whitespace().next()) {
            self.recorded_optimum = Some(self.number(v)?);
        }
        Ok(())
    }

    /// A section header, named by its first word: one of [`SECTIONS`].
    fn header(&mut self, name: &str) -> Result<(), MpsError> {
        if !SECTIONS.iter().any(|&(s, _)| s == name) {
            let names: Vec<_> = SECTIONS.iter().map(|&(s, _)| s).collect();
            let names = names.join(", ");
            return self.fail(format!("section {name:?}: expected one of {names}"));
        }
        self.rows_seen |= name == "ROWS";
        self.section = name.to_string();
        Ok(())
    }

    fn entry(&mut self, f: &[&str]) -> Result<(), MpsError> {
        match (self.section.as_str(), f) {
            ("ROWS", [kind, name]) => self.row(kind, name),
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
            (section, _) => match SECTIONS.iter().find(|&&(s, _)| s == section) {
                Some((_, want)) => self.fail(format!("entry in {section}: expected {want}")),
                None => self.fail("entry outside any section: expected a section header first"),
            },
        }
    }

    /// A row of [`ROW_TYPES`]: the objective, `item<i>` in order, or `bin<b>`.
    fn row(&mut self, kind: &str, name: &str) -> Result<(), MpsError> {
        match (kind, self.index(name, "item"), self.index(name, "bin")) {
            ("N", ..) => self.objective_row(name),
            ("E", Some(i), _) if i == self.items as u64 => {
                self.items += 1;
                Ok(())
            }
            ("E", Some(_), _) => self.fail(format!("item row {name:?} out of order")),
            ("E" | "L", _, Some(b)) => {
                self.bin_of_name.insert(b, self.bins.len() as u32);
                self.bins.push((kind == "E", None, None));
                Ok(())
            }
            ("E" | "L", ..) => self.fail(format!("row {name:?}: expected item<i> or bin<b>")),
            ("G", ..) => self.fail(format!("row type G of {name:?}: expected {ROW_TYPES}")),
            _ => self.fail(format!(
                "row type {kind:?} is not an MPS row type (N, E, L, G): expected {ROW_TYPES}"
            )),
        }
    }

    /// The objective: the first `N` row, whatever its name; a second one is refused.
    fn objective_row(&mut self, name: &str) -> Result<(), MpsError> {
        if let Some(first) = &self.objective {
            let reason = format!("second N row {name:?}: expected one objective ({first:?})");
            return self.fail(reason);
        }
        self.objective = Some(name.to_string());
        Ok(())
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
            if Some(row) == self.objective.as_deref() {
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
    /// column without a row. Its errors name the line past the last one.
    fn finish(mut self) -> Result<MpsProblem, MpsError> {
        self.line += 1;
        if !self.rows_seen {
            return self.fail("end of file without a ROWS section: expected an MPS file");
        }
        if self.items == 0 {
            return self.fail("no item rows: expected a correction problem (`E item0`, ...)");
        }
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

    /// One item with one candidate in a bin that must hold it; its file has ` E item0` on
    /// line 4.
    fn one_item() -> BoundedAssignment {
        BoundedAssignment {
            item_start: vec![0, 1],
            cand_bin: vec![0],
            cand_cost: vec![1.0],
            lower: vec![1],
            upper: vec![1],
        }
    }

    /// Text that is not MPS is refused at its first line: an unknown section, or an entry
    /// before any section.
    #[test]
    fn read_refuses_text_at_its_first_line() {
        let e = read("the quick brown fox\njumps\n").unwrap_err();
        assert_eq!(e.line, 1, "{e}");
        let want = "section \"the\": expected one of NAME, ROWS, COLUMNS, RHS, RANGES";
        assert!(e.reason.starts_with(want), "{e}");
        let e = read("  the quick brown fox\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "line 1: entry outside any section: expected a section header first"
        );
    }

    /// An empty file has no ROWS section, and rows without items are no correction problem:
    /// both are refused at the line past the last one.
    #[test]
    fn read_refuses_a_file_without_rows_or_items() {
        let e = read("").unwrap_err();
        assert_eq!(e.line, 1, "{e}");
        assert!(e.reason.contains("without a ROWS section"), "{e}");
        let e = read("NAME t\nROWS\n N cost\nENDATA\n").unwrap_err();
        assert_eq!(e.line, 5, "{e}");
        assert!(e.reason.starts_with("no item rows"), "{e}");
    }

    /// Control characters (NUL bytes of binary data) are refused at their line.
    #[test]
    fn read_refuses_binary_data() {
        let e = read("\u{7f}ELF\u{2}\u{1}\u{1}\0\0\n").unwrap_err();
        assert_eq!(e.line, 1, "{e}");
        assert!(e.reason.starts_with("binary data"), "{e}");
        let e = read(&write(&one_item(), "t", &[]).replace("item0\n", "item0\0\n")).unwrap_err();
        assert_eq!(e.line, 4, "{e}");
        assert!(e.reason.starts_with("binary data ('\\0')"), "{e}");
    }

    /// A row type outside N, E, L and G, a G row, a row that is neither the objective nor an
    /// item or bin row, and a second N row are refused at their line, saying what is taken.
    #[test]
    fn read_refuses_rows_it_does_not_take() {
        let text = write(&one_item(), "t", &[]);
        for (row, want) in [
            (" X item0", "row type \"X\" is not an MPS row type"),
            (" G item0", "row type G of \"item0\": expected N (the"),
            (" E balance", "row \"balance\": expected item<i> or bin<b>"),
            (" N cost2", "second N row \"cost2\": expected one"),
        ] {
            let e = read(&text.replace(" E item0", row)).unwrap_err();
            assert_eq!(e.line, 4, "{e}");
            assert!(e.reason.starts_with(want), "{e}");
        }
    }

    /// The objective is the N row whatever its name: a file that calls it `obj` reads back to
    /// the same problem as with `cost`.
    #[test]
    fn read_takes_the_objective_under_any_name() {
        let p = BoundedAssignment {
            item_start: vec![0, 2, 3],
            cand_bin: vec![0, 1, 0],
            cand_cost: vec![0.5, 0.25, 2.0],
            lower: vec![0, 0],
            upper: vec![1, 1],
        };
        let text = write(&p, "t", &[]);
        let obj = text.replace(" N cost", " N obj").replace(" cost ", " obj ");
        assert!(!obj.contains("cost"), "{obj}");
        assert_eq!(read(&obj).unwrap(), read(&text).unwrap());
        assert_eq!(read(&obj).unwrap().problem.cand_cost, p.cand_cost);
    }
}
