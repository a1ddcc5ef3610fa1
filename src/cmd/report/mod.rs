//! `cellflip report`: speed against error for every method, scene and resolution.
//!
//! Runs a matrix of (scene, method, resolution, seed) in one process through the one runner
//! ([`measure`]), then writes `report.md` (the paper's tables rebuilt, speed against error,
//! stability, Pareto conclusions), `report.csv` (one row per run, [`measure::COLUMNS`]), plots
//! as PNG and SVG ([`plots`]) and `report.rrd` (every run's time series side by side). A run
//! that fails is a row saying why; Ctrl-C stops the matrix and writes what is done. Every
//! registered method takes part unless `--methods` says otherwise: a new method appears here
//! without changes to this code.

pub mod docs;
pub mod measure;
mod measured;
pub mod options;
mod output;
pub mod plots;
pub mod saved;
pub mod sweep;

use crate::cmd::cli::{Matrix, ReportArgs};
use crate::methods::MethodKind;
use crate::scene::{Overrides, Scene, SceneFile};
use crate::validation::MartinMoyceProbe;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use measure::Measured;
use std::path::{Path, PathBuf};

/// Where a run's scene comes from.
#[derive(Clone, Debug)]
pub enum Source {
    /// A built-in scene or a scene file, by name or path.
    Named(String),
    /// A variant made in code: its label and TOML text.
    Text(String),
}

/// One run of the matrix.
#[derive(Clone, Debug)]
pub struct RunSpec {
    /// The scene as the tables name it (a variant has its own label).
    pub label: String,
    pub source: Source,
    pub method: MethodKind,
    pub res: Option<usize>,
    pub seed: Option<u64>,
    /// Simulated seconds (the scene's duration otherwise).
    pub duration: Option<f64>,
    /// In the accuracy tables, in the stability table.
    pub accuracy: bool,
    pub stability: bool,
    /// Wall seconds the run may take; past them it stops, and its row says so (`--budget`).
    pub budget: Option<f64>,
}

/// A scene of the matrix with the resolutions, duration and tables it is run for.
struct Entry {
    label: String,
    source: Source,
    res: Vec<Option<usize>>,
    duration: Option<f64>,
    accuracy: bool,
    stability: bool,
    /// The methods it is run with, if not all of them.
    methods: Option<&'static [MethodKind]>,
}

impl Entry {
    fn named(name: &str, res: &[usize], accuracy: bool, stability: bool) -> Self {
        Self {
            label: name.to_string(),
            source: Source::Named(name.to_string()),
            res: if res.is_empty() {
                vec![None]
            } else {
                res.iter().map(|&r| Some(r)).collect()
            },
            duration: None,
            accuracy,
            stability,
            methods: None,
        }
    }

    /// Whether it is run with `method`.
    fn runs(&self, method: MethodKind) -> bool {
        self.methods.is_none_or(|m| m.contains(&method))
    }
}

/// The falling obstacle on the paper's largest grid, 200 x 300 x 200 (a scene file kept with
/// the paper-scale benchmarks).
const FALLING_OBSTACLE_PAPER: (&str, &str) = (
    "falling-obstacle-200x300x200",
    include_str!("../../../tools/paper-scale/falling-obstacle-200x300x200.toml"),
);

/// The paper's matrix (docs/cluster.md, "The paper's matrix"): every built-in scene of sec. 8
/// at the size the paper names. The paper's tables of sizes are images, not in its text; the
/// sizes are those its text and its author's driver give: 50 cells per axis in 2D (`res = 50`
/// in `zflip.py`), twice as fine for the 1 ppc dam (fig. dam_2d_1ppc), the spiral's 64 (ours:
/// the channel needs them), the 3D dam at 100^3, the drop at 300^3 ("the LP is solved in 7
/// seconds for a 300^3 grid"), the falling obstacle on 200 x 300 x 200 ("from 46.7 million")
/// and the large obstacle on 50 x 75 x 50. The drop and the falling obstacle are also run at half
/// their size (150^3 and 100 x 150 x 100) with ccp alone, so that the page shows how the
/// paper's tab. time grows with the grid (issue 76).
fn paper_entries() -> Vec<Entry> {
    let mut e: Vec<Entry> = [
        "dam-2d",
        "dam-1ppc-2d",
        "drop-2d",
        "compress-2d",
        "spiral-2d",
        "falling-obstacle-2d",
        "falling-obstacle-zero-bc-2d",
        "large-obstacle-2d",
    ]
    .iter()
    .map(|name| Entry::named(name, &[], true, false))
    .collect();
    e.push(Entry::named("dam-3d", &[100], true, false));
    e.push(Entry::named("drop-3d", &[300], true, false));
    let (label, text) = FALLING_OBSTACLE_PAPER;
    let falling = |res: &[usize]| Entry {
        label: label.into(),
        source: Source::Text(text.into()),
        ..Entry::named(label, res, true, false)
    };
    e.push(falling(&[]));
    const CCP: &[MethodKind] = &[MethodKind::Ccp];
    e.push(Entry {
        methods: Some(CCP),
        ..Entry::named("drop-3d", &[150], true, false)
    });
    e.push(Entry {
        methods: Some(CCP),
        ..falling(&[150])
    });
    e.push(Entry::named("large-obstacle-3d", &[], true, false));
    e
}

