//! Method ccp's settings: the correction's solver and candidate moves, and the band method
//! (sec. band_method) with its depth `R`.

use super::correct::band::BandVariant;

pub use super::correct::problem::Directions;
pub use super::correct::Solver;
use crate::methods::seam::{MethodOption, SettingError};
use crate::sim::band::{check_band_r, DEFAULT_BAND_R};
use std::path::PathBuf;

/// Method ccp's settings: `[simulation.ccp]` in a scene file (or, for a file whose method is
/// ccp, the same keys directly in `[simulation]`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CcpSettings {
    /// Solver of the correction step (`simulation.solver`, `--solver`).
    pub solver: Solver,
    /// Candidate moves of the correction (`simulation.directions`, `--directions`).
    pub directions: Directions,
    /// The band method (sec. band_method) and how its count is kept (`simulation.band`,
    /// `--band`).
    pub band: BandMode,
    /// `R`: depth of the band interface; the band is `R + 1` cells thick (`simulation.band_r`,
    /// `--band-r`).
    pub band_r: u32,
    /// Solve every correction twice (other solver, other band variants) and compare
    /// (`--cross-check`; not a scene key).
    #[serde(skip)]
    pub cross_check: bool,
    /// Write the correction problem of this step as MPS to this path (`--export-lp`; not a
    /// scene key).
    #[serde(skip)]
    pub export_lp: Option<(u64, PathBuf)>,
}

impl CcpSettings {
    /// Refuses a band with Moore moves (the paths move to von Neumann neighbours only) and an
    /// `R` below 1.
    pub fn check(&self) -> Result<(), SettingError> {
        if self.band != BandMode::None && self.directions == Directions::Moore {
            let why = "the band method moves particles to von Neumann neighbours only \
                       (sec. push_part); use directions = \"von-neumann\" or band = \"none\"";
            return Err(SettingError {
                key: "band".into(),
                conflict: true,
                reason: why.into(),
            });
        }
        check_band_r(self.band_r).map_err(|why| SettingError::range("band_r", why.to_string()))
    }
}

impl Default for CcpSettings {
    /// The paper's choices: the exact flow solver, von Neumann moves, no band.
    fn default() -> Self {
        Self {
            solver: Solver::Flow,
            directions: Directions::VonNeumann,
            band: BandMode::None,
            band_r: DEFAULT_BAND_R,
            cross_check: false,
            export_lp: None,
        }
    }
}

/// The band setting of method ccp (`simulation.band`, `--band`): no band, or the band with the
/// variant that keeps its count.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum BandMode {
    /// No band: particles fill the whole fluid.
    None,
    /// The paper's choice: push particles along grid paths (sec. push_part).
    Paths,
    /// A second solve with the one-way constraint (sec. band_con2), an integer program.
    OneWay,
    /// Eq. problem3 with eq. band_con as one integer program: small grids only.
    Full,
    /// Beyond the paper: the problem `paths` solves greedily (move `n_move` particles from
    /// sources to sinks, other cells keeping their count), solved exactly as a min-cost flow.
    ExactPaths,
}

impl BandMode {
    /// The band variant, when there is a band.
    pub fn variant(self) -> Option<BandVariant> {
        match self {
            BandMode::None => None,
            BandMode::Paths => Some(BandVariant::Paths),
            BandMode::OneWay => Some(BandVariant::OneWay),
            BandMode::Full => Some(BandVariant::Full),
            BandMode::ExactPaths => Some(BandVariant::ExactPaths),
        }
    }

    pub fn name(self) -> &'static str {
        self.variant().map_or("none", BandVariant::name)
    }
}

/// Method ccp's flags on `cellflip run` (`--band-r`, which nbflip shares, is the run's own).
#[derive(clap::Args, Debug, Clone, Default)]
#[command(next_help_heading = "Method ccp")]
pub struct CcpArgs {
    /// Solver of the ccp correction: flow (exact min-cost flow) or simplex (the LP reference).
    #[arg(long, value_enum)]
    pub solver: Option<Solver>,
    /// Candidate moves of the ccp correction: von-neumann (paper) or moore.
    #[arg(long, value_enum)]
    pub directions: Option<Directions>,
    /// Band method of ccp (overrides `simulation.band`): none, paths (the paper's), one-way or
    /// full (an integer program: small grids only).
    #[arg(long, value_enum)]
    pub band: Option<BandMode>,
    /// Solve every correction with both solvers and report their largest objective difference;
    /// with a band, run every band variant on each step's problem and record their objectives
    /// (full and one-way, integer programs, only up to 50,000 candidates), and check
    /// exact-paths' second step against the simplex.
    #[arg(long)]
    pub cross_check: bool,
    /// Write the correction problem of step N as free-format MPS next to the recording (in
    /// recordings/ with --no-record), as
    /// <scene>-<method>[-band-<band>-r<R>]-<cells>-ppc<ppc>-seed<seed>-step<N>.mps.
    #[arg(long, value_name = "N")]
    pub export_lp: Option<u64>,
}

impl CcpArgs {
    /// The flags given, for the run's method to refuse those it lacks.
    pub fn given(&self) -> Vec<MethodOption> {
        [
            (MethodOption::Band, self.band.is_some()),
            (MethodOption::Solver, self.solver.is_some()),
            (MethodOption::Directions, self.directions.is_some()),
            (MethodOption::CrossCheck, self.cross_check),
            (MethodOption::ExportLp, self.export_lp.is_some()),
        ]
        .into_iter()
        .filter_map(|(o, given)| given.then_some(o))
        .collect()
    }
}
