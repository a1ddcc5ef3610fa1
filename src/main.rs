//! `cellflip`: parse the command line, load the scene, run it in its dimension.

use anyhow::Result;
use cellflip::cmd::cli::{Cli, Command, ValidateArgs};
use cellflip::cmd::{bench, compare, report, run, solve, view};
use cellflip::{interrupt, scene, validation};
use clap::Parser;
use std::io::Write;

/// Exit status: 0, 1 on an error, 128 + the signal's number after a run stopped by a signal
/// (its recording and summary finished first).
fn main() {
    tune_malloc();
    file_size_limit_as_write_error();
    // A usage error (an unknown flag or value) exits 1 as every other error; --help and
    // --version print and exit 0.
    let cli = Cli::try_parse().unwrap_or_else(|e| {
        let _ = e.print();
        std::process::exit(if e.use_stderr() { 1 } else { 0 });
    });
    // The main thread is one of rayon's workers: it runs its share of every parallel loop,
    // and rayon starts one thread fewer. Outside the pool it would wait on every loop and run
    // the serial parts of a step beside the workers spinning for work, one thread more than
    // there are cores.
    let pool = rayon::ThreadPoolBuilder::new().use_current_thread();
    let result = match pool.build_global() {
        Ok(()) => dispatch(cli),
        Err(e) => Err(anyhow::anyhow!("starting the worker threads: {e}")),
    };
    if let Err(e) = &result {
        let _ = writeln!(std::io::stderr(), "error: {e:#}");
    }
    match (interrupt::signal(), result) {
        (Some(sig), _) => std::process::exit(interrupt::exit_code(sig)),
        (None, Err(_)) => std::process::exit(1),
        (None, Ok(())) => {}
    }
}

/// Tunes glibc's allocator before any thread starts: one arena (`M_ARENA_MAX`), and a heap that
/// keeps what is freed for the next step (`M_MMAP_THRESHOLD`, `M_TRIM_THRESHOLD`).
///
/// **One arena.** By default glibc gives each thread its own arena, and an arena keeps the
/// memory its thread freed for that thread's next allocations. The flow solver's halves are
/// allocated by whichever thread runs them, a different one from step to step, so each arena
/// came to hold the high-water mark of the other's, and the resident peak was that of the live
/// memory plus an unpredictable share of it (ccp without the band on deep-pool-3d at 48^3, 0.3
/// s: 286-316 MiB over five runs, 341 in a 1 s run, against 256-272 with one arena; wall time
/// 0.98x, whole processes timed in turn, docs/benchmarks/memory.md, "One malloc arena"). The
/// memory estimate is fitted to peaks measured this way.
///
/// **A heap that is not handed back.** glibc returns the top of its heap to the kernel once
/// `M_TRIM_THRESHOLD` bytes of it are free (by default twice its mmap threshold, which rises with
/// the blocks freed to at most 32 MiB: at most 64 MiB), so every step shrank the heap where the
/// blocks it freed had been (the flow solver's networks, the correction's problem, row-sized
/// vectors) and grew it again the next step, the kernel handing the pages back and then clearing
/// and mapping them afresh, which is dear on these virtual machines. Keeping the heap took drop-3d
/// at 300^3 (ccp) from 11.8-15.0 s of kernel time a run to 8.9-9.4 s, its correction stage to
/// 0.61-0.72x in two rounds, the step to 0.78-0.86x, and its peak up by 10-14%; the falling
/// obstacle's step, the pressure solve's, is unchanged (docs/benchmarks/pressure.md, "Fresh
/// pages"). The mmap threshold is set to the value glibc's own rule would reach (setting the trim
/// threshold stops that rule), so blocks of 32 MiB and more still come from fresh mappings,
/// resident only where a step writes them (the memory estimate's sparse per-cell arrays,
/// `methods::cost::HEAP_CELLS`).
fn tune_malloc() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only sets an allocator parameter; no other thread exists yet.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 1);
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_BYTES);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_BYTES);
    }
}

/// Blocks from this size up are mapped afresh: glibc's largest dynamic mmap threshold.
const MMAP_BYTES: i32 = 32 << 20;

/// Free heap top returned to the kernel once this much of it is free: the largest value
/// `mallopt` takes, so in practice only when a run ends (`machine::reset_peak_memory` trims it
/// between the runs of a report).
const TRIM_BYTES: i32 = i32::MAX;

/// Makes a file size limit (`ulimit -f`, as batch systems set) a write error, as a full disk
/// is: by default the kernel kills a process that writes past it with SIGXFSZ, before any
/// message or checkpoint; ignored, the write fails with EFBIG ("File too large"), which every
/// writer reports with the file's name, finishing what it can.
fn file_size_limit_as_write_error() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: sets the disposition of one signal to "ignore"; no handler runs.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::List => {
            let width = scene::BUILT_IN
                .iter()
                .map(|(n, _)| n.len())
                .max()
                .unwrap_or(0);
            for (name, text) in scene::BUILT_IN {
                let s = scene::Scene::parse(name, text, &Default::default())?;
                cellflip::outln!("{name:<width$}  {}D  {}", s.dim(), s.file.description);
            }
            cellflip::outln!("\nmethods (--method):");
            for m in cellflip::methods::MethodKind::ALL {
                cellflip::outln!("  {:<8}  {}", m.name(), m.info().about);
            }
            Ok(())
        }
        Command::Run(args) => run::run(&args),
        Command::Compare(args) => compare::compare(&args),
        Command::Bench(args) => bench::bench(&args),
        Command::Validate(args) => validate(&args),
        Command::Report(args) => report::report(&args),
        Command::Solve(args) => solve::solve(&args),
        Command::View(args) => view::view(&args),
    }
}

fn validate(args: &ValidateArgs) -> Result<()> {
    anyhow::ensure!(
        (0.0..=0.2).contains(&args.shift),
        "--shift: must be in [0, 0.2], got {}",
        args.shift
    );
    let hs = validation::hydrostatic(500)?;
    cellflip::outln!(
        "hydrostatic-2d, 500 steps: max particle speed {:.3e} sqrt(gH); volume {:.3}% .. {:.3}%",
        hs.speed_fraction,
        hs.volume_min,
        hs.volume_max
    );
    let overrides = scene::Overrides {
        cells: args.res,
        ..Default::default()
    };
    let mm = validation::martin_moyce(&overrides, args.shift)?;
    cellflip::outln!(
        "\nmartin-moyce-2d: {:.0} cells per column width, {} steps, time shift {} in T",
        mm.cells_per_a,
        mm.steps,
        mm.shift_t
    );
    print_comparison(("T", "Z exp", "Z sim"), &mm.front, "surge front");
    cellflip::outln!();
    print_comparison(("tau", "H exp", "H sim"), &mm.height, "column height");
    Ok(())
}

fn print_comparison(header: (&str, &str, &str), rows: &[validation::Row], what: &str) {
    cellflip::outln!("{:>6} {:>8} {:>8}", header.0, header.1, header.2);
    for r in rows {
        cellflip::outln!("{:>6.2} {:>8.2} {:>8.2}", r.time, r.measured, r.simulated);
    }
    let e = validation::mean_relative_error(rows);
    cellflip::outln!("{what}: mean relative error {:.1}%", 100.0 * e);
}