/// The default matrix: the paper's scenes for accuracy, its hard cases for stability.
fn default_entries() -> Vec<Entry> {
    vec![
        Entry::named("dam-2d", &[32, 50, 100], true, false),
        Entry::named("dam-1ppc-2d", &[], true, true),
        Entry {
            duration: Some(MartinMoyceProbe::end_time()),
            ..Entry::named("martin-moyce-2d", &[160, 320, 480], true, false)
        },
        Entry {
            duration: Some(1.0),
            ..Entry::named("hydrostatic-2d", &[], true, false)
        },
        Entry::named("compress-2d", &[], true, true),
        Entry::named("falling-obstacle-2d", &[], true, false),
        Entry::named("dam-3d", &[24, 32, 48], true, false),
        // Narrow-band FLIP's scene: deep liquid, where a band of particles pays.
        Entry::named("deep-pool-2d", &[], true, false),
        Entry::named("deep-pool-3d", &[24, 32], true, false),
    ]
}

/// The hard cases of the stability table.
fn stability_entries() -> Result<Vec<Entry>> {
    Ok(vec![
        Entry::named("large-obstacle-2d", &[], false, true),
        emitter_at_speed_limit()?,
        Entry {
            label: "dam-2d, 20 s".into(),
            duration: Some(20.0),
            ..Entry::named("dam-2d", &[], false, true)
        },
    ])
}

/// The 2D dam with its emitter pouring from the start at the scene's speed bound.
fn emitter_at_speed_limit() -> Result<Entry> {
    let (_, text) = crate::scene::BUILT_IN
        .iter()
        .find(|(n, _)| *n == "dam-2d")
        .expect("dam-2d");
    let mut file: SceneFile = toml::from_str(text).context("dam-2d")?;
    let v = file.simulation.max_speed;
    for e in &mut file.emitter {
        e.velocity = vec![0.0, -v];
        e.start = 0.0;
    }
    file.name = "dam-2d-emitter-at-speed-limit".into();
    file.simulation.duration = 3.0;
    Ok(Entry {
        label: file.name.clone(),
        source: Source::Text(toml::to_string(&file).context("dam-2d variant")?),
        ..Entry::named("dam-2d", &[], false, true)
    })
}

/// The runs `args` ask for.
pub fn matrix(args: &ReportArgs) -> Result<Vec<RunSpec>> {
    let (_, stability) = stability(args);
    let mut entries = match (args.scenes.is_empty(), args.matrix.unwrap_or_default()) {
        (true, Matrix::Default) => default_entries(),
        (true, Matrix::Paper) => paper_entries(),
        (false, _) => args
            .scenes
            .iter()
            .map(|s| Entry::named(s, &[], true, stability))
            .collect(),
    };
    if stability && args.scenes.is_empty() {
        entries.extend(stability_entries()?);
    }
    let methods = if args.methods.is_empty() {
        MethodKind::ALL.to_vec()
    } else {
        args.methods.clone()
    };
    let seeds: Vec<Option<u64>> = if args.seeds.is_empty() {
        vec![None]
    } else {
        args.seeds.iter().map(|&s| Some(s)).collect()
    };
    let mut out = vec![];
    for e in &entries {
        let res: Vec<Option<usize>> = if args.res.is_empty() {
            e.res.clone()
        } else {
            args.res.iter().map(|&r| Some(r)).collect()
        };
        for &method in methods.iter().filter(|&&k| e.runs(k)) {
            for &r in &res {
                for &seed in &seeds {
                    let duration = match (e.duration, args.duration) {
                        (Some(a), Some(b)) => Some(a.min(b)),
                        (a, b) => a.or(b),
                    };
                    out.push(RunSpec {
                        label: e.label.clone(),
                        source: e.source.clone(),
                        method,
                        res: r,
                        seed,
                        duration,
                        accuracy: e.accuracy,
                        stability: e.stability,
                        budget: args.budget,
                    });
                }
            }
        }
    }
    Ok(out)
}

