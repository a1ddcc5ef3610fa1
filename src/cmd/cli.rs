//! Command-line definitions (clap) and nothing else. The library below takes plain enums and
//! numbers: where a flag's values are one of its enums, a mirror here names and explains them
//! for `--help` and maps onto it (`PreconditionerArg` onto `Preconditioner`, ...); the methods'
//! own flags come from their folders (`crate::methods::options`).

use crate::methods::ccp::{BandMode, Solver};
use crate::methods::{MethodFlags, MethodKind};
use crate::record::{parse_memory_limit, Moves};
use crate::solvers::pcg::Preconditioner;
use crate::stages::solids::ObstacleMode;
use clap::{Args, Parser, Subcommand};
use std::net::IpAddr;
use std::path::PathBuf;

/// cellflip: cell-constrained particles for incompressible fluids (Z. Levi), and the methods
/// it is compared with, in 2D and 3D. Runs write Rerun recordings (.rrd).
#[derive(Parser, Debug)]
#[command(name = "cellflip", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// List the built-in scenes, one per line.
    List,
    /// Run a scene and write a Rerun recording.
    Run(RunArgs),
    /// Run several methods on one scene into one recording: their worlds side by side, drawn
    /// at the same simulated times, with their volumes and kinetic energies in one plot.
    Compare(CompareArgs),
    /// Measure per-stage step times, peak memory and (ccp) the solvers on a scene.
    Bench(BenchArgs),
    /// Compare with experiment: Martin & Moyce's dam break and water at rest.
    Validate(ValidateArgs),
    /// Speed against error: every method on a matrix of scenes, resolutions and seeds, with
    /// tables (report.md, report.csv), plots (PNG, SVG) and a comparison recording.
    Report(ReportArgs),
    /// Open saved recordings (a run's, a comparison's, the report's): in a browser with
    /// --serve-web, else in the native viewer if `rerun` is on the PATH.
    View(ViewArgs),
    /// Time the correction's solvers on exported problems (`run --export-lp`), the same files
    /// a peer solver (HiGHS, LEMON) reads, and check their optimum.
    Solve(SolveArgs),
}

#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// A built-in scene (see `cellflip list`) or a scene file.
    pub scene: String,
    /// The runs, comma-separated: a method, or a method and its obstacle mode
    /// (`flip:naive,flip:ignore,idp:naive,ccp`) [default: every method].
    #[arg(long, value_delimiter = ',', value_parser = parse_compared)]
    pub methods: Vec<(MethodKind, Option<ObstacleMode>)>,
    /// Simulated seconds between the frames drawn (particles, cells, labels); every run is
    /// drawn at the first of its steps that reaches each frame's time.
    #[arg(long, value_name = "SECS", default_value_t = 0.04)]
    pub frame_dt: f64,
    /// Duration, resolution, particles per cell and seed, the same for every run.
    #[command(flatten)]
    pub scale: SceneArgs,
    /// 3D: do not draw the liquid's surfaces (meshes, over the particles).
    #[arg(long)]
    pub no_surface: bool,
    /// Frames for a renderer.
    #[command(flatten)]
    pub export: ExportArgs,
    /// Where the recording goes [default: recordings/<scene>-compare.rrd].
    #[command(flatten)]
    pub sink: SinkArgs,
    /// Serving it to browsers.
    #[command(flatten)]
    pub serve: ServeArgs,
    /// With --connect: run even when no viewer answers at the URL at the start (by default
    /// that stops the command at once, exit 1, nothing run).
    #[arg(long, requires = "connect")]
    pub no_viewer_check: bool,
    /// No progress bar and no summaries.
    #[arg(long, short)]
    pub quiet: bool,
}

/// A positive, finite number of seconds.
fn positive_secs(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("'{s}' is not a positive number of seconds")),
    }
}

