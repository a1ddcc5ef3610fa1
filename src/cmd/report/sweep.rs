//! The report as a sweep of independent jobs (docs/cluster.md): the plan of the matrix's jobs
//! with their memory and cost, the selection of jobs to run, and the merge of their results.
//! A job is one run of the matrix, kept under `--out` as `runs/<id>.result` ([`super::saved`]);
//! the one-process report runs every job and then merges, so both paths share this code. Each
//! result keeps the matrix it was planned from ([`super::options`]): a merge without matrix
//! options merges that matrix.

use super::measured::Measured;
use super::options::{shell_word, MatrixOptions};
use super::saved::{self, RunFiles};
use super::{scene_of, RunSpec};
use crate::cmd::cli::ReportArgs;
use crate::methods::Unit;
use crate::scene::{MemoryEstimate, Scene};
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Threads a job runs with on the machine the cost model was fitted on (2 cores): its
/// CPU-seconds are its wall seconds times these.
pub const FITTED_THREADS: f64 = 2.0;

/// One job of the plan: its run and what it is estimated to need.
#[derive(Clone, Debug)]
pub struct Job<'a> {
    pub id: String,
    pub spec: &'a RunSpec,
    pub cells: usize,
    /// What the cost model counts of the liquid on average over the run ([`cost`]): the
    /// particles the method holds, or the liquid's cells, its driven share twice for some, a
    /// share of them at rest.
    pub particles: f64,
    pub seed: u64,
    /// The up-front memory estimate the run is admitted on, MiB.
    pub mib: f64,
    /// Simulated seconds, and the estimated steps and CPU-seconds ([`cost`]).
    pub sim_secs: f64,
    pub steps: f64,
    pub cpu_secs: f64,
}

/// The jobs of the matrix, each scene loaded for its size, memory and cost (larger than this
/// machine, too: the plan is for wherever they run).
pub fn plan(specs: &[RunSpec]) -> Result<Vec<Job<'_>>> {
    specs
        .iter()
        .map(|spec| {
            let scene = scene_of(spec)?;
            let estimate = scene.memory_estimate(false);
            let (particles, steps, step_secs) = cost(&scene, &estimate);
            Ok(Job {
                id: saved::id(spec),
                spec,
                cells: estimate.cells,
                particles,
                seed: scene.file.simulation.seed,
                mib: estimate.mib(),
                sim_secs: scene.duration_secs(),
                steps,
                cpu_secs: steps * step_secs * FITTED_THREADS,
            })
        })
        .collect()
}

/// The cost model (docs/cluster.md, "The cost model"): the units of the liquid it counts, the
/// steps the run takes ([`steps`]) and the wall seconds of one, for the run of `scene` that
/// `estimate` sizes: the method's [`crate::methods::StepCost`] for the units it counts on
/// average over the run (the particles it holds or the liquid's cells, [`Unit`]; the average,
/// not the memory estimate's most, `held_most`, which counts an emitter's particles from the
/// start), its driven share twice where the method says so, a share of them for a liquid at
/// rest ([`crate::methods::Rest`], [`crate::methods::StepCost::rest_share`]), and the grid's
/// cells.
pub fn cost(scene: &Scene, estimate: &MemoryEstimate) -> (f64, f64, f64) {
    let step = scene.method.step_cost(scene.dim());
    let units = match step.unit {
        Unit::Particle => estimate.held_mean,
        Unit::LiquidCell => estimate.liquid_cells_mean,
    };
    let driven = match step.driven_twice {
        true => 1.0 + estimate.driven_share,
        false => 1.0,
    };
    let units = units * driven * step.rest_share(estimate.rest);
    let cells = estimate.cells as f64;
    (units, steps(scene, estimate), step.step_secs(units, cells))
}

/// The steps a run of `scene` takes: each as long as the smaller of `max_dt` and the time to
/// cross `cfl` cells at the liquid's speed, the fastest of an emitter's, an obstacle's and that
/// of a fall from the seeded liquid's top (or a falling obstacle's bottom) to the liquid's level
/// at rest, `sqrt(2 g fall)` (`estimate.fall_m`; a dam's front runs at about that, a pool at
/// rest not at all).
///
/// On the default matrix (2026-11-29, 480cee2) this is 0.8x (martin-moyce-2d, compress-2d) to
/// 1.4x (deep-pool-2d, whose ball falls once; dam-3d at 48^3) the steps FLIP took; the height
/// of the whole tank (`sqrt(g H)`, before) over-counted every scene whose liquid falls less than
/// the tank's height, up to 1.9x (deep-pool-2d; the falling obstacles and drop-2d 1.6x).
fn steps(scene: &Scene, estimate: &MemoryEstimate) -> f64 {
    let f = &scene.file;
    let longest = f.domain.size.iter().copied().fold(0.0, f64::max);
    let h = longest / f.domain.cells as f64;
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let g = (f.simulation.gravity.as_deref()).map_or(9.81, norm);
    let poured = (f.emitter.iter().map(|e| &e.velocity))
        .chain(f.obstacle.iter().map(|o| &o.velocity))
        .map(|v| norm(v))
        .fold(0.0, f64::max);
    let speed = (2.0 * g * estimate.fall_m).sqrt().max(poured);
    let dt = (f.simulation.max_dt).min(f.simulation.cfl * h / speed.max(1e-9));
    (scene.duration_secs() / dt).ceil()
}

