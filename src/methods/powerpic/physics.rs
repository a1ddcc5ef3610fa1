//! Method powerpic's step: the hooks it implements (see the module doc of `super`).

use super::air::air_baseline;
use super::settings::{AirForm, PowerPicSettings};
use crate::draw::Image;
use crate::grid::{Grid, MacField, Vector};
use crate::methods::seam::{FluidMethod, MethodRecording, MethodReport};
use crate::metrics::InvariantViolation;
use crate::sim::advect::displace;
use crate::sim::transfer::{self, Known};
use crate::sim::{ParticlesMut, State, StepError};
use crate::snapshot::{Reader, SnapshotError, Writer};
use crate::solvers::sinkhorn::{Air, SinkhornError, Transport, TransportGrid};
use rayon::prelude::*;

/// Power PIC in a running simulation.
pub struct PowerPicSim<const D: usize> {
    settings: PowerPicSettings,
    /// `V_p = (2 tau)^d`, cells.
    volume: f64,
    tg: TransportGrid<D>,
    /// The simulation cell of each transport cell (the grids are fixed: found once, not in
    /// three passes a step).
    cell_of: Vec<u32>,
    /// This step's plan, for the particles' positions at its start.
    plan: Option<Transport<D>>,
    /// `sum_p T_pj` per transport cell.
    fill: Vec<f64>,
    /// Empty volume of the liquid's transport cells, cells.
    air_volume: f64,
    /// The largest `|sum_j T_pj / V_p - 1|` the transfer back found.
    row_error: f64,
}

impl<const D: usize> PowerPicSim<D> {
    pub fn new(settings: PowerPicSettings) -> Self {
        PowerPicSim {
            settings,
            volume: 0.0,
            tg: TransportGrid {
                grid: Grid::new([1; D]),
                h: 1.0,
                capacity: vec![],
                air: Air::Capacity,
            },
            cell_of: vec![],
            plan: None,
            fill: vec![],
            air_volume: 0.0,
            row_error: 0.0,
        }
    }

    /// The particles' volume and the transport grid, fixed by the scene.
    fn set_up_grids(&mut self, s: &State<D>) {
        self.volume = (2.0 * self.settings.tau(s.config.per_axis)).powi(D as i32);
        let refine = self.settings.refine;
        let grid = Grid::new(std::array::from_fn(|k| s.grid.dims[k] * refine));
        let n = grid.num_cells();
        self.tg = TransportGrid {
            grid,
            h: 1.0 / refine as f64,
            capacity: vec![0.0; n],
            air: Air::Capacity,
        };
        self.cell_of = self.tg.cells_on(&s.grid);
    }

    /// Transport cells in solid cells have no capacity (the solids of this step); the air's
    /// cost from the settings, with the baseline of this step's markings.
    fn update_cells(&mut self, s: &State<D>) {
        let tg = &mut self.tg;
        let cell_volume = tg.h.powi(D as i32);
        let (solid, cell_of) = (&s.solids.solid, &self.cell_of);
        (tg.capacity.par_iter_mut().zip(cell_of)).for_each(|(v, &c)| {
            *v = if solid[c as usize] { 0.0 } else { cell_volume };
        });
        tg.air = match self.settings.air {
            AirForm::Capacity => Air::Capacity,
            AirForm::Baseline => Air::Baseline {
                eta: self.settings.eta,
                baseline: air_baseline(tg, cell_of, &s.markings, s.config.mu()),
            },
        };
    }

    /// A solver failure as an error naming the setting that causes it.
    fn explain(&self, e: SinkhornError) -> StepError {
        let key = match e {
            SinkhornError::KernelVanishes { .. } => "simulation.powerpic.epsilon",
            SinkhornError::Overfull { .. } => "simulation.powerpic.tau",
            SinkhornError::Diverged { .. } => "simulation.powerpic",
        };
        StepError::Solver {
            setting: key,
            solver: "Sinkhorn",
            error: Box::new(e),
        }
    }

    fn plan(&self) -> &Transport<D> {
        self.plan
            .as_ref()
            .expect("the plan is made in particles_to_grid")
    }

    /// Empty volume of the transport cells of the liquid's cells (every one of them is within
    /// the reach of its particles, so among the plan's).
    fn air_in_liquid(&self, s: &State<D>) -> f64 {
        let tg = &self.tg;
        (self.plan().active_cells().iter().map(|&j| j as usize))
            .filter(|&j| s.markings.is_fluid(self.cell_of[j] as usize))
            .map(|j| (tg.capacity[j] - self.fill[j]).max(0.0))
            .sum()
    }
}

impl<const D: usize> FluidMethod<D> for PowerPicSim<D> {
    fn start(&mut self, s: &mut State<D>) {
        self.set_up_grids(s);
    }