/// The scene values `run` and `compare` override.
#[derive(Args, Debug, Clone, Default)]
pub struct SceneArgs {
    /// Simulated seconds to run (overrides the scene's `simulation.duration`).
    #[arg(long, allow_hyphen_values = true)]
    pub duration: Option<f64>,
    /// Cells along the longest axis (overrides `domain.cells`).
    #[arg(long)]
    pub res: Option<usize>,
    /// Particles per cell, mu = k^dim (overrides `simulation.ppc`).
    #[arg(long)]
    pub ppc: Option<usize>,
    /// Random seed (overrides `simulation.seed`).
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Frames for a renderer, for `run` and `compare`.
#[derive(Args, Debug, Clone, Default)]
pub struct ExportArgs {
    /// Also write every drawn frame into DIR as PLY files a renderer reads: the particles (3D:
    /// and the liquid's surface, a mesh with normals), in metres, y up, named
    /// <scene>_<method>_f<frame>_t<time>s_{particles,surface}.ply.
    #[arg(long, value_name = "DIR")]
    pub export_frames: Option<PathBuf>,
}

/// `method[:obstacle]`, as `--methods` takes it.
fn parse_compared(s: &str) -> Result<(MethodKind, Option<ObstacleMode>), String> {
    use clap::ValueEnum;
    let (m, o) = match s.split_once(':') {
        Some((m, o)) => (m, Some(o)),
        None => (s, None),
    };
    let method = MethodKind::from_str(m, false).map_err(|_| {
        let names: Vec<&str> = MethodKind::ALL.iter().map(|k| k.name()).collect();
        format!("unknown method '{m}' (methods: {})", names.join(", "))
    })?;
    let obstacle = o
        .map(|o| {
            ObstacleArg::from_str(o, false)
                .map(ObstacleMode::from)
                .map_err(|_| format!("unknown obstacle mode '{o}' (couple, naive or ignore)"))
        })
        .transpose()?;
    Ok((method, obstacle))
}

/// Where a recording goes, as Rerun's own examples take it (`rerun::clap::RerunArgs`), and by
/// default a file under `recordings/`. At most one.
#[derive(Args, Debug, Clone, Default)]
#[group(multiple = false)]
pub struct SinkArgs {
    /// Write the recording to this .rrd file [default: recordings/<scene>.rrd].
    #[arg(long, visible_alias = "out", value_name = "PATH")]
    pub save: Option<PathBuf>,
    /// Start a Rerun viewer (`rerun` on the PATH: pip install rerun-sdk==0.36.3) and stream
    /// the run to it as it goes; no file is written.
    #[arg(long, conflicts_with = "serve_web")]
    pub spawn: bool,
    /// Stream the run as it goes to a viewer already running [default URL:
    /// rerun+http://127.0.0.1:9876/proxy].
    #[arg(long, value_name = "URL", num_args = 0..=1, conflicts_with = "serve_web")]
    pub connect: Option<Option<String>>,
    /// Write the recording to standard output, for `| rerun -`; the summary goes to
    /// standard error.
    #[arg(long, conflicts_with = "serve_web")]
    pub stdout: bool,
    /// Do not record.
    #[arg(long, conflicts_with = "serve_web")]
    pub no_record: bool,
}

/// Serving a recording to browsers (Rerun's web viewer), for `run`, `compare` and `view`
/// (docs/cli.md, "In a browser").
#[derive(Args, Debug, Clone)]
pub struct ServeArgs {
    /// Serve Rerun's web viewer over HTTP on PORT and the recording to it, so that a browser
    /// shows the run as it goes (print the URL to open); serving goes on after the run until
    /// Ctrl-C. No file is written unless --save PATH is given too [default PORT: 9090].
    #[arg(long, value_name = "PORT", num_args = 0..=1, default_missing_value = "9090")]
    pub serve_web: Option<u16>,
    /// With --serve-web: the port of the recording's gRPC server, which the page connects to.
    #[arg(
        long,
        value_name = "PORT",
        default_value_t = 9876,
        requires = "serve_web"
    )]
    pub grpc_port: u16,
    /// With --serve-web: the address both servers listen on. Any other than a loopback one
    /// serves the run to other machines (a warning says so) and lets pages from that address
    /// (from any, for 0.0.0.0) read the recording.
    #[arg(
        long,
        value_name = "ADDR",
        default_value = "127.0.0.1",
        requires = "serve_web"
    )]
    pub bind: IpAddr,
    /// With --serve-web: how much of the recording the gRPC server keeps for browsers that
    /// open the page late, a size (1GiB, 500MB) or a share of the machine's memory (25%); past
    /// it the oldest steps are dropped (static data never). 1 GiB holds a whole built-in run.
    #[arg(long, value_name = "SIZE", default_value = "1GiB", value_parser = parse_memory_limit, requires = "serve_web")]
    pub server_memory_limit: String,
}

#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// Recordings (.rrd) to open together.
    #[arg(required = true, value_name = "REC.rrd")]
    pub recordings: Vec<PathBuf>,
    /// Serving them to browsers.
    #[command(flatten)]
    pub serve: ServeArgs,
}