/// Whether `args` ask for the default matrix (which runs the stability table's hard cases
/// unless told not to), and whether its runs include those hard cases.
fn stability(args: &ReportArgs) -> (bool, bool) {
    let default = args.scenes.is_empty() && args.matrix.unwrap_or_default() == Matrix::Default;
    (default, args.stability || (default && !args.no_stability))
}

/// Loads a run's scene with its overrides and checks that it fits in the memory this process
/// may take.
pub fn load(spec: &RunSpec) -> Result<Scene> {
    let scene = scene_of(spec)?;
    scene.ensure_fits_in_memory(false)?;
    Ok(scene)
}

/// A run's scene with its overrides, whatever memory this machine has (the plan of a sweep
/// lists jobs for larger ones).
pub fn scene_of(spec: &RunSpec) -> Result<Scene> {
    let o = Overrides {
        method: Some(spec.method),
        cells: spec.res,
        seed: spec.seed,
        duration: spec.duration,
        ..Default::default()
    };
    match &spec.source {
        Source::Named(name) => Ok(Scene::load(name, &o)?),
        Source::Text(text) => Ok(Scene::parse(
            &format!("scene variant '{}'", spec.label),
            text,
            &o,
        )?),
    }
}

/// `cellflip report`: the plan (`--plan`), some jobs (`--job`), the merge of their results
/// (`--merge`), or all three in one process.
pub fn report(args: &ReportArgs) -> Result<()> {
    if !args.merge.is_empty() {
        return merge(&sweep::merged(args, &args.merge)?, &args.merge);
    }
    let specs = matrix(args)?;
    if args.plan {
        sweep::print_plan(&sweep::plan(&specs)?);
        return Ok(());
    }
    // Only the jobs this process runs must fit here: a sweep's others may be a cluster's.
    let jobs = match args.job.is_empty() {
        true => specs.iter().collect(),
        false => sweep::select(&specs, &args.job)?,
    };
    check_loads(&jobs)?;
    // When and at which commit the binary ran, read before the matrix: the checkout may move on
    // during a run of a quarter of an hour.
    let provenance = docs::Provenance::now(&command());
    let docs = docs_target(args)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder '{}'", args.out.display()))?;
    crate::interrupt::install()?;
    let stop = || crate::interrupt::signal().is_some();
    let planned = options::MatrixOptions::of(args);
    run_all(&jobs, &planned, args.quiet, &stop, &args.out);
    let interrupted = stop();
    if args.job.is_empty() {
        // An interrupted matrix would leave the manual with half its runs: keep the pages.
        let to_docs = docs.filter(|_| !interrupted);
        let out = [args.out.clone()];
        write(args, &specs, &out, &provenance, to_docs.as_ref())?;
    }
    if interrupted {
        anyhow::bail!(
            "stopped by {}; the runs that ended are kept in '{}'",
            crate::interrupt::name(crate::interrupt::signal().unwrap_or(0)),
            args.out.display()
        );
    }
    Ok(())
}

/// `--merge DIR[,DIR...]`: the report (with `--docs`, the manual's pages) of the matrix `args`
/// ask for ([`sweep::merged`]) from the results kept in `dirs`, written into the first, nothing
/// run.
fn merge(args: &ReportArgs, dirs: &[PathBuf]) -> Result<()> {
    let provenance = docs::Provenance::now(&command());
    let specs = matrix(args)?;
    write(args, &specs, dirs, &provenance, docs_target(args)?.as_ref())
}

