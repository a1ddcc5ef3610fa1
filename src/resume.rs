//! `cellflip run --resume`: the scene a checkpoint was written with, and the refusal of a
//! command line that would change it. Only how long the run goes, where it records and how it
//! reports may change: anything else would make the continuation another run.

use crate::checkpoint::Opened;
use crate::scene::{Overrides, Scene};
use anyhow::{anyhow, bail, Result};

/// The scene of checkpoint `c`, run until `duration` when given. `scene_arg`, the command
/// line's scene, must name the checkpoint's; each of `given`, a flag with the overrides it
/// makes alone, must leave the scene as the checkpoint has it.
pub fn scene(
    c: &Opened,
    scene_arg: Option<&str>,
    duration: Option<f64>,
    given: &[(String, Overrides)],
) -> Result<Scene> {
    let o = &c.origin;
    let file = c.path.display();
    let parse = |over: &Overrides| Scene::parse(&o.scene_source, &o.scene_toml, over);
    let base = parse(&Overrides::default())
        .map_err(|e| anyhow!("checkpoint '{file}': its scene does not load: {e:#}"))?;
    if let Some(a) = scene_arg.filter(|a| *a != o.scene_arg && *a != base.name()) {
        bail!(
            "{a}: checkpoint '{file}' is of scene '{}' (started as `{}`); leave the scene out \
             or name that one",
            base.name(),
            o.scene_arg
        );
    }
    for (flag, only) in given {
        let same = parse(only).is_ok_and(|s| s.resolved_toml() == base.resolved_toml());
        if !same {
            bail!(
                "{flag}: checkpoint '{file}' was written with another value; a resumed run keeps \
                 the scene, method and options it started with (only --steps, --duration, where \
                 it records and how it reports may change)"
            );
        }
    }
    let program = c.reader.meta("program").unwrap_or("an unknown program");
    let ours = format!("cellflip {}", env!("CARGO_PKG_VERSION"));
    if program != ours {
        eprintln!(
            "warning: checkpoint '{file}' was written by {program}, this is {ours}: the \
             continuation may differ from the run never stopped"
        );
    }
    match duration {
        Some(d) => parse(&Overrides {
            duration: Some(d),
            ..Default::default()
        }),
        None => Ok(base),
    }
}
