//! Method powerpic: the Power Particle-in-Cell method (Qu, Li, de Goes, Jiang, "The Power
//! Particle-in-Cell Method", ACM TOG 41(4), art. 118, 2022), with a free surface.
//!
//! Every particle has a volume-constrained density kernel: its row of the entropic transport
//! plan `T` between the particles and a transportation grid finer than the simulation grid
//! ([`crate::solvers::sinkhorn`]). Per step (alg. flip with these hooks):
//!
//! 1. the plan for the particles' positions, by Sinkhorn iterations in the log domain from
//!    zero scalings, until both marginals hold to `delta`;
//! 2. particles to grid with the power (GIMP) weights `w_pi = sum_j T_pj N_i(x_j) / V_p`: each
//!    transport cell gathers the mass `sum_p T_pj` and momentum `sum_p T_pj v_p` of its
//!    column, and splats them with the tent functions `N_i` of the faces;
//! 3. forces and the projection as in flip;
//! 4. grid to particles with the same weights (the FLIP/PIC blend of flip, `u` and `u - u_old`
//!    averaged over the kernel), and each particle moved to its kernel's barycentre
//!    `sum_j T_pj x_j / V_p`;
//! 5. advection from there, as in flip.
//!
//! The free surface: a transport cell need not be full, `sum_p T_pj + a_j = V_j` with an
//! air slack `a_j >= 0`, so kernels fill the liquid's cells and keep their Gaussian shape
//! where there is air. Solids: transport cells in solid cells have no capacity, so no kernel
//! reaches into a solid (no clipping, no ghost particles).
//!
//! Parameters ([`PowerPicSettings`]; defaults from Levi, sec. Evaluation): transport grid 2x
//! finer per axis, `eps = 0.1`, `eta = 1`, `tau = 1 / (2 mu^(1/d))`, `delta = 0.1`. Qu et al.'s
//! text is not available to this project (its public summary and the open Taichi code,
//! g1n0st/power-pic, which has no free surface, are), and Levi gives only the values, so the
//! meaning of `eta` and `tau` is our reading, chosen to match their formulas:
//!
//! - `tau` is a length in cells: half a particle's spacing at rest, the half-width `l_p` of
//!   its GIMP domain (Bardenhagen and Kober 2004), so `(2 tau)^d` is its rest volume;
//! - `eta` scales that volume: every particle carries `V_p = eta (2 tau)^d` cells. With a free
//!   surface the fluid's volume is not the domain's, so it must be given; `eta = 1` is the
//!   volume the particles were seeded with ("precise volume control" of Qu et al.'s abstract).
//!
//! Where the text leaves a choice: `eps` is in simulation cells squared (the Taichi code's
//! `2 dx_T^2` is 0.125 of them, close to Levi's 0.1); the kernel is cut at `1e-12` of its peak
//! (Levi cut nothing; the Taichi code cuts at 6 transport cells); each step starts from zero
//! scalings (as the Taichi code does), so iteration counts measure the step's own problem; the
//! barycentre move is clamped like any particle move (into the domain, never into a solid);
//! the liquid cells of the pressure solve are those holding particles, as in every method
//! here, and advection is flip's forward Euler from the barycentre (the Taichi code moves to
//! `barycentre + dt sum_j T_pj u(x_j) / V_p`).

use super::{FluidMethod, Known, MethodInfo, MethodReport, MethodSettings, MethodType};
use crate::grid::{Grid, MacField, Vector};
use crate::metrics::InvariantViolation;
use crate::record::layout::{LayerView, Needs, Panel};
use crate::record::Log;
use crate::sim::advect::displace;
use crate::sim::solids::ObstacleMode;
use crate::sim::{transfer, State};
use crate::solvers::sinkhorn::{SinkhornError, SinkhornSettings, Transport, TransportGrid};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::any::Any;

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

    fn sinkhorn(&self) -> SinkhornSettings {
        SinkhornSettings {
            epsilon: self.epsilon,
            delta: self.delta,
            max_iterations: self.max_iterations,
        }
    }
}

/// Power PIC, as registered.
pub struct Powerpic;

