//! A report's matrix as the command-line options that make it (`--scenes dam-2d --res 32`):
//! kept with each run's result ([`super::saved`]), so that `report --merge DIR` merges what
//! DIR holds without the options repeated, and names the command that merges another matrix's
//! results.

use crate::cmd::cli::{Matrix, ReportArgs};
use anyhow::{anyhow, Result};
use clap::{Args, FromArgMatches, ValueEnum};

/// A matrix's options in one order, each left out where it is the default (the default matrix
/// has none), so that two command lines of one matrix give the same options.
#[derive(Clone, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub struct MatrixOptions(Vec<String>);

impl MatrixOptions {
    /// The options of the matrix `args` ask for.
    pub fn of(args: &ReportArgs) -> Self {
        let mut o: Vec<String> = vec![];
        let mut list = |name: &str, values: Vec<String>| {
            if !values.is_empty() {
                o.extend([name.to_string(), values.join(",")]);
            }
        };
        match args.matrix {
            _ if !args.scenes.is_empty() => list("--scenes", args.scenes.clone()),
            Some(Matrix::Paper) => list("--matrix", vec!["paper".into()]),
            _ => {}
        }
        let methods = args.methods.iter().filter_map(|m| m.to_possible_value());
        list("--methods", methods.map(|m| m.get_name().into()).collect());
        list("--res", args.res.iter().map(usize::to_string).collect());
        list("--seeds", args.seeds.iter().map(u64::to_string).collect());
        list(
            "--duration",
            args.duration.iter().map(f64::to_string).collect(),
        );
        list("--budget", args.budget.iter().map(f64::to_string).collect());
        match super::stability(args) {
            (true, false) => o.push("--no-stability".into()),
            (false, true) => o.push("--stability".into()),
            _ => {}
        }
        Self(o)
    }

    /// Whether `args` name any option of the matrix (`--matrix default` too); without one,
    /// `--merge` merges the matrix its folder's results were planned from.
    pub fn given(args: &ReportArgs) -> bool {
        let said = args.matrix.is_some() || args.stability || args.no_stability;
        said || !Self::of(args).0.is_empty()
    }

    /// `args` with this matrix in place of theirs, read by the command line's own parser (so
    /// that `--docs` refuses a matrix it does not write).
    pub fn apply(&self, args: &ReportArgs) -> Result<ReportArgs> {
        let docs = args.docs.then_some("--docs");
        let words = self.0.iter().map(String::as_str).chain(docs);
        let parser = ReportArgs::augment_args(clap::Command::new("report"));
        let parsed = (parser.try_get_matches_from(std::iter::once("report").chain(words)))
            .and_then(|m| ReportArgs::from_arg_matches(&m))
            .map_err(|e| {
                let said = e.render().to_string();
                let line = said.lines().next().unwrap_or_default();
                anyhow!("{}", line.trim_start_matches("error: "))
            })?;
        Ok(ReportArgs {
            out: args.out.clone(),
            merge: args.merge.clone(),
            quiet: args.quiet,
            ..parsed
        })
    }

    /// As a result file keeps them: one option or value a line.
    pub fn to_meta(&self) -> String {
        self.0.join("\n")
    }

    pub fn from_meta(meta: &str) -> Self {
        Self(meta.lines().map(String::from).collect())
    }
}

/// As typed after `cellflip report`, quoted for a shell where needed; the default matrix as
/// `--matrix default`.
impl std::fmt::Display for MatrixOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_empty() {
            return f.write_str("--matrix default");
        }
        let words: Vec<String> = self.0.iter().map(|w| shell_word(w)).collect();
        f.write_str(&words.join(" "))
    }
}

/// `w` as a shell reads it back: as it is when plain, else in single quotes.
pub fn shell_word(w: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "-_.,/:=+@%".contains(c);
    match !w.is_empty() && w.chars().all(plain) {
        true => w.into(),
        false => format!("'{}'", w.replace('\'', r"'\''")),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use clap::Parser;

    /// `cellflip report` with the options of `line` (split at spaces).
    pub fn args(line: &str) -> ReportArgs {
        let words = ["cellflip", "report"]
            .into_iter()
            .chain(line.split_whitespace());
        match crate::cmd::cli::Cli::parse_from(words).command {
            crate::cmd::cli::Command::Report(args) => args,
            _ => unreachable!("a report command"),
        }
    }

    /// Command lines of one matrix give one set of options (defaults left out), which read
    /// back give that matrix again.
    #[test]
    fn a_matrix_s_options_leave_out_its_defaults_and_read_back() {
        for (line, options) in [
            ("", "--matrix default"),
            ("--matrix default --stability", "--matrix default"),
            ("--no-stability -q", "--no-stability"),
            ("--matrix paper", "--matrix paper"),
            ("--scenes dam-2d --no-stability", "--scenes dam-2d"),
            (
                "--res 32,24 --scenes dam-2d,o'brien.toml --methods flip --duration 0.5 --budget 90 --stability",
                r"--scenes 'dam-2d,o'\''brien.toml' --methods flip --res 32,24 --duration 0.5 --budget 90 --stability",
            ),
        ] {
            let o = MatrixOptions::of(&args(line));
            assert_eq!(o.to_string(), options, "{line}");
            assert_eq!(MatrixOptions::from_meta(&o.to_meta()), o);
            let again = o.apply(&args("--merge x")).unwrap();
            assert_eq!(MatrixOptions::of(&again), o, "{line}");
            assert_eq!(again.merge, [std::path::PathBuf::from("x")]);
        }
        assert!(!MatrixOptions::given(&args("-q --merge x")));
        assert!(MatrixOptions::given(&args("--matrix default")));
        let scenes = MatrixOptions::of(&args("--scenes dam-2d"));
        let e = scenes.apply(&args("--docs --merge x")).unwrap_err();
        assert!(
            e.to_string().contains("cannot be used with '--docs'"),
            "{e}"
        );
    }
}