#[derive(Args, Debug, Clone)]
pub struct SolveArgs {
    /// MPS files written by `run --export-lp`.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Solvers, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Solver::Flow])]
    pub solver: Vec<Solver>,
    /// Solves per file and solver; the median time is printed.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    pub repeat: u64,
}

#[derive(Args, Debug, Clone)]
pub struct ReportArgs {
    /// Which scenes and sizes: `default` (the paper's scenes at small sizes and the hard
    /// cases, about 15 minutes on 2 cores) or `paper` (every scene of the paper's sec. 8 at
    /// the size the paper names, whole runs: hours to days, a sweep for a cluster;
    /// docs/cluster.md). --scenes replaces either [default: default]
    #[arg(long, value_enum)]
    pub matrix: Option<Matrix>,
    /// Scenes (built-in names or .toml paths), comma-separated [default: the --matrix's]
    #[arg(long, value_delimiter = ',', conflicts_with = "matrix")]
    pub scenes: Vec<String>,
    /// Methods, comma-separated [default: every method]
    #[arg(long, value_enum, value_delimiter = ',')]
    pub methods: Vec<MethodKind>,
    /// Resolutions (cells along the longest axis), comma-separated; every scene runs at each
    /// [default: the --matrix's for each scene]
    #[arg(long, value_delimiter = ',')]
    pub res: Vec<usize>,
    /// Seeds, comma-separated; every run is repeated with each [default: the scene's]
    #[arg(long, value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// Simulated seconds per run at most (quick looks) [default: each scene's]
    #[arg(long)]
    pub duration: Option<f64>,
    /// Also run the hard cases for the stability table (on by default without --scenes)
    #[arg(long, conflicts_with = "no_stability")]
    pub stability: bool,
    /// Leave out the stability runs
    #[arg(long)]
    pub no_stability: bool,
    /// Wall seconds each run may take; a run past them stops and its row says so, "over
    /// budget" (the others are unaffected) [default: no limit]
    #[arg(long, value_name = "SECS", value_parser = positive_secs)]
    pub budget: Option<f64>,
    /// Output folder
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
    /// Regenerate the manual's results: the matrix with every method, written to
    /// docs/results.md, docs/results/ (PNG plots, report.csv) and README.md's headline table
    /// (with --matrix paper: docs/results-paper.md and docs/results-paper/), each headed by the
    /// date, commit, machine and command. Run from the repository's root; if interrupted, the
    /// runs done go to --out and the docs are left as they were
    #[arg(long, conflicts_with_all = ["scenes", "methods", "res", "seeds", "duration", "stability", "no_stability"])]
    pub docs: bool,
    /// Print the matrix's jobs, one line each (id, scene, method, cells, particles, seed,
    /// memory estimate, estimated CPU-seconds), and their totals; nothing is run. The lines of
    /// the jobs are those not starting with '#' (docs/cluster.md)
    #[arg(long, conflicts_with_all = ["job", "merge"])]
    pub plan: bool,
    /// Run only these jobs of the matrix (ids from --plan), comma-separated, each kept under
    /// --out: a job whose result is there is skipped, one stopped midway goes on from its
    /// checkpoint; no report is written (--merge does)
    #[arg(long, value_name = "ID", value_delimiter = ',', conflicts_with_all = ["merge", "docs"])]
    pub job: Vec<String>,
    /// Build the report (report.md, report.csv, plots, report.rrd, written into DIR; with --docs
    /// the manual's pages) from the jobs' results kept in DIR: of the matrix they were run for
    /// (each result keeps its matrix options), or of the one the matrix options given name;
    /// nothing is run, and jobs without a result are listed as missing. Several folders
    /// (comma-separated): a job's result is the first folder's that has one, and the report
    /// goes into the first. Results of other builds of cellflip merge too, each build named
    /// with its jobs
    #[arg(
        long,
        value_name = "DIR",
        value_delimiter = ',',
        conflicts_with = "out"
    )]
    pub merge: Vec<PathBuf>,
    /// No progress bar and no closing line
    #[arg(long, short)]
    pub quiet: bool,
}

/// The scenes a report runs when `--scenes` does not name them (`crate::cmd::report`'s entries).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Matrix {
    /// The paper's scenes at small sizes for accuracy, its hard cases for stability.
    #[default]
    Default,
    /// Every scene of the paper's sec. 8 at the size the paper names, whole runs.
    Paper,
}

