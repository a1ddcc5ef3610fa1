//! `cellflip view`: saved recordings (a run's, a comparison's, the report's) in a browser,
//! served by this program with Rerun's web viewer (`--serve-web`), or in the native viewer.

use crate::cmd::cli::ViewArgs;
use crate::{interrupt, record};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// `cellflip view`: every file is read through first, so that one that is not a recording is
/// refused before a viewer opens on nothing, and one cut short is shown with a warning.
pub fn view(args: &ViewArgs) -> Result<()> {
    let files = read_all(&args.recordings)?;
    let Some(serve) = args.serve.web() else {
        return native(&args.recordings);
    };
    interrupt::install()?;
    let served = record::serve_files(&serve, &files)?;
    served.hold_until_signal();
    Ok(())
}

/// What each file holds ([`record::Contents`]); warns of each file cut short.
fn read_all(paths: &[PathBuf]) -> Result<Vec<record::Contents>> {
    let mut all = vec![];
    for p in paths {
        let c = record::Contents::read(p)?;
        if let Some(warning) = c.warning() {
            eprintln!("{warning}");
        }
        all.push(c);
    }
    Ok(all)
}

/// The native viewer (`rerun` on the `PATH`) on the recordings, until it is closed.
fn native(files: &[PathBuf]) -> Result<()> {
    let Some(rerun) = on_path("rerun") else {
        let names: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
        bail!(
            "no native viewer: `rerun` is not on the PATH (pip install rerun-sdk==0.36.3); \
             or open them in a browser, no install needed: cellflip view --serve-web {}",
            names.join(" ")
        );
    };
    let status = std::process::Command::new(&rerun)
        .args(files)
        .status()
        .with_context(|| format!("cannot start the viewer '{}'", rerun.display()))?;
    match status.success() {
        true => Ok(()),
        false => bail!("the viewer '{}' ended with {status}", rerun.display()),
    }
}

/// The first file called `name` in a folder of the `PATH`.
fn on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| Path::is_file(p))
}