impl MethodType for Powerpic {
    const INFO: MethodInfo = MethodInfo {
        name: "powerpic",
        about: "Power PIC (Qu et al. 2022): transfers through volume-constrained kernels, an \
                entropic transport to a finer grid solved by Sinkhorn, with air slack at the \
                free surface",
        options: &[],
        obstacle_modes: &[ObstacleMode::Naive, ObstacleMode::Ignore],
        panels: &[
            Panel {
                title: "powerpic: Sinkhorn iterations",
                series: &["metrics/powerpic/iterations"],
                needs: Needs::Always,
            },
            Panel {
                title: "powerpic: marginal error",
                series: &["metrics/powerpic/marginal_error"],
                needs: Needs::Always,
            },
            Panel {
                title: "powerpic: air in liquid cells",
                series: &["metrics/powerpic/air_volume"],
                needs: Needs::Always,
            },
        ],
        layer_views: &[LayerView {
            title: "transport grid: fluid fraction",
            origin: "powerpic",
            layers: &["powerpic/fluid_fraction"],
            marks: &[],
            needs: Needs::Always,
        }],
        figures: &[
            "powerpic_iterations",
            "powerpic_marginal_error",
            "powerpic_air_volume",
        ],
    };

    fn build<const D: usize>(s: &MethodSettings) -> Box<dyn FluidMethod<D>> {
        Box::new(PowerPicSim::<D> {
            settings: s.powerpic,
            volume: 0.0,
            tg: TransportGrid {
                grid: Grid::new([1; D]),
                h: 1.0,
                capacity: vec![],
            },
            plan: None,
            fill: vec![],
            air_volume: 0.0,
            row_error: 0.0,
            totals: Totals::default(),
        })
    }
}

/// Power PIC in a running simulation.
pub struct PowerPicSim<const D: usize> {
    settings: PowerPicSettings,
    /// `V_p`, cells.
    volume: f64,
    tg: TransportGrid<D>,
    /// This step's plan, for the particles' positions at its start.
    plan: Option<Transport<D>>,
    /// `sum_p T_pj` per transport cell.
    fill: Vec<f64>,
    /// Empty volume of the liquid's transport cells, cells.
    air_volume: f64,
    /// The largest `|sum_j T_pj / V_p - 1|` the transfer back found.
    row_error: f64,
    totals: Totals,
}

/// What the summary reports.
#[derive(Clone, Copy, Debug, Default)]
struct Totals {
    steps: u64,
    iterations: u64,
    most_iterations: u32,
    at_cap: u64,
}

impl<const D: usize> PowerPicSim<D> {
    /// Transport cells in solid cells have no capacity (the solids of this step).
    fn update_capacity(&mut self, s: &State<D>) {
        let tg = &mut self.tg;
        let cell_volume = tg.h.powi(D as i32);
        let solid = &s.solids.solid;
        tg.capacity.par_iter_mut().enumerate().for_each(|(j, v)| {
            let c = s
                .grid
                .cell_index_of(&(tg.grid.center(tg.grid.cell_coords(j)) * tg.h));
            *v = if solid[c] { 0.0 } else { cell_volume };
        });
    }

    /// A solver failure as an error naming the setting that causes it.
    fn explain(&self, e: SinkhornError) -> anyhow::Error {
        let key = match e {
            SinkhornError::KernelVanishes { .. } => "simulation.powerpic.epsilon",
            SinkhornError::Overfull { .. } => "simulation.powerpic.eta",
            SinkhornError::Diverged { .. } => "simulation.powerpic",
        };
        anyhow::anyhow!("{key}: Sinkhorn failed: {e}")
    }

    fn plan(&self) -> &Transport<D> {
        self.plan
            .as_ref()
            .expect("the plan is made in particles_to_grid")
    }

    /// Empty volume of the transport cells of the liquid's cells.
    fn air_in_liquid(&self, s: &State<D>) -> f64 {
        let tg = &self.tg;
        (0..tg.capacity.len())
            .filter(|&j| {
                let x = tg.grid.center(tg.grid.cell_coords(j)) * tg.h;
                s.markings.is_fluid(s.grid.cell_index_of(&x))
            })
            .map(|j| (tg.capacity[j] - self.fill[j]).max(0.0))
            .sum()
    }
}

impl<const D: usize> FluidMethod<D> for PowerPicSim<D> {
    fn start(&mut self, s: &mut State<D>) {
        let tau = self.settings.tau(s.config.per_axis);
        self.volume = self.settings.eta * (2.0 * tau).powi(D as i32);
        let refine = self.settings.refine;
        let grid = Grid::new(std::array::from_fn(|k| s.grid.dims[k] * refine));
        let n = grid.num_cells();
        self.tg = TransportGrid {
            grid,
            h: 1.0 / refine as f64,
            capacity: vec![0.0; n],
        };
    }

