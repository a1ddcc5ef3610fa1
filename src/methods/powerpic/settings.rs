//! Power PIC's settings: `[simulation.powerpic]` in a scene file (defaults: Levi's, sec.
//! Evaluation).

use crate::solvers::sinkhorn::SinkhornSettings;
use serde::{Deserialize, Serialize};

/// Power PIC's parameters: `[simulation.powerpic]` in a scene file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PowerPicSettings {
    /// Transport cells per simulation cell along each axis (Levi: 2).
    pub refine: usize,
    /// `eps`, the entropic regularisation, in cells squared (Levi: 0.1).
    pub epsilon: f64,
    /// `eta`: a particle's volume as a multiple of its rest volume `(2 tau)^d` (Levi: 1).
    pub eta: f64,
    /// `tau`: half a particle's rest spacing, in cells (Levi: `1 / (2 mu^(1/d))`, the default
    /// when unset).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tau: Option<f64>,
    /// `delta`: the relative marginal error at which Sinkhorn stops (Levi: 0.1).
    pub delta: f64,
    /// Sinkhorn iterations per step at most; a step that reaches it is reported.
    pub max_iterations: u32,
}

impl Default for PowerPicSettings {
    fn default() -> Self {
        Self {
            refine: 2,
            epsilon: 0.1,
            eta: 1.0,
            tau: None,
            delta: 0.1,
            max_iterations: 1000,
        }
    }
}

impl PowerPicSettings {
    /// `tau` for `per_axis` particles per cell along each axis.
    pub fn tau(&self, per_axis: usize) -> f64 {
        self.tau.unwrap_or(0.5 / per_axis as f64)
    }

    /// The smallest `eps` whose kernel reaches the nearest transport cell centre from anywhere
    /// (half a transport cell's diagonal).
    pub fn min_epsilon(&self, dim: usize) -> f64 {
        let h = 1.0 / self.refine as f64;
        dim as f64 * h * h / 4.0 / crate::solvers::sinkhorn::KERNEL_CUTOFF
    }

    pub(super) fn sinkhorn(&self) -> SinkhornSettings {
        SinkhornSettings {
            epsilon: self.epsilon,
            delta: self.delta,
            max_iterations: self.max_iterations,
        }
    }
}
