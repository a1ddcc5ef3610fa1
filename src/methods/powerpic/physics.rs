//! Method powerpic's step: the hooks it implements (see the module doc of `super`).

use super::air::air_baseline;
use super::record::PowerPicReport;
use super::settings::{AirForm, PowerPicSettings};
use crate::draw::Image;
use crate::grid::lanes::cpu_has_lanes;
use crate::grid::{Grid, MacField, Vector};
use crate::methods::seam::{FluidMethod, MethodRecording, MethodReport};
use crate::snapshot::{check_elements, check_indices, Reader, SnapshotError, Writer};
use crate::solvers::awake::Awake;
use crate::solvers::sinkhorn::{Air, SinkhornError, Summand, Transport, TransportGrid};
use crate::stages::advect::displace;
use crate::stages::invariants::InvariantViolation;
use crate::stages::transfer::{self, Known};
use crate::stages::{ParticlesMut, State, StepError};
use rayon::prelude::*;

/// Particles per piece of grid to particles ([`FluidMethod::grid_to_particles`]): enough
/// that each piece keeps both threads busy, few enough that the piece's new states weigh a
/// few MB.
const ROWS_PER_PIECE: usize = 1 << 16;

/// Power PIC in a running simulation.
pub struct PowerPicSim<const D: usize> {
    settings: PowerPicSettings,
    /// `V_p = (2 tau)^d`, cells.
    volume: f64,
    /// Its cells are blocked in the simulation's solid cells, kept up with the obstacles.
    tg: TransportGrid<D>,
    /// The simulation cells whose transport cells were last blocked or freed for obstacles.
    obstacle_cells: Vec<usize>,
    /// This step's plan, for the particles' positions at its start.
    plan: Option<Transport<D>>,
    /// `sum_p T_pj` per slot of the plan.
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
            tg: TransportGrid::new(Grid::new([1; D]), 1.0),
            obstacle_cells: vec![],
            plan: None,
            fill: vec![],
            air_volume: 0.0,
            row_error: 0.0,
        }
    }

    /// The particles' volume and the transport grid, fixed by the scene but for its cells in
    /// solids: blocked in the solid cells (one pass over the grid, at the start and a restore).
    fn set_up_grids(&mut self, s: &State<D>) {
        self.volume = (2.0 * self.settings.tau(s.config.per_axis)).powi(D as i32);
        let refine = self.settings.refine;
        let grid = Grid::new(std::array::from_fn(|k| s.grid.dims[k] * refine));
        self.tg = TransportGrid::new(grid, 1.0 / refine as f64);
        let blocked: Vec<usize> = (0..self.tg.grid.num_cells())
            .into_par_iter()
            .filter(|&j| s.solids.solid[self.cell_of(s, j)])
            .collect();
        blocked.into_iter().for_each(|j| self.tg.set_free(j, false));
        self.obstacle_cells = s.solids.obstacle_cells().collect();
    }

    /// The transport cells blocked in this step's solid cells: those of the cells the
    /// obstacles covered go back to the solids' there, then the obstacles' cells now are
    /// blocked (the work of the obstacles' cells; a static solid never changes).
    fn update_cells(&mut self, s: &State<D>) {
        let before = std::mem::take(&mut self.obstacle_cells);
        self.obstacle_cells = s.solids.obstacle_cells().collect();
        let refine = self.settings.refine;
        let within = Grid::new([refine; D]);
        for &c in before.iter().chain(&self.obstacle_cells) {
            let (at, free) = (s.grid.cell_coords(c), !s.solids.solid[c]);
            for o in 0..within.num_cells() {
                let o = within.cell_coords(o);
                let j = self
                    .tg
                    .grid
                    .cell_index(std::array::from_fn(|k| at[k] * refine + o[k]));
                self.tg.set_free(j, free);
            }
        }
    }

    /// The simulation cell holding transport cell `j`.
    fn cell_of(&self, s: &State<D>, j: usize) -> usize {
        s.grid.cell_index_of(&self.tg.center(j))
    }

    /// This step's plan, from the last one's: the air's cost from the settings, with the
    /// baseline of this step's markings.
    fn solve(&mut self, s: &State<D>) -> Result<Transport<D>, StepError> {
        let warm = self.plan.take();
        let (tg, markings, mu) = (&self.tg, &s.markings, s.config.mu());
        let baseline = |j| air_baseline(tg.cell_volume(), markings, mu, self.cell_of(s, j));
        let air = match self.settings.air {
            AirForm::Capacity => Air::Capacity,
            AirForm::Baseline => Air::Baseline {
                eta: self.settings.eta,
                baseline: &baseline as _,
            },
        };
        let pos = &s.particles.pos;
        Transport::solve(tg, &air, pos, self.volume, &self.settings.sinkhorn(), warm)
            .map_err(|e| self.explain(e))
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
        let cell_volume = self.tg.cell_volume();
        (self.plan().active_cells().iter().zip(&self.fill))
            .filter(|&(&j, _)| s.markings.is_fluid(self.cell_of(s, j as usize)))
            .map(|(_, &fill)| (cell_volume - fill).max(0.0))
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
            let active = r.slice::<u32>("powerpic.active", None)?;
            let cells = self.tg.grid.num_cells();
            check_indices("powerpic.active", active.len(), |i| {
                let (j, next) = (active[i], active.get(i + 1));
                let outside = || format!("cell {j} of a transport grid of {cells}");
                let unsorted = |n| format!("{j} before {n}");
                ((j as usize) >= cells)
                    .then(outside)
                    .or_else(|| next.filter(|&&n| n <= j).map(unsorted))
            })?;
            let v = r.slice("powerpic.v", Some(active.len()))?;
            check_elements("powerpic.v", &v, scaling)?;
            let u = r.slice("powerpic.u", None)?;
            check_elements("powerpic.u", &u, scaling)?;
            self.plan = Some(Transport::from_warm_parts(active, u, v));
        }
        Ok(())
    }

    /// Steps 1 and 2: the plan, then each transport cell's mass and momentum to the faces.
    /// Both transfers are runs of short parallel passes (the Sinkhorn iterations', the
    /// columns', the rows'), which rayon's other workers wait for awake ([`Awake`]).
    fn particles_to_grid(&mut self, s: &State<D>) -> Result<(MacField<D>, Known<D>), StepError> {
        let _awake = Awake::start();
        self.update_cells(s);
        let plan = self.solve(s)?;
        let vel = &s.particles.vel;
        let sums = plan.columns(MassMomentum(0.0, Vector::zeros()), |p| {
            MassMomentum(1.0, vel[p])
        });
        self.fill = sums.iter().map(|s| s.0).collect();
        // A slot the kernels put no mass in (an underflow) weighs nothing in the splat.
        let velocities: Vec<Vector<D>> = (sums.iter())
            .map(|&MassMomentum(m, mv)| if m > 0.0 { mv / m } else { Vector::zeros() })
            .collect();
        drop(sums);
        self.plan = Some(plan);
        self.air_volume = self.air_in_liquid(s);
        let tg = &self.tg;
        let centres: Vec<Vector<D>> = (self.plan().active_cells().par_iter())
            .map(|&j| tg.center(j as usize))
            .collect();
        Ok(transfer::weighted_to_grid(
            &s.grid,
            &centres,
            &velocities,
            &self.fill,
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
        let _awake = Awake::start();
        let plan = self.plan();
        let (tg, g) = (&self.tg, s.grid);
        let slots = SlotMoments::new(plan, |cells, values| {
            let x: Vec<Vector<D>> = cells.iter().map(|&j| tg.center(j as usize)).collect();
            let mut at = vec![[Vector::<D>::zeros(); 2]; x.len()];
            u.interpolate_pairs(u_old, g, &x, &mut at);
            for ((value, x), [un, uo]) in values.iter_mut().zip(x).zip(at) {
                *value = [x, un, un - uo].map(Into::into);
            }
        });
        let (flip, solid, n) = (s.config.flip_ratio, &s.solids.solid, plan.points());
        assert_eq!(n, s.particles.len(), "one row per particle of the solve");
        let mut row_error = 0.0f64;
        // A piece of rows at a time: each piece's particles are written before the next is
        // computed, so the new states are not all held at once (56 bytes a particle in 3D).
        for start in (0..n).step_by(ROWS_PER_PIECE) {
            let (pos, vel) = (&s.particles.pos, &s.particles.vel);
            let moved = plan.by_rows(start..(start + ROWS_PER_PIECE).min(n), |p| {
                let (mass, [centre, un, du]) = slots.row(plan, p);
                let (un, du) = (un / mass, du / mass);
                let v = flip * (vel[p] + du) + (1.0 - flip) * un;
                let x = displace(g, solid, &pos[p], centre / mass - pos[p]);
                (x, v, (mass / self.volume - 1.0).abs())
            });
            for (p, (x, v, e)) in moved {
                s.particles.pos[p] = x;
                s.particles.vel[p] = v;
                row_error = row_error.max(e);
            }
        }
        self.row_error = row_error;
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
        for (k, ((&j, &v), &fill)) in plan
            .active_cells()
            .iter()
            .zip(v)
            .zip(&self.fill)
            .enumerate()
        {
            let error = plan.column_error(k, fill, v);
            if error > delta {
                return Err(InvariantViolation(format!(
                    "powerpic: transport cell {j} holds {fill:e} of its {:e} with column \
                     error {error:.4} after Sinkhorn converged to delta = {}",
                    self.tg.cell_volume(),
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
        Box::new(PowerPicReport {
            solved: true,
            iterations: plan.iterations,
            marginal_error: plan.error,
            converged: plan.converged,
            out_of_range: plan.out_of_range,
            air_volume: self.air_volume,
            fraction: fraction_image(&self.tg, plan, &self.fill),
        })
    }
}

/// The transport grid's fluid fraction `sum_p T_pj / V_j` as an image ([`Image::of_cells`];
/// 0 where no particle reaches, solid cells among them), from `fill` per slot of `plan`.
fn fraction_image<const D: usize>(
    tg: &TransportGrid<D>,
    plan: &Transport<D>,
    fill: &[f64],
) -> Image {
    let cell_volume = tg.cell_volume();
    Image::of_listed_cells(tg.grid.dims, plan.active_cells(), |k| {
        (fill[k] / cell_volume) as f32
    })
}

impl<const D: usize> MethodRecording<D> for PowerPicSim<D> {}

/// [`check_elements`]' reason for a Sinkhorn scaling that is not a finite positive number
/// (`u_p`, `v_j`: exponentials of the dual potentials).
fn scaling(x: &f64) -> Option<String> {
    (!(x.is_finite() && *x > 0.0)).then(|| format!("scaling {x} is not a finite positive number"))
}

/// A transport cell's mass and momentum, summed together in one pass over the plan's rows
/// (each component as it would be alone).
#[derive(Clone, Copy)]
struct MassMomentum<const D: usize>(f64, Vector<D>);

impl<const D: usize> std::ops::AddAssign for MassMomentum<D> {
    fn add_assign(&mut self, o: Self) {
        self.0 += o.0;
        self.1 += o.1;
    }
}

impl<const D: usize> std::ops::Mul<f64> for MassMomentum<D> {
    type Output = Self;
    fn mul(self, a: f64) -> Self {
        Self(self.0 * a, self.1 * a)
    }
}

/// Added into the column sums a cell at a time.
impl<const D: usize> Summand for MassMomentum<D> {}

/// What grid to particles sums over a row, per slot of the plan: the slot's centre, the new
/// velocity and its change there, as `3 D` numbers in a row, so that one loop adds a row's
/// three moments, `acc[c] += T_pj s_j[c]`, with the same operations, in the same order, as
/// three sums of vectors: the same bits. On a CPU with AVX2 that loop runs four values to an
/// instruction ([`SlotMoments::row`]), where the sums as vectors of `D` did not: grid to
/// particles about 0.9x on dam-3d at 48^3 (docs/benchmarks/powerpic.md).
struct SlotMoments<const D: usize> {
    values: Vec<[[f64; D]; 3]>,
}

/// The most values of a slot: `3 D` in 3D.
const MOST_SLOT_VALUES: usize = 9;

/// Slots a task of [`SlotMoments::new`].
const SLOTS_PER_PIECE: usize = 4096;

impl<const D: usize> SlotMoments<D> {
    /// The values of every slot of `plan`: `at(cells, values)` writes `[x_j, u(x_j), du(x_j)]`
    /// of each of a run of its cells (so that the velocities are interpolated in bulk,
    /// [`MacField::interpolate_pairs`]).
    fn new(plan: &Transport<D>, at: impl Fn(&[u32], &mut [[[f64; D]; 3]]) + Sync) -> Self {
        const { assert!(3 * D <= MOST_SLOT_VALUES) };
        let cells = plan.active_cells();
        let mut values = vec![[[0.0; D]; 3]; cells.len()];
        (values.par_chunks_mut(SLOTS_PER_PIECE))
            .zip(cells.par_chunks(SLOTS_PER_PIECE))
            .for_each(|(values, cells)| at(cells, values));
        Self { values }
    }

    /// Point `p`'s row summed: `sum_j T_pj` and `sum_j T_pj [x_j, u(x_j), du(x_j)]`.
    #[inline]
    fn row(&self, plan: &Transport<D>, p: usize) -> (f64, [Vector<D>; 3]) {
        let (mass, acc) = match cpu_has_lanes() {
            // SAFETY: only where the CPU has AVX2.
            true => unsafe { self.sum_in_lanes(plan, p) },
            false => self.sum(plan, p),
        };
        let moment = |m: usize| Vector::<D>::from_column_slice(&acc[m * D..(m + 1) * D]);
        (mass, [moment(0), moment(1), moment(2)])
    }

    /// [`Self::sum`] compiled for AVX2 (the same operations, four values at a time).
    ///
    /// # Safety
    /// Only on a CPU with AVX2.
    #[target_feature(enable = "avx2")]
    unsafe fn sum_in_lanes(&self, plan: &Transport<D>, p: usize) -> (f64, [f64; MOST_SLOT_VALUES]) {
        self.sum(plan, p)
    }

    /// `sum_j T_pj` and `sum_j T_pj s_j`, value by value (the first `3 D`), the row's cells in
    /// order.
    #[inline(always)]
    fn sum(&self, plan: &Transport<D>, p: usize) -> (f64, [f64; MOST_SLOT_VALUES]) {
        let (mut mass, mut acc) = (0.0, [0.0; MOST_SLOT_VALUES]);
        plan.for_each_in_row(p, |k, t| {
            mass += t;
            for (acc, s) in acc[..3 * D].iter_mut().zip(self.values[k].as_flattened()) {
                *acc += t * s;
            }
        });
        (mass, acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::methods::MethodKind;
    use crate::scene::{Overrides, Scene};
    use crate::solvers::sinkhorn::SinkhornSettings;
    use crate::step::Simulation;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    #[test]
    fn slot_moments_are_the_rows_summed_as_vectors_bit_for_bit_2d_and_3d() {
        // A plan of random points in a box of free transport cells; each slot's three vectors
        // random. The rows summed as four separate sums (grid to particles before
        // `SlotMoments`) against `SlotMoments::row`, and its two loops against each other.
        fn check<const D: usize>(cells: [usize; D], n: usize) {
            let mut rng = StdRng::seed_from_u64(7);
            let tg = TransportGrid::new(Grid::new(cells), 0.5);
            let side = |k: usize| cells[k] as f64 * 0.5;
            let points: Vec<Vector<D>> = (0..n)
                .map(|_| Vector::from_fn(|k, _| rng.random::<f64>() * side(k)))
                .collect();
            let s = SinkhornSettings {
                epsilon: 0.1,
                delta: 0.1,
                max_iterations: 100,
            };
            let volume = 0.5 * tg.free_volume() / n as f64;
            let air: Air<fn(usize) -> f64> = Air::Capacity;
            let plan = Transport::solve(&tg, &air.cost(), &points, volume, &s, None).unwrap();
            let per_slot: Vec<[Vector<D>; 3]> = (plan.active_cells().iter())
                .map(|_| std::array::from_fn(|_| Vector::from_fn(|_, _| rng.random::<f64>() - 0.5)))
                .collect();
            let slot_of: std::collections::HashMap<u32, usize> =
                (plan.active_cells().iter().enumerate())
                    .map(|(k, &j)| (j, k))
                    .collect();
            let slots = SlotMoments::new(&plan, |cells, values| {
                for (value, j) in values.iter_mut().zip(cells) {
                    *value = per_slot[slot_of[j]].map(Into::into);
                }
            });
            for p in 0..n {
                let (mut mass, mut sums) = (0.0, [Vector::<D>::zeros(); 3]);
                plan.for_each_in_row(p, |k, t| {
                    mass += t;
                    for (sum, v) in sums.iter_mut().zip(&per_slot[k]) {
                        *sum += t * v;
                    }
                });
                assert_eq!(slots.row(&plan, p), (mass, sums), "point {p}");
                if cpu_has_lanes() {
                    // SAFETY: on a CPU with AVX2.
                    let lanes = unsafe { slots.sum_in_lanes(&plan, p) };
                    assert_eq!(lanes, slots.sum(&plan, p), "point {p}");
                }
            }
        }
        check([12, 10], 150);
        check([8, 7, 6], 300);
    }

    #[test]
    fn the_blocked_transport_cells_follow_a_falling_obstacle_as_a_fresh_set_up_finds_them() {
        // The scene run by FLIP; the transport grid kept up step by step against one set up
        // from scratch on the same solids, and the obstacle seen to block new cells.
        fn check<const D: usize>(name: &str, cells: usize, steps: usize) {
            let o = Overrides {
                cells: Some(cells),
                method: Some(MethodKind::Flip),
                ..Default::default()
            };
            let scene = Scene::load(name, &o).unwrap();
            let mut sim = Simulation::<D>::new(scene.config(), &scene.method);
            let mut kept = PowerPicSim::<D>::new(PowerPicSettings::default());
            kept.start(&mut sim.state);
            let first = kept.tg.clone();
            let flags = |tg: &TransportGrid<D>| -> Vec<bool> {
                (0..tg.grid.num_cells()).map(|j| tg.is_free(j)).collect()
            };
            for step in 0..steps {
                sim.step().unwrap();
                kept.update_cells(&sim.state);
                let mut fresh = PowerPicSim::<D>::new(PowerPicSettings::default());
                fresh.start(&mut sim.state);
                assert!(flags(&kept.tg) == flags(&fresh.tg), "{name}, step {step}");
                assert_eq!(kept.tg.free_volume(), fresh.tg.free_volume());
            }
            let (before, after) = (flags(&first), flags(&kept.tg));
            let moved = (before.iter().zip(&after)).filter(|(a, b)| a != b).count();
            assert!(moved > 0, "{name}: the obstacle blocked no new cell");
        }
        check::<2>("falling-obstacle-2d", 32, 30);
        check::<3>("falling-obstacle-3d", 16, 15);
    }
}