    /// Steps 1 and 2: the plan, then each transport cell's mass and momentum to the faces.
    fn particles_to_grid(&mut self, s: &State<D>) -> anyhow::Result<(MacField<D>, Known<D>)> {
        self.update_capacity(s);
        let (pos, vel) = (&s.particles.pos, &s.particles.vel);
        let warm = self.plan.take().map(|p| p.g);
        let plan = Transport::solve(&self.tg, pos, self.volume, &self.settings.sinkhorn(), warm)
            .map_err(|e| self.explain(e))?;
        let tg = &self.tg;
        let active: Vec<usize> = plan.active_cells().collect();
        let columns: Vec<(f64, Vector<D>)> = active
            .par_iter()
            .map(|&j| {
                let (mut mass, mut momentum) = (0.0, Vector::<D>::zeros());
                plan.for_each_in_column(tg, pos, j, |p, t| {
                    mass += t;
                    momentum += t * vel[p];
                });
                (mass, momentum)
            })
            .collect();
        let mut fill = vec![0.0; tg.capacity.len()];
        let (mut centres, mut velocities, mut masses) = (vec![], vec![], vec![]);
        for (&j, &(m, mv)) in active.iter().zip(&columns) {
            fill[j] = m;
            if m > 0.0 {
                centres.push(tg.center(j));
                velocities.push(mv / m);
                masses.push(m);
            }
        }
        self.fill = fill;
        self.plan = Some(plan);
        self.air_volume = self.air_in_liquid(s);
        Ok(transfer::weighted_to_grid(
            &s.grid,
            &centres,
            &velocities,
            &masses,
        ))
    }

    /// Step 4: velocities from the kernels (FLIP/PIC blend), positions to their barycentres.
    fn grid_to_particles(
        &mut self,
        s: &mut State<D>,
        u: &MacField<D>,
        u_old: &MacField<D>,
        _at: &mut Vec<Vector<D>>,
    ) -> bool {
        let plan = self.plan();
        let (tg, g) = (&self.tg, &s.grid);
        let mut slot = vec![u32::MAX; tg.capacity.len()];
        let active: Vec<usize> = plan.active_cells().collect();
        for (k, &j) in active.iter().enumerate() {
            slot[j] = k as u32;
        }
        let at_cells: Vec<(Vector<D>, Vector<D>)> = active
            .par_iter()
            .map(|&j| {
                let x = tg.center(j);
                let un = u.interpolate(g, &x);
                (un, un - u_old.interpolate(g, &x))
            })
            .collect();
        let flip = s.config.flip_ratio;
        let solid = &s.solids.solid;
        let pos = &s.particles.pos;
        let moved: Vec<(Vector<D>, Vector<D>, f64)> = (0..pos.len())
            .into_par_iter()
            .map(|p| {
                let (mut mass, mut centre) = (0.0, Vector::<D>::zeros());
                let (mut un, mut du) = (Vector::<D>::zeros(), Vector::<D>::zeros());
                plan.for_each_in_row(tg, pos, p, |j, xj, t| {
                    let (a, b) = at_cells[slot[j] as usize];
                    mass += t;
                    centre += t * xj;
                    un += t * a;
                    du += t * b;
                });
                let (un, du) = (un / mass, du / mass);
                let v = flip * (s.particles.vel[p] + du) + (1.0 - flip) * un;
                let x = displace(g, solid, &pos[p], centre / mass - pos[p]);
                (x, v, (mass / self.volume - 1.0).abs())
            })
            .collect();
        self.row_error = 0.0;
        for (p, (x, v, e)) in moved.into_iter().enumerate() {
            s.particles.pos[p] = x;
            s.particles.vel[p] = v;
            self.row_error = self.row_error.max(e);
        }
        transfer::limit_speeds(&mut s.particles.vel, s.config.max_speed);
        // The particles moved to their barycentres: advection interpolates there.
        false
    }