#[derive(Args, Debug, Clone)]
pub struct ValidateArgs {
    /// Cells along the Martin & Moyce tank (20 per column width at the default 320).
    #[arg(long)]
    pub res: Option<usize>,
    /// Shift added to the simulated dimensionless time T (at most 0.2).
    #[arg(long, default_value_t = 0.0)]
    pub shift: f64,
}

#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// A built-in scene name (see `cellflip list`) or the path of a scene .toml file (with
    /// --resume it may be left out; given, it must be the checkpoint's scene).
    #[arg(required_unless_present = "resume")]
    pub scene: Option<String>,
    /// The fluid method (overrides the scene's `simulation.method`).
    #[arg(long, value_enum)]
    pub method: Option<MethodKind>,
    /// Number of steps to run (instead of the scene's duration).
    #[arg(long, conflicts_with = "duration")]
    pub steps: Option<u64>,
    /// Duration, resolution, particles per cell and seed.
    #[command(flatten)]
    pub scale: SceneArgs,
    /// How obstacles pass particles (overrides `simulation.obstacle`): couple (ccp), or for
    /// the other methods naive (wait for free cells) or ignore (move regardless).
    #[arg(long, value_enum)]
    pub obstacle: Option<ObstacleArg>,
    /// The pressure solve.
    #[command(flatten)]
    pub pressure: PressureArgs,
    /// Where the recording goes.
    #[command(flatten)]
    pub sink: SinkArgs,
    /// Serving it to browsers.
    #[command(flatten)]
    pub serve: ServeArgs,
    /// With --connect: run even when no viewer answers at the URL at the start (by default
    /// that stops the command at once, exit 1, nothing run).
    #[arg(long, requires = "connect")]
    pub no_viewer_check: bool,
    /// Frames for a renderer.
    #[command(flatten)]
    pub export: ExportArgs,
    /// Record particles, markings and correction moves every N steps (metrics: every step)
    /// [default: 2D every step; 3D every 1/25 s of simulated time, which keeps a 50^3 run
    /// near 1 MB per recorded step and a whole built-in run under about 200 MB].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub record_every: Option<u64>,
    /// How the recording draws the correction's moves: arrows (from x_hat to x, often a small
    /// fraction of a cell) or hops (from the cell the particle was advected into to the cell
    /// it was put in).
    #[arg(long, value_enum, default_value_t = MovesArg::Arrows)]
    pub moves: MovesArg,
    /// 3D: the slice the recording draws as a 2D view: an axis (x, y or z) and, after `=`, a
    /// position as a fraction of the tank along it (e.g. `x=0.3`) [default: z=0.5].
    #[arg(long, value_name = "AXIS[=FRACTION]")]
    pub slice: Option<String>,
    /// 3D: do not draw the liquid's surface (a mesh, over the particles) in the recording.
    #[arg(long)]
    pub no_surface: bool,
    /// No progress bar and no summary.
    #[arg(long, short)]
    pub quiet: bool,
    /// The methods' own flags (`crate::methods::options`).
    #[command(flatten)]
    pub methods: MethodFlags,
    /// Checkpoints.
    #[command(flatten)]
    pub checkpoint: CheckpointArgs,
}

/// The pressure solve's options, for every method.
#[derive(Args, Debug, Clone, Default)]
pub struct PressureArgs {
    /// CG's preconditioner in the pressure solve (overrides
    /// `simulation.pressure_preconditioner`): auto (multigrid from 10,000 unknown rows in 2D
    /// and 100,000 in 3D, mic0 below), mic0
    /// (modified incomplete Cholesky) or multigrid (a geometric V-cycle).
    #[arg(long = "pressure", value_enum, value_name = "PRECONDITIONER")]
    pub preconditioner: Option<PreconditionerArg>,
}

/// `--pressure`'s values: [`Preconditioner`] as the command line names and explains it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PreconditionerArg {
    /// By the system's size: multigrid from 10,000 unknown rows in 2D and 100,000 in 3D
    /// (`Preconditioner::AUTO_ROWS`), MIC(0) below, where the multigrid's set-up and heavier
    /// iterations do not pay (the crossover measured in docs/benchmarks/pressure.md).
    Auto,
    /// Modified incomplete Cholesky: cheap per iteration, but its triangular solves are
    /// sequential and its iteration count grows with the grid.
    Mic0,
    /// A geometric multigrid V-cycle (McAdams et al. 2010; `solvers::multigrid`): several
    /// MIC(0) iterations' work per iteration, but an iteration count nearly independent of
    /// the grid, and parallel.
    Multigrid,
}

