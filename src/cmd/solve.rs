//! `cellflip solve`: the correction's solvers timed on exported problems (`run --export-lp`),
//! so that they can be compared with any peer that reads the same MPS file, and their optimum
//! checked against the one the file records.

use crate::cmd::cli::SolveArgs;
use crate::methods::ccp::Solver;
use crate::metrics::median;
use crate::outln;
use crate::solvers::mps;
use anyhow::{Context, Result};
use std::path::Path;
use std::time::Instant;

pub fn solve(args: &SolveArgs) -> Result<()> {
    for path in &args.files {
        let text = read_text(path)?;
        let file = mps::read(&text).with_context(|| format!("{}", path.display()))?;
        let p = &file.problem;
        outln!(
            "{}: {} items, {} candidates, {} bins",
            path.display(),
            p.items(),
            p.cand_bin.len(),
            p.bins()
        );
        for &solver in &args.solver {
            let mut times = vec![];
            let mut last = None;
            for _ in 0..args.repeat {
                let t0 = Instant::now();
                let result = solver.solve(p, None);
                times.push(t0.elapsed().as_secs_f64() * 1e3);
                last = Some(result);
            }
            let ms = median(&times).expect("at least one solve");
            match last.expect("at least one solve") {
                Ok(crate::methods::ccp::correct::Solved { choice, work, .. }) => {
                    p.check(&choice)
                        .map_err(anyhow::Error::msg)
                        .with_context(|| format!("{}: {} solver", path.display(), solver.name()))?;
                    let objective = p.objective(&choice);
                    let versus = file.recorded_optimum.map_or(String::new(), |o| {
                        let rel = (objective - o).abs() / o.abs().max(1.0);
                        format!(", {rel:.1e} from the recorded optimum")
                    });
                    // The flow solver's work, which a loaded machine does not blur.
                    let work = match solver {
                        Solver::Flow => {
                            format!(
                                "  {} augmentations, {} nodes settled{}",
                                work.augmentations,
                                work.nodes_settled,
                                match work.halvings {
                                    0 => String::new(),
                                    1 => " (halved)".to_string(),
                                    h => format!(" (halved: {h} splits)"),
                                }
                            )
                        }
                        Solver::Simplex => String::new(),
                    };
                    outln!(
                        "  {:<8} {ms:>10.2} ms (median of {})  objective {objective:.12e}{versus}\
                         {work}",
                        solver.name(),
                        args.repeat
                    );
                }
                Err(e) => outln!("  {:<8} {ms:>10.2} ms  failed: {e}", solver.name()),
            }
        }
    }
    Ok(())
}

/// The file's text, or an error naming the file and the line where it stops being UTF-8.
fn read_text(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    String::from_utf8(bytes).map_err(|e| {
        let text = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = text.iter().filter(|&&b| b == b'\n').count() + 1;
        let path = path.display();
        anyhow::anyhow!("{path}: line {line}: not a text file (not UTF-8): expected an MPS file")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file that is not UTF-8 is refused, naming the file and the line of the first bad byte.
    #[test]
    fn read_text_refuses_a_file_that_is_not_utf8() {
        let path =
            std::env::temp_dir().join(format!("cellflip-{}-not-utf8.mps", std::process::id()));
        std::fs::write(&path, b"NAME t\nROWS\n\xff\xfe\n").unwrap();
        let e = format!("{:#}", read_text(&path).unwrap_err());
        std::fs::remove_file(&path).unwrap();
        assert_eq!(
            e,
            format!(
                "{}: line 3: not a text file (not UTF-8): expected an MPS file",
                path.display()
            )
        );
    }
}
