//! Validation against measurements nobody here wrote: the Martin & Moyce (1952) dam break
//! (surge front and residual column height) and water at rest. Used by the tests and by
//! `cellflip validate`, so the docs' figures and the tests come from the same code.

use crate::runner::{Limit, Runner, StepFailed};
use crate::scene::{LoadError, Overrides, Scene};
use crate::step::Simulation;

/// Surge front, `T = t sqrt(2 g / a)`, `Z = x / a` (Martin & Moyce 1952, table 2).
pub const SURGE_FRONT_CSV: &str = include_str!("../validation/martin_moyce_1952.csv");
/// Residual column height, `tau = t sqrt(g / a)`, `H = y / (2 a)`.
pub const COLUMN_HEIGHT_CSV: &str = include_str!("../validation/martin_moyce_1952_height.csv");

/// Column width of the experiment and of scene `martin-moyce-2d`, metres.
pub const COLUMN_WIDTH_M: f64 = 0.05715;
const G: f64 = 9.81;

/// A line of a CSV that is not two numbers.
#[derive(Debug, thiserror::Error)]
#[error("bad CSV line '{0}'")]
pub struct BadCsvLine(pub String);

/// Why a validation run could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ValidationError {
    #[error(transparent)]
    Scene(#[from] LoadError),
    #[error("{scene}")]
    Run {
        scene: &'static str,
        #[source]
        error: StepFailed,
    },
}

/// Parses a two-column CSV with `#` comments and a header line.
pub fn parse_csv(text: &str) -> Result<Vec<(f64, f64)>, BadCsvLine> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .skip(1)
        .map(|l| {
            let mut it = l.split(',').map(|v| v.trim().parse::<f64>());
            match (it.next(), it.next()) {
                (Some(Ok(a)), Some(Ok(b))) => Ok((a, b)),
                _ => Err(BadCsvLine(l.into())),
            }
        })
        .collect()
}

/// Linear interpolation in a time series sorted by time.
fn interpolate(series: &[(f64, f64)], t: f64) -> f64 {
    let i = series.partition_point(|(ti, _)| *ti < t);
    if i == 0 {
        return series[0].1;
    }
    if i == series.len() {
        return series[i - 1].1;
    }
    let (t0, v0) = series[i - 1];
    let (t1, v1) = series[i];
    v0 + (v1 - v0) * (t - t0) / (t1 - t0)
}

/// One row of a comparison with experiment.
#[derive(Clone, Debug)]
pub struct Row {
    pub time: f64,
    pub measured: f64,
    pub simulated: f64,
}

/// The result of simulating Martin & Moyce's experiment.
#[derive(Clone, Debug)]
pub struct MartinMoyce {
    pub front: Vec<Row>,
    pub height: Vec<Row>,
    /// Shift added to the simulated T before comparing (the experiment's start is uncertain).
    pub shift_t: f64,
    pub steps: u64,
    pub cells_per_a: f64,
}

impl MartinMoyce {
    /// Mean of `|Z_sim - Z| / Z` over the table's points.
    pub fn front_mean_relative_error(&self) -> f64 {
        mean_relative_error(&self.front)
    }

    pub fn height_mean_relative_error(&self) -> f64 {
        mean_relative_error(&self.height)
    }
}

/// Mean of `|simulated - measured| / measured` over `rows`.
pub fn mean_relative_error(rows: &[Row]) -> f64 {
    rows.iter()
        .map(|r| (r.simulated - r.measured).abs() / r.measured)
        .sum::<f64>()
        / rows.len() as f64
}

/// The surge front (furthest particle within a quarter column width of the floor) and the
/// column height at the back wall (highest particle in the first cell column) of scene
/// `martin-moyce-2d` over time, observed after each step, and their comparison with
/// experiment.
#[derive(Clone, Debug, Default)]
pub struct MartinMoyceProbe {
    /// `(t, front, column)`, seconds and metres.
    pub series: Vec<(f64, f64, f64)>,
}

impl MartinMoyceProbe {
    /// Simulated seconds that cover both tables.
    pub fn end_time() -> f64 {
        let last = |csv| {
            parse_csv(csv)
                .ok()
                .and_then(|d| d.last().map(|r| r.0))
                .unwrap_or(0.0)
        };
        let a = COLUMN_WIDTH_M;
        (last(SURGE_FRONT_CSV) / (2.0 * G / a).sqrt()).max(last(COLUMN_HEIGHT_CSV) / (G / a).sqrt())
    }

