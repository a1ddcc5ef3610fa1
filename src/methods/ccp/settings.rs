//! Method ccp's settings: the correction's solver and candidate moves, and the band method
//! (sec. band_method) with its depth `R`.

use super::correct::band::BandVariant;

pub use super::correct::problem::Directions;
pub use super::correct::Solver;
use crate::methods::options::{Flag, FlagValue};
use crate::methods::seam::{SettingError, StepFile};
use crate::stages::band::{check_band_r, DEFAULT_BAND_R};
use clap::builder::PossibleValue;
use std::path::{Path, PathBuf};

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
    /// (`simulation.ccp.cross_check`, `--cross-check`).
    pub cross_check: bool,
    /// Write the correction problem of this step as MPS (`--export-lp`; not a scene key) ...
    #[serde(skip)]
    pub export_lp: Option<u64>,
    /// ... to this path, beside the recording ([`CcpSettings::files`]).
    #[serde(skip)]
    pub export_path: Option<PathBuf>,
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

    /// `--export-lp N` writes step N's problem beside the recording, named after it:
    /// `<stem>-step<N>.mps`.
    pub fn files(&mut self, stem: &Path) -> Vec<StepFile> {
        let Some(step) = self.export_lp else {
            return vec![];
        };
        let mut name = stem.file_name().unwrap_or_default().to_os_string();
        name.push(format!("-step{step}.mps"));
        let path = stem.with_file_name(name);
        self.export_path = Some(path.clone());
        let flag = "export-lp";
        vec![StepFile { flag, step, path }]
    }
}

/// `--solver`'s values, named as serde names them, with their help.
impl clap::ValueEnum for Solver {
    fn value_variants<'a>() -> &'a [Self] {
        &Solver::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        let help = match self {
            Solver::Flow => "Exact min-cost flow by successive shortest paths (solvers/min_cost_flow.rs)",
            Solver::Simplex => "The LP relaxation by microlp's simplex (solvers/lp.rs): the reference, slow on large problems",
        };
        Some(PossibleValue::new(self.name()).help(help))
    }
}

/// `--directions`' values, named as serde names them, with their help.
impl clap::ValueEnum for Directions {
    fn value_variants<'a>() -> &'a [Self] {
        &[Directions::VonNeumann, Directions::Moore]
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(match self {
            Directions::VonNeumann => PossibleValue::new("von-neumann")
                .help("Stay, or one cell along an axis: 5 in 2D, 7 in 3D (the paper's choice)"),
            Directions::Moore => PossibleValue::new("moore")
                .help("Stay, or to any cell of the Moore neighbourhood: 9 in 2D, 27 in 3D"),
        })
    }
}

/// Method ccp's command-line flags.
pub const FLAGS: &[Flag<CcpSettings>] = &[
    Flag {
        name: "solver",
        help: "Solver of the correction: flow (exact min-cost flow) or simplex (the LP \
               reference) (overrides `simulation.solver`).",
        value: FlagValue::choice::<Solver>(),
        set: |s, v| v.try_into().map(|x| s.solver = x),
    },
    Flag {
        name: "directions",
        help: "Candidate moves of the correction: von-neumann (the paper's) or moore.",
        value: FlagValue::choice::<Directions>(),
        set: |s, v| v.try_into().map(|x| s.directions = x),
    },
    Flag {
        name: "band",
        help: "The band method (overrides `simulation.band`): none, paths (the paper's), \
               one-way or full (an integer program: small grids only), or exact-paths (ours).",
        value: FlagValue::choice::<BandMode>(),
        set: |s, v| v.try_into().map(|x| s.band = x),
    },
    Flag {
        name: "band-r",
        help: "Depth R of the band interface below the surface; the band is R + 1 cells thick \
               (overrides `simulation.band_r`).",
        value: FlagValue::number::<u32>(),
        set: |s, v| v.try_into().map(|x| s.band_r = x),
    },
    Flag {
        name: "cross-check",
        help: "Solve every correction with both solvers and report their largest objective \
               difference; with a band, run every band variant on each step's problem and \
               record their objectives (full and one-way, integer programs, only up to 50,000 \
               candidates), and check exact-paths' second step against the simplex.",
        value: FlagValue::SWITCH,
        set: |s, v| v.try_into().map(|x| s.cross_check = x),
    },
    Flag {
        name: "export-lp",
        help: "Write the correction problem of step N as free-format MPS next to the \
               recording (in recordings/ with --no-record), as \
               <scene>-<method>[-band-<band>-r<R>]-<cells>-ppc<ppc>-seed<seed>-step<N>.mps.",
        value: FlagValue::number::<u64>(),
        set: |s, v| v.try_into().map(|n| s.export_lp = Some(n)),
    },
];

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
            export_path: None,
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
