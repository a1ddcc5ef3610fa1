//! `cellflip`: parse the command line, load the scene, run it in its dimension.

use anyhow::Result;
use cellflip::cli::{Cli, Command, ValidateArgs};
use cellflip::{bench, run, scene, validation};
use clap::Parser;

fn main() {
    let cli = Cli::parse();
    if let Err(e) = dispatch(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::List => {
            for (name, text) in scene::BUILT_IN {
                let s = scene::Scene::parse(name, text, &Default::default())?;
                println!("{name:<18} {}D  {}", s.dim(), s.file.description);
            }
            Ok(())
        }
        Command::Run(args) => run::run(&args),
        Command::Bench(args) => bench::bench(&args),
        Command::Validate(args) => validate(&args),
    }
}

fn validate(args: &ValidateArgs) -> Result<()> {
    anyhow::ensure!(
        (0.0..=0.2).contains(&args.shift),
        "--shift: must be in [0, 0.2], got {}",
        args.shift
    );
    let hs = validation::hydrostatic(500)?;
    println!(
        "hydrostatic-2d, 500 steps: max particle speed {:.3e} sqrt(gH); volume {:.3}% .. {:.3}%",
        hs.speed_fraction, hs.volume_min, hs.volume_max
    );
    let overrides = scene::Overrides {
        cells: args.res,
        ..Default::default()
    };
    let mm = validation::martin_moyce(&overrides, args.shift)?;
    println!(
        "\nmartin-moyce-2d: {:.0} cells per column width, {} steps, time shift {} in T",
        mm.cells_per_a, mm.steps, mm.shift_t
    );
    println!("{:>6} {:>8} {:>8}", "T", "Z exp", "Z sim");
    for r in &mm.front {
        println!("{:>6.2} {:>8.2} {:>8.2}", r.time, r.measured, r.simulated);
    }
    println!(
        "surge front: mean relative error {:.1}%",
        100.0 * mm.front_mean_relative_error()
    );
    println!("\n{:>6} {:>8} {:>8}", "tau", "H exp", "H sim");
    for r in &mm.height {
        println!("{:>6.2} {:>8.2} {:>8.2}", r.time, r.measured, r.simulated);
    }
    println!(
        "column height: mean relative error {:.1}%",
        100.0 * mm.height_mean_relative_error()
    );
    Ok(())
}