    pub fn observe(&mut self, sim: &Simulation<2>) {
        let s = &sim.state;
        let h = s.config.cell_size_m;
        let floor = 0.25 * COLUMN_WIDTH_M / h;
        let pos = &s.particles.pos;
        let front = pos
            .iter()
            .filter(|x| x[1] < floor)
            .map(|x| x[0])
            .fold(0.0, f64::max);
        let column = pos
            .iter()
            .filter(|x| x[0] < 1.0)
            .map(|x| x[1])
            .fold(0.0, f64::max);
        self.series.push((s.time_secs, front * h, column * h));
    }

    /// The comparison with experiment, the simulated `T` shifted by `shift_t`.
    pub fn compare(&self, shift_t: f64, steps: u64, cells_per_a: f64) -> MartinMoyce {
        let embedded = "the measurements built in parse (tests/it/validation.rs)";
        let front_data = parse_csv(SURGE_FRONT_CSV).expect(embedded);
        let height_data = parse_csv(COLUMN_HEIGHT_CSV).expect(embedded);
        let a = COLUMN_WIDTH_M;
        let (t_front, t_height) = ((2.0 * G / a).sqrt(), (G / a).sqrt());
        let fronts: Vec<(f64, f64)> = self
            .series
            .iter()
            .map(|(t, f, _)| (t * t_front + shift_t, f / a))
            .collect();
        let heights: Vec<(f64, f64)> = self
            .series
            .iter()
            .map(|(t, _, c)| (t * t_height + shift_t / 2f64.sqrt(), c / (2.0 * a)))
            .collect();
        let rows = |data: &[(f64, f64)], sim_series: &[(f64, f64)]| -> Vec<Row> {
            data.iter()
                .map(|&(t, m)| Row {
                    time: t,
                    measured: m,
                    simulated: interpolate(sim_series, t),
                })
                .collect()
        };
        MartinMoyce {
            front: rows(&front_data, &fronts),
            height: rows(&height_data, &heights),
            shift_t,
            steps,
            cells_per_a,
        }
    }
}

/// Runs scene `martin-moyce-2d` (with `overrides`) until the last tabulated time and compares
/// it with experiment ([`MartinMoyceProbe`]).
pub fn martin_moyce(overrides: &Overrides, shift_t: f64) -> Result<MartinMoyce, ValidationError> {
    let scene = Scene::load("martin-moyce-2d", overrides)?;
    let sim = Simulation::<2>::new(scene.config::<2>(), &scene.method);
    let mut probe = MartinMoyceProbe::default();
    probe.observe(&sim);
    let mut runner = Runner::new(sim);
    let limit = Limit::SimSeconds(MartinMoyceProbe::end_time());
    runner
        .run(
            limit,
            || false,
            |sim, _| {
                probe.observe(sim);
                Ok(())
            },
        )
        .map_err(|error| ValidationError::Run {
            scene: "martin-moyce-2d",
            error,
        })?;
    let cells_per_a = COLUMN_WIDTH_M / runner.sim.state.config.cell_size_m;
    Ok(probe.compare(shift_t, runner.sim.state.steps, cells_per_a))
}

/// Water at rest after `steps` steps: the largest particle speed as a fraction of
/// `sqrt(g H)` and the volume range in percent.
#[derive(Clone, Debug)]
pub struct Hydrostatic {
    pub speed_fraction: f64,
    pub volume_min: f64,
    pub volume_max: f64,
}

pub fn hydrostatic(steps: u64) -> Result<Hydrostatic, ValidationError> {
    let scene = Scene::load("hydrostatic-2d", &Overrides::default())?;
    let mut runner = Runner::new(Simulation::<2>::new(scene.config::<2>(), &scene.method));
    let s = &runner.sim.state;
    let top = s.particles.pos.iter().map(|x| x[1]).fold(0.0, f64::max);
    let depth_m = top.ceil() * s.config.cell_size_m;
    runner
        .run_to(Limit::Steps(steps))
        .map_err(|error| ValidationError::Run {
            scene: "hydrostatic-2d",
            error,
        })?;
    let s = &runner.sim.state;
    let speed = s.particles.vel.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let vmax_speed = speed * s.config.cell_size_m;
    let (vmin, vmax) = (runner.summary.volume_min, runner.summary.volume_max);
    Ok(Hydrostatic {
        speed_fraction: vmax_speed / (G * depth_m).sqrt(),
        volume_min: vmin,
        volume_max: vmax,
    })
}
