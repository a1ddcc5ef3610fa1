//! How a run starts: afresh, or from the checkpoint `--resume` names (its scene, the command
//! line checked against it: only how long the run goes, where it records and how it reports may
//! change, anything else would make the continuation another run), and with what checkpointing.

use crate::checkpoint::{self, Checkpoints, Opened, Origin, Saver};
use crate::cmd::cli::RunArgs;
use crate::methods::{MethodFlags, MethodSettings, StepFile};
use crate::record::{Resumed, Sink};
use crate::scene::{Overrides, Scene};
use anyhow::{anyhow, bail, Result};
use std::path::Path;
use std::time::Duration;

impl RunArgs {
    /// Each option given that sets the scene, named as typed, with the overrides it makes
    /// alone (a resumed run refuses any that would change its checkpoint's scene).
    fn given_overrides(&self) -> Vec<(String, Overrides)> {
        let o = self.overrides();
        let none = Overrides::default;
        let mut given = vec![];
        macro_rules! each {
            ($($field:ident $flag:literal),*) => {$(
                if o.$field.is_some() {
                    let only = Overrides { $field: o.$field, ..none() };
                    given.push(($flag.to_string(), only));
                }
            )*};
        }
        each!(method "--method", cells "--res", ppc "--ppc", seed "--seed",
            obstacle "--obstacle", pressure "--pressure");
        for (name, value) in &o.flags.0 {
            let flags = MethodFlags(vec![(*name, value.clone())]);
            given.push((format!("--{name}"), Overrides { flags, ..none() }));
        }
        given
    }
}

/// How a run starts: afresh or from a checkpoint, and its checkpointing.
pub(super) struct Start {
    /// The method's settings as it runs, with the files it writes ([`MethodSettings::files`]).
    pub method: MethodSettings,
    pub files: Vec<StepFile>,
    pub resumed: Option<Opened>,
    /// How the recording goes on from the checkpoint's.
    pub continued: Option<Resumed>,
    pub checkpoints: Option<Saver>,
    /// How long reading and checking the checkpoint took.
    pub read: Duration,
}

/// `--checkpoint-every`, checked: a positive, finite number of simulated seconds.
pub(super) fn checkpoint_every(every: Option<f64>) -> Result<Option<f64>> {
    match every {
        Some(e) if !(e.is_finite() && e > 0.0) => {
            bail!("--checkpoint-every {e}: must be a positive, finite number of simulated seconds")
        }
        e => Ok(e),
    }
}

/// The scene of the checkpoint `--resume` names, the command line's other options checked
/// against it.
pub(super) fn resumed_scene(args: &RunArgs, c: &Opened) -> Result<Scene> {
    let given = args.given_overrides();
    checkpoint_scene(c, args.scene.as_deref(), args.scale.duration, &given)
}

/// Where the recording goes and, for a resumed run, how it goes on: by default in the
/// checkpoint's file, cut back to the checkpoint's step (none if the run had no file); with
/// a sink given, there, with the same recording id.
pub(super) fn recording_of(
    args: &RunArgs,
    scene: &Scene,
    resumed: Option<&Opened>,
) -> Result<(Option<Sink>, Option<Resumed>)> {
    let Some(mark) = resumed.map(|c| c.origin.recording.as_ref()) else {
        return Ok((args.sink.choice(scene.name(), &args.serve)?, None));
    };
    let s = &args.sink;
    let not_a_file = s.spawn || s.connect.is_some() || s.stdout || s.no_record;
    let chosen = s.save.is_some() || not_a_file || args.serve.serve_web.is_some();
    let same_file = |m: &checkpoint::RecordingMark| s.save.as_ref().is_none_or(|p| *p == m.path);
    match mark {
        Some(m) if same_file(m) && !not_a_file => {
            let continued = Resumed {
                id: m.id.clone(),
                append_at: Some(m.bytes),
            };
            Ok((args.serve.sink(Some(m.path.clone())), Some(continued)))
        }
        _ if !chosen => Ok((None, None)),
        _ => {
            let id = mark.map(|m| m.id.clone());
            let continued = id.map(|id| Resumed {
                id,
                append_at: None,
            });
            Ok((s.choice(scene.name(), &args.serve)?, continued))
        }
    }
}

/// The run's checkpointing, if on: `--checkpoint-every` or the resumed checkpoint's, into
/// `--checkpoint-dir` or the default folder (the resumed checkpoint's own), made and checked
/// writable before the run starts.
pub(super) fn checkpoints_of(
    args: &RunArgs,
    every: Option<f64>,
    scene: &Scene,
    sink: Option<&Sink>,
    resumed: Option<&Opened>,
) -> Result<Option<Saver>> {
    let Some(every) = every.or(resumed.and_then(|c| c.origin.every)) else {
        if args.checkpoint.checkpoint_dir.is_some() {
            bail!("--checkpoint-dir: checkpoints are written only with --checkpoint-every SECS");
        }
        return Ok(None);
    };
    let file = sink.and_then(Sink::file);
    let resumed_dir = resumed.and_then(|c| c.path.parent().map(Path::to_path_buf));
    let dir = (args.checkpoint.checkpoint_dir.clone())
        .or(resumed_dir)
        .unwrap_or_else(|| checkpoint::default_dir(file, scene.name()));
    let origin = match resumed {
        Some(c) => Origin {
            command: command_line(),
            ..c.origin.clone()
        },
        None => Origin {
            scene_arg: args.scene.clone().unwrap_or_default(),
            scene_source: scene.source.clone(),
            scene_toml: scene.resolved_toml(),
            command: command_line(),
            frames: 0,
            recording: None,
            every: None,
            trails: vec![],
        },
    };
    Ok(Some(Saver::new(
        Checkpoints::new(&dir, resumed)?,
        every,
        origin,
    )))
}

/// The command line, for a checkpoint's reader.
fn command_line() -> String {
    std::env::args().collect::<Vec<_>>().join(" ")
}

/// The scene of checkpoint `c`, run until `duration` when given. `scene_arg`, the command
/// line's scene, must name the checkpoint's; each of `given`, a flag with the overrides it
/// makes alone, must leave the scene as the checkpoint has it.
fn checkpoint_scene(
    c: &Opened,
    scene_arg: Option<&str>,
    duration: Option<f64>,
    given: &[(String, Overrides)],
) -> Result<Scene> {
    let o = &c.origin;
    let file = c.path.display();
    let base = Scene::parse_resolved(&o.scene_source, &o.scene_toml, &Overrides::default())
        .map_err(|e| anyhow!("checkpoint '{file}': its scene does not load: {e:#}"))?;
    // The scene as run with `over` applied as the command line would.
    let parse = |over: &Overrides| Scene::parse_resolved(&o.scene_source, &o.scene_toml, over);
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
    let ours = checkpoint::build();
    if program != ours {
        eprintln!(
            "warning: checkpoint '{file}' was written by {program}, this is {ours}: the \
             continuation may differ from the run never stopped"
        );
    }
    match duration {
        Some(d) => Ok(parse(&Overrides {
            duration: Some(d),
            ..Default::default()
        })?),
        None => Ok(base),
    }
}