impl From<PreconditionerArg> for Preconditioner {
    fn from(p: PreconditionerArg) -> Self {
        match p {
            PreconditionerArg::Auto => Preconditioner::Auto,
            PreconditionerArg::Mic0 => Preconditioner::Mic0,
            PreconditionerArg::Multigrid => Preconditioner::Multigrid,
        }
    }
}

/// `--obstacle`'s values (and `compare --methods`'): [`ObstacleMode`] as the command line
/// names and explains it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ObstacleArg {
    /// Method ccp: through the correction (sec. 7).
    Couple,
    /// Move regardless; the particles covered count as lost volume.
    Ignore,
    /// Wait until the cells it would enter hold no liquid.
    Naive,
}

impl From<ObstacleArg> for ObstacleMode {
    fn from(o: ObstacleArg) -> Self {
        match o {
            ObstacleArg::Couple => ObstacleMode::Couple,
            ObstacleArg::Ignore => ObstacleMode::Ignore,
            ObstacleArg::Naive => ObstacleMode::Naive,
        }
    }
}

/// `--moves`' values: the recording's [`Moves`] as the command line names and explains them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MovesArg {
    /// From `x_hat` (after advection) to `x` (after the correction): the exact displacement,
    /// often a small fraction of a cell (the moved particles are highlighted).
    Arrows,
    /// From the centre of the cell the particle was advected into to the centre of the cell
    /// the correction put it in: every move at least one cell long.
    Hops,
}

impl From<MovesArg> for Moves {
    fn from(m: MovesArg) -> Self {
        match m {
            MovesArg::Arrows => Moves::Arrows,
            MovesArg::Hops => Moves::Hops,
        }
    }
}

/// Checkpoints of `run`: writing them, and going on from one (docs/checkpoints.md).
#[derive(Args, Debug, Clone, Default)]
pub struct CheckpointArgs {
    /// Write a checkpoint every SECS simulated seconds, at the end of the run, and when a signal
    /// stops it (SIGINT, SIGTERM, SIGHUP) or asks for one (SIGUSR1, which does not stop it);
    /// the last two are kept [default: none; a resumed run keeps its checkpoint's].
    #[arg(long, value_name = "SECS", allow_hyphen_values = true)]
    pub checkpoint_every: Option<f64>,
    /// Where checkpoints go [default: beside the recording, <recording stem>.checkpoints/; with
    /// --no-record, recordings/<scene>.checkpoints/; a resumed run: its checkpoint's folder].
    #[arg(long, value_name = "DIR")]
    pub checkpoint_dir: Option<PathBuf>,
    /// Go on with the run a checkpoint holds: a checkpoint file, or a folder (its newest
    /// complete checkpoint). The scene, method and options are the checkpoint's; --steps and
    /// --duration count from the run's start; by default the recording goes on in the
    /// checkpoint's file (with --save, in a new file of the same recording id).
    #[arg(long, value_name = "PATH")]
    pub resume: Option<PathBuf>,
}

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Scene to measure.
    #[arg(long, default_value = "dam-3d")]
    pub scene: String,
    /// Resolutions (cells along the longest axis), comma-separated; with two or more, a table
    /// of each stage's time per particle (or fluid cell) and the log-log slope of the step time
    /// against the particle count follow.
    #[arg(long, value_delimiter = ',', default_values_t = [64usize, 100])]
    pub res: Vec<usize>,
    /// Steps measured per resolution.
    #[arg(long, default_value_t = 10)]
    pub steps: u64,
    /// Steps run before measuring (at least 1).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub warmup: u64,
    /// The fluid method.
    #[arg(long, value_enum)]
    pub method: Option<MethodKind>,
    /// The pressure solve.
    #[command(flatten)]
    pub pressure: PressureArgs,
    /// Band methods of ccp to compare, comma-separated (none, paths, one-way, full); the
    /// step-time ratio to the first is printed [default: the scene's].
    #[arg(long, value_enum, value_delimiter = ',')]
    pub band: Vec<BandMode>,
    /// The methods' own flags but `--band`, which is bench's list above (with
    /// `--cross-check`, ccp's step times of both solvers are compared).
    #[command(flatten)]
    pub methods: MethodFlags,
}