/// Prints the plan: a line per job, then the totals, every line but the jobs' starting with
/// `#` (so that `grep -v '^#'` leaves the jobs, their id first).
pub fn print_plan(jobs: &[Job<'_>]) {
    crate::outln!(
        "# {:<44} {:<24} {:<8} {:>10} {:>11} {:>5} {:>9} {:>7} {:>8} {:>10}",
        "id",
        "scene",
        "method",
        "cells",
        "particles",
        "seed",
        "mem_mib",
        "sim_s",
        "steps",
        "cpu_s"
    );
    for j in jobs {
        crate::outln!(
            "{:<46} {:<24} {:<8} {:>10} {:>11.0} {:>5} {:>9.0} {:>7} {:>8.0} {:>10.2}",
            j.id,
            j.spec.label,
            j.spec.method.name(),
            j.cells,
            j.particles,
            j.seed,
            j.mib,
            j.sim_secs,
            j.steps,
            j.cpu_secs
        );
    }
    let total: f64 = jobs.iter().map(|j| j.cpu_secs).sum();
    if let Some(big) = jobs.iter().max_by(|a, b| a.mib.total_cmp(&b.mib)) {
        crate::outln!(
            "# {} jobs, about {:.2} CPU-hours in all; the largest memory estimate {:.0} MiB ({})",
            jobs.len(),
            total / 3600.0,
            big.mib,
            big.id
        );
    }
    crate::outln!(
        "# cpu_s: estimated CPU-seconds ({FITTED_THREADS} threads x wall seconds on the machine \
         the model was fitted on; docs/cluster.md)"
    );
}

/// The specs `ids` name, in the plan's order; an id not in the plan is an error that says
/// how to list them.
pub fn select<'a>(specs: &'a [RunSpec], ids: &[String]) -> Result<Vec<&'a RunSpec>> {
    let known: Vec<String> = specs.iter().map(saved::id).collect();
    if let Some(bad) = ids.iter().find(|id| !known.contains(id)) {
        bail!(
            "--job {bad}: no such job in this matrix ({} jobs; `cellflip report` with the same \
             matrix options and --plan lists their ids)",
            known.len()
        );
    }
    Ok(specs
        .iter()
        .zip(&known)
        .filter(|(_, id)| ids.contains(id))
        .map(|(s, _)| s)
        .collect())
}

/// The report's section on the jobs without a result: each with why, its memory estimate and
/// its estimated cost, and their totals (empty when every job has one).
pub fn not_run(missing: &[Missing<'_>]) -> Result<String> {
    if missing.is_empty() {
        return Ok(String::new());
    }
    let specs: Vec<RunSpec> = missing.iter().map(|(s, _)| (*s).clone()).collect();
    let jobs = plan(&specs)?;
    let mut s = format!(
        "## Not run\n\n{} jobs of the matrix have no result; their estimates are the plan's \
         (`--plan`, docs/cluster.md).\n\n| scene | grid cells | method | why | memory MiB | estimated CPU-s |\n|---|---|---|---|---|---|\n",
        jobs.len()
    );
    for (j, (_, why)) in jobs.iter().zip(missing) {
        s += &format!(
            "| {} | {} | {} | {why} | {:.0} | {:.0} |\n",
            j.spec.label,
            j.cells,
            j.spec.method.name(),
            j.mib,
            j.cpu_secs
        );
    }
    let total: f64 = jobs.iter().map(|j| j.cpu_secs).sum();
    s += &format!("\nIn all about {:.1} CPU-hours.\n\n", total / 3600.0);
    Ok(s)
}

/// A job without a result, and why (not run, or its file cannot be taken).
pub type Missing<'a> = (&'a RunSpec, String);