/// With `--docs`, the manual's pages in the folder the command runs from (checked first).
fn docs_target(args: &ReportArgs) -> Result<Option<docs::DocsTarget>> {
    match args.docs {
        true => docs::DocsTarget::at(Path::new("."), args.matrix.unwrap_or_default()).map(Some),
        false => Ok(None),
    }
}

/// Writes the report of the results kept in `dirs` into the first (or the manual's pages),
/// under the provenance line of the machines and builds that ran them, lists the jobs without
/// a result and says where it all went.
fn write(
    args: &ReportArgs,
    specs: &[RunSpec],
    dirs: &[PathBuf],
    provenance: &docs::Provenance,
    docs: Option<&docs::DocsTarget>,
) -> Result<()> {
    let (results, missing) = sweep::gather(dirs, specs, &options::MatrixOptions::of(args))?;
    let dir = &dirs[0];
    let header = provenance.line(&results);
    for (spec, why) in &missing {
        eprintln!(
            "missing: {} {} {}: {why}",
            spec.label,
            spec.method.name(),
            spec.res.map_or("(scene's)".into(), |r| r.to_string())
        );
    }
    let not_run = sweep::not_run(&missing)?;
    match docs {
        Some(target) => {
            write_docs(target, specs, &results, &header, &not_run)?;
            keep_results(target, &results, &options::MatrixOptions::of(args))?;
        }
        None => write_all(dir, specs, &results, &header, &not_run)?,
    }
    if !args.quiet {
        let failed = results.iter().filter(|m| !m.ok());
        crate::outln!(
            "report: {} of {} runs ({} failed, {} missing) written to {}",
            results.len(),
            specs.len(),
            failed.count(),
            missing.len(),
            match docs {
                Some(t) => format!(
                    "{}, {}{}",
                    t.page.display(),
                    t.plots.display(),
                    t.readme
                        .as_ref()
                        .map_or(String::new(), |r| format!(" and {}", r.display()))
                ),
                None => dir.display().to_string(),
            }
        );
    }
    Ok(())
}

/// Every run's scene loads: an unknown scene, an unreadable or malformed file and an impossible
/// resolution stop the report before any run, with nothing written (each reason once).
fn check_loads(specs: &[&RunSpec]) -> Result<()> {
    let mut reasons: Vec<String> = vec![];
    for spec in specs {
        if let Err(e) = load(spec) {
            let reason = format!("{e:#}");
            if !reasons.contains(&reason) {
                reasons.push(reason);
            }
        }
    }
    match reasons.as_slice() {
        [] => Ok(()),
        [one] => anyhow::bail!("{one}"),
        all => anyhow::bail!(
            "{} of the report's scenes cannot run:\n  {}",
            all.len(),
            all.join("\n  ")
        ),
    }
}

