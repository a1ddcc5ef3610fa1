//! What a run of the report measured ([`Measured`], a row of report.csv and its series) and
//! what its observer gathers step by step ([`Gathered`]): shared by the measurement
//! ([`super::measure`]) and the runs kept under `--out` ([`super::saved`]).

use super::RunSpec;
use crate::machine::Machine;
use crate::validation::MartinMoyceProbe;
use std::collections::BTreeMap;

/// A run and what it measured. Figures a run does not have are NaN.
#[derive(Clone, Debug)]
pub struct Measured {
    pub spec: RunSpec,
    /// The resolution the run had (the scene's when the spec gives none).
    pub res: usize,
    pub seed: u64,
    pub status: String,
    pub dim: usize,
    /// The build of cellflip that ran it ([`crate::checkpoint::build`]: version and CRC-32 of
    /// its executable); a merge may take results of several.
    pub build: String,
    /// The machine of the process that ran it (that finished it, when resumed); `None` for a
    /// result kept before results recorded their machine.
    pub machine: Option<Machine>,
    /// The values of [`super::measure::COLUMNS`] from `particles` on, then the method figures.
    pub values: BTreeMap<String, f64>,
    /// `(t, V/V* %)` and `(t, kinetic energy per unit mass)` after every step.
    pub volume: Vec<(f64, f64)>,
    pub ke: Vec<(f64, f64)>,
    /// martin-moyce-2d: `(T, Z)` of the surge front.
    pub front: Vec<(f64, f64)>,
}

impl Measured {
    /// A run of `spec` not measured yet, on this machine (with the threads it has).
    pub fn new(spec: &RunSpec) -> Self {
        Self {
            spec: spec.clone(),
            res: spec.res.unwrap_or(0),
            seed: spec.seed.unwrap_or(0),
            status: String::new(),
            dim: 0,
            build: crate::checkpoint::build().into(),
            machine: Some(Machine::here(rayon::current_num_threads())),
            values: BTreeMap::new(),
            volume: vec![],
            ke: vec![],
            front: vec![],
        }
    }

    pub fn ok(&self) -> bool {
        self.status == "ok"
    }

    /// Whether this build of cellflip ran it (a run of another may not equal what this one
    /// computes: a report run again runs it again).
    pub fn ours(&self) -> bool {
        self.build == crate::checkpoint::build()
    }

    /// A figure by column name (NaN when the run has none).
    pub fn get(&self, column: &str) -> f64 {
        self.values.get(column).copied().unwrap_or(f64::NAN)
    }
}

/// What the observer gathers after every step.
#[derive(Default)]
pub struct Gathered {
    pub compression: f64,
    pub figures: BTreeMap<&'static str, Vec<f64>>,
    /// Steps the first obstacle had to stay.
    pub held: u64,
    /// Sums over the steps of the particles the method holds and of those the scene has
    /// (imaginary ones included: ccp's deep).
    pub particles_held: f64,
    pub particles_all: f64,
    pub probe: Option<MartinMoyceProbe>,
}