/// The results of the matrix's jobs kept in `dirs`, in the plan's order (each job's from the
/// first folder that has one, by whichever build), and the jobs that have none. Fails when
/// there is none at all, naming the command that merges each matrix of the results there
/// (`matrix` is the one asked for, that of `specs`).
pub fn gather<'a>(
    dirs: &[PathBuf],
    specs: &'a [RunSpec],
    matrix: &MatrixOptions,
) -> Result<(Vec<Measured>, Vec<Missing<'a>>)> {
    let (mut results, mut missing) = (vec![], vec![]);
    for spec in specs {
        let mut why = vec![];
        let found = dirs.iter().find_map(|dir| {
            let files = RunFiles::of(dir, spec, matrix);
            match saved::load_result(&files.result, spec) {
                Ok(found) => found,
                Err(e) => {
                    why.push(format!("{e:#}"));
                    None
                }
            }
        });
        match found {
            Some(m) => results.push(with_grid_cells(m)),
            None if why.is_empty() => missing.push((spec, under_way(dirs, spec, matrix))),
            None => missing.push((spec, why.join("; "))),
        }
    }
    if !results.is_empty() {
        return Ok((results, missing));
    }
    let kept = kept_matrices(dirs);
    let none = format!(
        "--merge {}: no result of this matrix's {} jobs ({matrix}) in {}",
        folders(dirs),
        specs.len(),
        in_runs(dirs)
    );
    if !kept.is_empty() {
        let others = match kept.len() {
            1 => "another matrix".to_string(),
            n => format!("{n} other matrices"),
        };
        bail!(
            "{none}; the results there are of {others}, merged with:\n{}",
            commands(dirs, &kept)
        );
    }
    let there: usize = dirs.iter().map(|d| result_files(d).len()).sum();
    bail!("{none} ({} there, damaged)", counted(there))
}

/// Why a job has no result in `dirs`: "under way" with the step of its newest checkpoint in
/// the first folder that has one (a long job stopped between sittings, or running), else "not
/// run".
fn under_way(dirs: &[PathBuf], spec: &RunSpec, matrix: &MatrixOptions) -> String {
    let step = dirs.iter().find_map(|dir| {
        let checkpoints = RunFiles::of(dir, spec, matrix).checkpoints;
        checkpoints
            .is_dir()
            .then(|| crate::checkpoint::open(&checkpoints).ok())?
    });
    step.map_or("not run".into(), |c| {
        format!("under way (checkpoint after step {})", c.step)
    })
}

/// `m` with its grid's cells: a result kept before results recorded them (before `87cfc95`)
/// takes them from its scene at its size, as the run had them.
fn with_grid_cells(mut m: Measured) -> Measured {
    if !m.values.contains_key("grid_cells") {
        if let Ok(scene) = scene_of(&m.spec) {
            let cells = scene.dims.iter().product::<usize>() as f64;
            m.values.insert("grid_cells".into(), cells);
        }
    }
    m
}

/// The report `--merge DIR[,DIR...]` writes, as options: those given or, without any, those of
/// the matrix the folders' results were planned from. Refuses results of several matrices
/// then, naming the command that merges each.
pub fn merged(args: &ReportArgs, dirs: &[PathBuf]) -> Result<ReportArgs> {
    let kept = kept_matrices(dirs);
    let mut matrices = kept.keys();
    match (MatrixOptions::given(args), matrices.next(), matrices.next()) {
        (true, _, _) | (false, None, _) => Ok(args.clone()),
        (false, Some(one), None) => one.apply(args).with_context(|| {
            format!(
                "--merge {}: its results are of the matrix {one}",
                folders(dirs)
            )
        }),
        (false, Some(_), Some(_)) => bail!(
            "--merge {}: its results are of {} matrices; name one with its options:\n{}",
            folders(dirs),
            kept.len(),
            commands(dirs, &kept)
        ),
    }
}

/// The matrices the results in `dirs` were planned from, with how many results each.
fn kept_matrices(dirs: &[PathBuf]) -> BTreeMap<MatrixOptions, usize> {
    let mut kept = BTreeMap::new();
    for path in dirs.iter().flat_map(|d| result_files(d)) {
        if let Some(m) = saved::matrix_of(&path) {
            *kept.entry(m).or_default() += 1;
        }
    }
    kept
}

/// The folders as `--merge` takes them: `a,b`.
fn folders(dirs: &[PathBuf]) -> String {
    let names: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    names.join(",")
}

/// Where the results of `dirs` are kept: `'a/runs'` or `'a/runs' or 'b/runs'`.
fn in_runs(dirs: &[PathBuf]) -> String {
    let each: Vec<String> = (dirs.iter())
        .map(|d| format!("'{}'", d.join("runs").display()))
        .collect();
    each.join(" or ")
}

/// The result files under `dir/runs`.
pub fn result_files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir.join("runs")) else {
        return vec![];
    };
    let paths = entries.flatten().map(|e| e.path());
    paths
        .filter(|p| p.extension().is_some_and(|x| x == "result"))
        .collect()
}

/// The command that merges each of the `kept` matrices in `dirs`, a line each with its count.
fn commands(dirs: &[PathBuf], kept: &BTreeMap<MatrixOptions, usize>) -> String {
    let dir = shell_word(&folders(dirs));
    let line = |(m, n): (&MatrixOptions, &usize)| {
        format!("  cellflip report --merge {dir} {m}    ({})", counted(*n))
    };
    kept.iter().map(line).collect::<Vec<_>>().join("\n")
}

/// `1 result`, `2 results`.
fn counted(n: usize) -> String {
    format!("{n} result{}", if n == 1 { "" } else { "s" })
}