/// Runs `jobs` in order with a progress bar, until done or stopped, each kept under `out`
/// with the `matrix` it was planned from: a job whose result is there is skipped, one stopped
/// midway goes on from its checkpoint.
pub fn run_all(
    jobs: &[&RunSpec],
    matrix: &options::MatrixOptions,
    quiet: bool,
    stop: &dyn Fn() -> bool,
    out: &Path,
) {
    let bar = ProgressBar::with_draw_target(Some(jobs.len() as u64), ProgressDrawTarget::stderr());
    if quiet {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    let style = ProgressStyle::with_template(
        "{bar:30} {pos}/{len} runs  {msg}  elapsed {elapsed}  ETA {eta}",
    )
    .expect("a valid progress template");
    bar.set_style(style);
    for &spec in jobs {
        if stop() {
            break;
        }
        bar.set_message(format!(
            "{} {} {}",
            spec.label,
            spec.method.name(),
            spec.res.map_or(String::new(), |r| r.to_string())
        ));
        let files = saved::RunFiles::of(out, spec, matrix);
        match saved::load_result(&files.result, spec) {
            Ok(Some(m)) if m.ours() => {
                bar.inc(1);
                continue;
            }
            Ok(Some(m)) => bar.suspend(|| {
                let file = files.result.display();
                eprintln!(
                    "warning: '{file}' kept by another build ({}); running it again",
                    m.build
                )
            }),
            Ok(None) => {}
            Err(e) => bar.suspend(|| eprintln!("warning: {e:#}; running it again")),
        }
        let resumed = measure::resumable(&files.checkpoints);
        if let (Some(c), false) = (&resumed, quiet) {
            let (name, file) = (spec.method.name(), c.path.display());
            bar.suspend(|| {
                eprintln!(
                    "resuming {} {name} from '{file}' (step {})",
                    spec.label, c.step
                )
            });
        }
        let m = measure::run(spec, stop, Some(&files), resumed);
        // A run that could not start is a result too (a row that says why); one a signal
        // stopped is not, and goes on from its checkpoint next time.
        if m.status != "interrupted" && !files.result.exists() {
            if let Err(e) = saved::save_result(&files, &m) {
                bar.suspend(|| eprintln!("warning: {e:#}"));
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
}

/// Writes every output, naming the file that could not be written; `not_run` closes
/// report.md.
fn write_all(
    dir: &Path,
    specs: &[RunSpec],
    results: &[Measured],
    header: &str,
    not_run: &str,
) -> Result<()> {
    let csv = dir.join("report.csv");
    std::fs::write(&csv, output::csv(results))
        .with_context(|| format!("cannot write '{}'", csv.display()))?;
    let figures = plots::all(dir, results, true)?;
    let md = dir.join("report.md");
    let text = output::markdown(specs, results, &figures, "cellflip report", header) + not_run;
    std::fs::write(&md, text).with_context(|| format!("cannot write '{}'", md.display()))?;
    let rrd = dir.join("report.rrd");
    crate::record::write_comparison(&rrd, &measure::comparison_series(results))
        .with_context(|| format!("cannot write '{}'", rrd.display()))?;
    Ok(())
}

/// The command line as typed after `cellflip`.
fn command() -> String {
    std::env::args().skip(1).collect::<Vec<_>>().join(" ")
}

/// `--docs`: the manual's results page, its plots and CSV, and the README's headline table,
/// all under one provenance line.
fn write_docs(
    target: &docs::DocsTarget,
    specs: &[RunSpec],
    results: &[Measured],
    header: &str,
    not_run: &str,
) -> Result<()> {
    let csv = target.plots.join("report.csv");
    std::fs::write(&csv, output::csv(results))
        .with_context(|| format!("cannot write '{}'", csv.display()))?;
    let figures: Vec<String> = plots::all(&target.plots, results, false)?
        .into_iter()
        .map(|f| format!("{}/{f}", target.plots_name))
        .collect();
    let mut text = output::markdown(specs, results, &figures, "Results", header);
    text += not_run;
    for f in &figures {
        text += &format!("![{f}]({f})\n\n");
    }
    std::fs::write(&target.page, text)
        .with_context(|| format!("cannot write '{}'", target.page.display()))?;
    target.write_headline(&docs::headline(results, header))
}

/// `--docs`: the page's results kept beside it in `docs/<page>/runs/`, as `--out` keeps them,
/// and no others: the repository holds what its page was made from, so that any checkout
/// merges it again (`--merge NEW,docs/results-paper` puts new results before them) when the
/// folders that ran its jobs are gone with their machine (docs/cluster.md, "Plan, job, merge").
fn keep_results(
    target: &docs::DocsTarget,
    results: &[Measured],
    matrix: &options::MatrixOptions,
) -> Result<()> {
    let kept: Vec<PathBuf> = results
        .iter()
        .map(|m| {
            let files = saved::RunFiles::of(&target.plots, &m.spec, matrix);
            saved::save_result(&files, m).map(|()| files.result)
        })
        .collect::<Result<_>>()?;
    for old in sweep::result_files(&target.plots) {
        if !kept.contains(&old) {
            std::fs::remove_file(&old)
                .with_context(|| format!("cannot remove '{}'", old.display()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::Machine;
    use options::tests::args;

    /// A merge names the machines that ran its jobs, as each result keeps its own, not the one
    /// that merges them; a result kept before results recorded their machine still merges,
    /// "on a machine not recorded".
    #[test]
    fn a_merge_names_the_machines_that_ran_its_jobs() {
        let dir = std::env::temp_dir().join(format!("cellflip-merge-{}", std::process::id()));
        let line = "--scenes dam-2d --methods flip,ccp,idp --res 24 --duration 0.05 -q --merge";
        let args = args(&format!("{line} {}", dir.display()));
        let specs = matrix(&args).unwrap();
        let node = |cpu: &str, copy_gb_s| {
            Some(Machine {
                cpu: cpu.into(),
                cores: 64,
                threads: 8,
                copy_gb_s,
            })
        };
        let machines = [node("node-a", 30.0), node("node-b", 12.5), None];
        for (spec, machine) in specs.iter().zip(machines) {
            let files = saved::RunFiles::of(&dir, spec, &options::MatrixOptions::of(&args));
            let m = Measured {
                status: "ok".into(),
                machine,
                ..Measured::new(spec)
            };
            saved::save_result(&files, &m).unwrap();
        }
        report(&args).unwrap();
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        let line = md.lines().find(|l| l.starts_with("Generated ")).unwrap();
        let on = " on several machines (1 job on node-a (64 cores, 8 threads, memory copy 30.0 \
                  GB/s), 1 job on node-b (64 cores, 8 threads, memory copy 12.5 GB/s), 1 job on a \
                  machine not recorded) by `cellflip ";
        assert!(line.contains(on), "{line}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A merge of two folders takes each job's result from the first that has one, whichever
    /// build kept it, and names the builds (the jobs of all but the one with the most); a
    /// result without its grid's cells takes its scene's; a report run again over another
    /// build's result runs it again.
    #[test]
    fn a_merge_of_several_folders_names_the_builds_that_ran_its_jobs() {
        let base = std::env::temp_dir().join(format!("cellflip-builds-{}", std::process::id()));
        let (a, b) = (base.join("a"), base.join("b"));
        let line = "--scenes dam-2d --methods flip,ccp,idp --res 24 --duration 0.05 -q";
        let merged = args(&format!("{line} --merge {},{}", a.display(), b.display()));
        let specs = matrix(&merged).unwrap();
        let matrix_options = options::MatrixOptions::of(&merged);
        let keep = |dir: &Path, spec: &RunSpec, build: &str, steps: f64| {
            let m = Measured {
                status: "ok".into(),
                build: build.into(),
                values: [("steps".to_string(), steps)].into(),
                ..Measured::new(spec)
            };
            saved::save_result(&saved::RunFiles::of(dir, spec, &matrix_options), &m).unwrap();
        };
        let (old, older) = ("cellflip 0.0.9 (0000aaaa)", "cellflip 0.0.8 (0000bbbb)");
        keep(&a, &specs[0], old, 1.0);
        keep(&a, &specs[1], old, 2.0);
        keep(&b, &specs[1], older, 3.0);
        keep(&b, &specs[2], older, 4.0);
        report(&merged).unwrap();
        let md = std::fs::read_to_string(a.join("report.md")).unwrap();
        let said = md.lines().find(|l| l.starts_with("Generated ")).unwrap();
        let builds = "Its runs are of 2 builds of cellflip (version and CRC-32 of the \
                      executable): 2 jobs of cellflip 0.0.9 (0000aaaa); 1 job of cellflip 0.0.8 \
                      (0000bbbb): dam-2d idp 24.";
        assert!(said.ends_with(builds), "{said}");
        let csv = std::fs::read_to_string(a.join("report.csv")).unwrap();
        let rows: Vec<&str> = csv.lines().skip(1).collect();
        assert_eq!(rows.len(), 3, "{csv}");
        assert!(rows[1].contains(old) && rows[2].contains(older), "{csv}");
        // Kept without their grid's cells (as results before 87cfc95), they take the scene's.
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        let at = header.iter().position(|c| *c == "grid_cells").unwrap();
        // Counted from the end: the machine's column before it is quoted and holds commas.
        let from_end = header.len() - 1 - at;
        let cells: Vec<&str> = (rows.iter())
            .map(|r| r.rsplit(',').nth(from_end).unwrap())
            .collect();
        assert_eq!(cells, ["576.0"; 3], "{csv}");

        let flip = "--scenes dam-2d --methods flip --res 24 --duration 0.05 -q";
        let run_again = args(&format!("{flip} --out {}", a.display()));
        report(&run_again).unwrap();
        let files = saved::RunFiles::of(&a, &specs[0], &options::MatrixOptions::of(&run_again));
        let kept = saved::load_result(&files.result, &specs[0])
            .unwrap()
            .unwrap();
        assert!(kept.ours() && kept.get("steps") > 1.0, "{}", kept.build);
        std::fs::remove_dir_all(&base).unwrap();
    }
}
