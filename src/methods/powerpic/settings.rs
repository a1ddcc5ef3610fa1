//! Power PIC's settings: `[simulation.powerpic]` in a scene file (defaults: Levi's, sec.
//! Evaluation).

use crate::methods::seam::{SettingContext, SettingError};
use crate::solvers::sinkhorn::SinkhornSettings;
use serde::{Deserialize, Serialize};

/// How the free surface's air is costed in the transport (see [`crate::solvers::sinkhorn`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum AirForm {
    /// Free air: a transport cell holds at most its volume.
    Capacity,
    /// Air pulled towards the air occupancy baseline estimated from the markings, with weight
    /// `eta`.
    Baseline,
}

/// Power PIC's parameters: `[simulation.powerpic]` in a scene file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PowerPicSettings {
    /// Transport cells per simulation cell along each axis (Levi: 2).
    pub refine: usize,
    /// `eps`, the entropic regularisation, in cells squared (Levi: 0.1).
    pub epsilon: f64,
    /// `eta`: the weight of the air term `eta eps KL(a | b)` in the baseline form (Levi: 1; our
    /// reading, see the module doc of `super`); the capacity form does not use it.
    pub eta: f64,
    /// `tau`: half a particle's rest spacing, in cells, so that `V_p = (2 tau)^d` is the volume
    /// of the box each particle stands for (Levi: `1 / (2 mu^(1/d))`, the default when unset,
    /// which makes `V_p = 1 / mu`; our reading).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tau: Option<f64>,
    /// How the free surface's air is costed: `baseline` (the default; pulled towards the air
    /// baseline estimated from the markings) or `capacity` (free: a transport cell holds at
    /// most its volume).
    pub air: AirForm,
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
            air: AirForm::Baseline,
            delta: 0.1,
            max_iterations: 1000,
        }
    }
}

impl PowerPicSettings {
    /// Refuses a kernel that does not reach a transport cell from anywhere, a particle volume
    /// that does not fit in a cell, and tolerances that cannot be met.
    pub fn check(&self, ctx: SettingContext) -> Result<(), SettingError> {
        let (p, per_axis) = (self, ctx.per_axis);
        let range = |key: &str, ok: bool, why: String| match ok {
            true => Ok(()),
            false => Err(SettingError::range(&format!("powerpic.{key}"), why)),
        };
        range(
            "refine",
            (1..=8).contains(&p.refine),
            format!(
                "must be 1 to 8 transport cells per cell and axis, got {}",
                p.refine
            ),
        )?;
        let (e, min) = (p.epsilon, p.min_epsilon(ctx.dim));
        range(
            "epsilon",
            e.is_finite() && e >= min && e <= 4.0,
            format!(
                "must be in [{min:.5}, 4] cells^2, got {e}: below, the kernel vanishes before the nearest transport cell; above, it spans many cells"
            ),
        )?;
        let t = p.tau(per_axis);
        range(
            "tau",
            t.is_finite() && t > 0.0 && t <= 0.5,
            format!("must be a half-width in (0, 0.5] cells, got {t}"),
        )?;
        range(
            "eta",
            p.eta.is_finite() && p.eta > 0.0,
            format!("must be a positive weight, got {}", p.eta),
        )?;
        range(
            "delta",
            p.delta > 0.0 && p.delta < 1.0,
            format!("must be in (0, 1), got {}", p.delta),
        )?;
        range(
            "max_iterations",
            p.max_iterations >= 1,
            "must be at least 1".into(),
        )
    }

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