    /// The last plan's scalings, the next solve's warm start.
    fn save_state<'a>(&'a self, w: &mut Writer<'a>) {
        if let Some(plan) = &self.plan {
            let (active, u, v) = plan.warm_parts();
            w.slice("powerpic.active", active);
            w.slice("powerpic.u", u);
            w.slice("powerpic.v", v);
        }
    }

    fn restore_state(&mut self, s: &State<D>, r: &Reader) -> Result<(), SnapshotError> {
        self.set_up_grids(s);
        if r.has("powerpic.active") {
            let active = r.slice("powerpic.active", None)?;
            let v = r.slice("powerpic.v", Some(active.len()))?;
            let u = r.slice("powerpic.u", None)?;
            self.plan = Some(Transport::from_warm_parts(active, u, v));
        }
        Ok(())
    }

    /// Steps 1 and 2: the plan, then each transport cell's mass and momentum to the faces.
    fn particles_to_grid(&mut self, s: &State<D>) -> Result<(MacField<D>, Known<D>), StepError> {
        self.update_cells(s);
        let (pos, vel) = (&s.particles.pos, &s.particles.vel);
        let warm = self.plan.take();
        let plan = Transport::solve(&self.tg, pos, self.volume, &self.settings.sinkhorn(), warm)
            .map_err(|e| self.explain(e))?;
        let tg = &self.tg;
        let mass = plan.columns(0.0, |_| 1.0);
        let momentum = plan.columns(Vector::<D>::zeros(), |p| vel[p]);
        let mut fill = vec![0.0; tg.capacity.len()];
        let (mut centres, mut velocities, mut masses) = (vec![], vec![], vec![]);
        for ((&j, &m), mv) in plan.active_cells().iter().zip(&mass).zip(&momentum) {
            fill[j as usize] = m;
            if m > 0.0 {
                centres.push(tg.center(j as usize));
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
        s: ParticlesMut<'_, D>,
        u: &MacField<D>,
        u_old: &MacField<D>,
        _at: &mut Vec<Vector<D>>,
    ) -> bool {
        let plan = self.plan();
        let (tg, g) = (&self.tg, s.grid);
        let at_cells: Vec<(Vector<D>, Vector<D>)> = (plan.active_cells().par_iter())
            .map(|&j| {
                let x = tg.center(j as usize);
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
                plan.for_each_in_row(p, |k, xj, t| {
                    let (a, b) = at_cells[k];
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
    /// volume (to rounding), and, when Sinkhorn converged, every cell's column, with the air
    /// its model gives, holds to `delta`.
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
        let v = plan.column_scalings();
        for (&j, &v) in plan.active_cells().iter().zip(v) {
            let (j, fill) = (j as usize, self.fill[j as usize]);
            let error = self.tg.column_error(j, fill, v);
            if error > delta {
                return Err(InvariantViolation(format!(
                    "powerpic: transport cell {j} holds {fill:e} of its {:e} with column \
                     error {error:.4} after Sinkhorn converged to delta = {}",
                    self.tg.capacity[j], self.settings.delta
                )));
            }
        }
        Ok(())
    }

    fn finish_step(&mut self, _s: &State<D>) -> Box<dyn MethodReport<D>> {
        let Some(plan) = &self.plan else {
            return Box::new(PowerPicReport::default());
        };
        Box::new(PowerPicReport {
            solved: true,
            iterations: plan.iterations,
            marginal_error: plan.error,
            converged: plan.converged,
            air_volume: self.air_volume,
            fraction: fraction_image(&self.tg, &self.fill),
        })
    }
}

/// The transport grid's fluid fraction `sum_p T_pj / V_j` as an image ([`Image::of_cells`];
/// solid cells: 0).
fn fraction_image<const D: usize>(tg: &TransportGrid<D>, fill: &[f64]) -> Image {
    Image::of_cells(tg.grid.dims, |j| match tg.capacity[j] {
        c if c > 0.0 => (fill[j] / c) as f32,
        _ => 0.0,
    })
}

/// What Power PIC did in one step.
#[derive(Clone, Debug, Default)]
pub struct PowerPicReport {
    /// Whether a transport was solved this step (the other fields are zero otherwise).
    pub solved: bool,
    /// Sinkhorn's row updates.
    pub iterations: u32,
    /// The largest relative column error when it stopped.
    pub marginal_error: f64,
    /// Whether it met `delta` (otherwise it stopped at its cap).
    pub converged: bool,
    /// Empty volume of the transport cells in the liquid's cells, cells.
    pub air_volume: f64,
    /// The transport grid's fluid fraction (2D; the mid slice in 3D).
    pub fraction: Image,
}

impl<const D: usize> MethodRecording<D> for PowerPicSim<D> {}