    /// The plan's marginals, recounted from the cells' sums: every particle's row holds its
    /// volume (to rounding), and, when Sinkhorn converged, no cell is over-full by more than
    /// `delta` and full cells are full to `delta`.
    fn check_invariants(&self, _s: &State<D>) -> Result<(), InvariantViolation> {
        let Some(plan) = &self.plan else {
            return Ok(());
        };
        if self.row_error > 1e-9 {
            return Err(InvariantViolation(format!(
                "powerpic: a particle's kernel holds {:e} more or less than its volume",
                self.row_error
            )));
        }
        if !plan.converged {
            return Ok(());
        }
        let delta = self.settings.delta * (1.0 + 1e-9);
        for j in plan.active_cells() {
            let ratio = self.fill[j] / self.tg.capacity[j];
            let full = plan.g[j] < 0.0;
            if ratio - 1.0 > delta || (full && 1.0 - ratio > delta) {
                return Err(InvariantViolation(format!(
                    "powerpic: transport cell {j} is filled to {ratio:.4} of its capacity \
                     (full: {full}) after Sinkhorn converged to delta = {}",
                    self.settings.delta
                )));
            }
        }
        Ok(())
    }

    fn finish_step(&mut self, _s: &State<D>) -> Box<dyn MethodReport<D>> {
        let Some(plan) = &self.plan else {
            return Box::new(PowerPicReport::default());
        };
        let t = &mut self.totals;
        t.steps += 1;
        t.iterations += plan.iterations as u64;
        t.most_iterations = t.most_iterations.max(plan.iterations);
        t.at_cap += u64::from(!plan.converged);
        Box::new(PowerPicReport {
            iterations: plan.iterations,
            marginal_error: plan.error,
            converged: plan.converged,
            air_volume: self.air_volume,
            fraction: fraction_image(&self.tg, &self.fill),
        })
    }

    fn summary(&self) -> Vec<String> {
        let t = &self.totals;
        if t.steps == 0 {
            return vec![];
        }
        let mut lines = vec![format!(
            "Sinkhorn: {:.1} iterations per step on average, {} at most",
            t.iterations as f64 / t.steps as f64,
            t.most_iterations
        )];
        if t.at_cap > 0 {
            lines.push(format!(
                "Sinkhorn reached its cap of {} iterations in {} of {} steps \
                 (simulation.powerpic.max_iterations)",
                self.settings.max_iterations, t.at_cap, t.steps
            ));
        }
        lines
    }

    fn reset_summary(&mut self) {
        self.totals = Totals::default();
    }
}

/// The transport grid's fluid fraction `sum_p T_pj / V_j` as an image: the whole grid in 2D,
/// the slice through the middle of the third axis in 3D (solid cells: 0).
fn fraction_image<const D: usize>(tg: &TransportGrid<D>, fill: &[f64]) -> FractionImage {
    let dims = tg.grid.dims;
    let (w, h) = (dims[0], dims[1]);
    let offset = if D == 3 { dims[2] / 2 * w * h } else { 0 };
    let values = (offset..offset + w * h)
        .map(|j| match tg.capacity[j] {
            c if c > 0.0 => (fill[j] / c) as f32,
            _ => 0.0,
        })
        .collect();
    FractionImage {
        size: [w, h],
        values,
    }
}

/// A fluid-fraction image.
#[derive(Clone, Debug, Default)]
pub struct FractionImage {
    pub size: [usize; 2],
    pub values: Vec<f32>,
}

/// What Power PIC did in one step.
#[derive(Clone, Debug, Default)]
pub struct PowerPicReport {
    /// Sinkhorn's row updates.
    pub iterations: u32,
    /// The largest relative column error when it stopped.
    pub marginal_error: f64,
    /// Whether it met `delta` (otherwise it stopped at its cap).
    pub converged: bool,
    /// Empty volume of the transport cells in the liquid's cells, cells.
    pub air_volume: f64,
    /// The transport grid's fluid fraction (2D; the mid slice in 3D).
    pub fraction: FractionImage,
}

impl<const D: usize> MethodReport<D> for PowerPicReport {
    fn record(&self, _s: &State<D>, log: &mut dyn Log<D>, full: bool) {
        log.scalar("metrics/powerpic/iterations", self.iterations as f64);
        log.scalar("metrics/powerpic/marginal_error", self.marginal_error);
        log.scalar("metrics/powerpic/air_volume", self.air_volume);
        if !self.converged {
            log.warn(&format!(
                "powerpic: Sinkhorn stopped at its cap of {} iterations with marginal error \
                 {:.3e}",
                self.iterations, self.marginal_error
            ));
        }
        if full {
            let f = &self.fraction;
            log.image("powerpic/fluid_fraction", f.size, &f.values, [0.0, 1.0]);
        }
    }

    fn figures(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("powerpic_iterations", self.iterations as f64),
            ("powerpic_marginal_error", self.marginal_error),
            ("powerpic_air_volume", self.air_volume),
        ]
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}
