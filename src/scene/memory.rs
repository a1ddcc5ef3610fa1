//! Runs that cannot fit are refused up front: a run's peak memory, estimated from its cell and
//! particle counts with its method's measured [`Footprint`], against the smallest limit on the
//! process's memory ([`super::limits`]: the machine's `MemAvailable`, its cgroup's limit, its
//! own `ulimit -v` and `-d`).
//!
//! The estimate is `BASE + per_cell * cells + per_fluid_cell * fluid cells + per_particle *
//! particles held (+ a large problem's surcharge, + the spreading of a band beyond its seeded
//! count, + the recording's)`, where the fluid cells are the seeded liquid's and the
//! particles held are those seeded plus what emitters may add. A grid too large for the limit
//! on its cells alone (`per_cell * cells`) is refused before the estimate builds anything over
//! it. A band method holds only the band's, which moves with the water: the estimate takes the
//! larger of the band of the seeded liquid's first markings and the band of that liquid
//! settled at rest over the tank's floor (a column that spreads into a sheet is all band). It
//! holds every particle seeded while it starts, which is a second peak the estimate takes the
//! larger of. The footprints are fits
//! to the peak resident memory of whole runs (docs/benchmarks/memory.md, gives the
//! measurements, the ratio of estimate to peak per method and the command that repeats them).

use super::Scene;
use super::{ErrorKind, SceneError};
use crate::grid::{Grid, NearCells};
use crate::methods::{Holds, Rest};
use crate::particles::Region;
use crate::stages::markings::Markings;
use crate::stages::solids::{Motion, Obstacle, Solids};
use crate::stages::SimConfig;

/// The process before any simulation: code, the thread pool, the scene.
const BASE_BYTES: f64 = 12.0 * MIB;
/// What a recording adds, an allowance rather than a fit: rerun's SDK and buffers, the frame
/// worker's copies of the particles and, in 3D, the surface reconstruction. Measured with flip:
/// 42-49 MiB on dam-2d at 128^2 and 256^2; on dam-3d 70 MiB at 48^3, 180 at 64^3, 277 at 96^3,
/// that is 0.7 to 1.6 KB per particle beyond the fixed part. A whole recorded run of dam-2d
/// at its own 50^2 (8 s, ccp) peaks at 67 MiB, 2 above an allowance of 48: the SDK's share
/// grows with the recording's length, so the fixed part is 56.
const RECORDING_BASE_BYTES: f64 = 56.0 * MIB;
/// The recording's allowance per particle, [2D, 3D].
const RECORDING_PER_PARTICLE: [f64; 2] = [300.0, 1300.0];
const MIB: f64 = (1u64 << 20) as f64;

/// A run's size and estimated peak memory.
#[derive(Clone, Copy, Debug)]
pub struct MemoryEstimate {
    pub cells: usize,
    /// Cells of the seeded liquid.
    pub fluid_cells: usize,
    /// With a band, the active cells of the seeded liquid's first markings (`None` without:
    /// those footprints do not count them).
    pub active_cells: Option<usize>,
    /// Particles seeded, plus what the emitters may add (up to their fill, or a full tank).
    pub particles: f64,
    /// Of those, the particles the method holds after its start (a band method drops the
    /// deeper ones).
    pub held: f64,
    /// The most it is taken to hold during the run: with a band, the larger of `held` and the
    /// band of the liquid at rest ([`SeededLiquid::new`]).
    pub held_most: f64,
    /// The particles it holds on average over the run, which is what a step's cost follows
    /// (`held_most` is the memory's bound, for a dam with an emitter twice as many): those of
    /// `held_most` before the emitters, plus the emitters' particles averaged over the run
    /// ([`emitted_mean`]), of which a band holds its share of the seeded liquid.
    pub held_mean: f64,
    /// The liquid's cells on average over the run, band or not: the seeded liquid's plus the
    /// emitters' average over `mu`.
    pub liquid_cells_mean: f64,
    /// The share of the liquid that is driven on average, 0 to 1: the emitters' average
    /// (a jet that falls and splashes), or all of it where a lid (an obstacle of constant,
    /// nonzero velocity) keeps pushing into it.
    pub driven_share: f64,
    /// How far the seeded liquid's top, or a falling obstacle's bottom, falls to the liquid's
    /// level at rest over the tank's floor, metres ([`falls`]): the cost model's speed of
    /// the liquid (`cellflip report --plan`, docs/cluster.md).
    pub fall_m: f64,
    /// Whether anything moves the liquid ([`rest`]): the cost model's liquid at rest.
    pub rest: Rest,
    /// The simulation's share once it runs: the cells' and the particles' bytes.
    pub cell_bytes: f64,
    pub particle_bytes: f64,
    /// The simulation's share while a band method starts, holding every particle seeded (0
    /// for the others, whose share only grows from there).
    pub start_bytes: f64,
    /// What the recording adds per particle (0 without one).
    pub recording_bytes: f64,
    /// Whether the run is recorded (the recording's fixed part counts once per process).
    pub recorded: bool,
}

impl MemoryEstimate {
    /// The whole run's peak, the process's base and the recording's fixed part included.
    pub fn bytes(&self) -> f64 {
        process_bytes(self.recorded) + self.run_bytes()
    }

    /// [`MemoryEstimate::bytes`] in MiB.
    pub fn mib(&self) -> f64 {
        self.bytes() / MIB
    }

    /// This run's own share: what one more run side by side adds.
    fn run_bytes(&self) -> f64 {
        (self.cell_bytes + self.particle_bytes).max(self.start_bytes) + self.recording_bytes
    }
}

/// The process's share, whatever it runs: its base and, `recorded`, the recording's fixed part.
fn process_bytes(recorded: bool) -> f64 {
    BASE_BYTES + if recorded { RECORDING_BASE_BYTES } else { 0.0 }
}

/// What the pressure solve keeps from one step to the next for its warm start
/// ([`WarmStart`](crate::stages::pressure::WarmStart): a `u32` cell and an `f64` pressure per
/// fluid cell, the seeded liquid's here), unless the scene turns the warm start off; the
/// footprints were fitted to runs made before it (2026-12-01). About 4 MiB on drop-3d at
/// 150^3, whose whole ccp runs peaked at 791 MiB cold and 836 MiB warm against an estimate of
/// 831 without this term (the rest of the difference is not the kept pressure's: the two runs'
/// particles part after the first steps, and so do their allocations).
fn warm_start_bytes<const D: usize>(config: &SimConfig<D>, fluid_cells: usize) -> f64 {
    let per_cell = std::mem::size_of::<u32>() + std::mem::size_of::<f64>();
    match config.pressure_warm_start {
        true => (per_cell * fluid_cells) as f64,
        false => 0.0,
    }
}

impl Scene {
    /// The estimated peak of a run of this scene, `recorded` or not.
    pub fn memory_estimate(&self, recorded: bool) -> MemoryEstimate {
        match self.dim() {
            2 => self.memory_estimate_dim::<2>(recorded),
            _ => self.memory_estimate_dim::<3>(recorded),
        }
    }

    /// What the run's cells alone take, its footprint's bytes per cell: a floor under
    /// [`Self::memory_estimate`] found without building anything over the grid.
    fn cell_floor_bytes(&self) -> (usize, f64) {
        let cells: usize = self.dims.iter().product();
        (
            cells,
            self.method.footprint(self.dim()).per_cell * cells as f64,
        )
    }

    fn memory_estimate_dim<const D: usize>(&self, recorded: bool) -> MemoryEstimate {
        let config = self.config::<D>();
        let grid = Grid::new(config.dims);
        let cells = grid.num_cells();
        let mu = self.file.simulation.ppc as f64;
        let footprint = self.method.footprint(D);
        let seeded = SeededLiquid::new(&config, &grid, footprint.holds);
        // The largest fill any emitter may reach (0 without emitters).
        let emitted = (self.file.emitter.iter())
            .map(|e| e.until_fill.unwrap_or(1.0))
            .fold(0.0, f64::max);
        let emitted = mu * emitted * cells as f64;
        let particles = mu * seeded.cells as f64 + emitted;
        let held = mu * seeded.held_cells as f64 + emitted;
        // What a band holds of the seeded liquid at the most (all of it without a band).
        let band = mu * seeded.held_cells.max(seeded.rest_cells) as f64;
        let held_most = band + emitted;
        let start_bytes = footprint.start_bytes(mu * seeded.cells as f64, cells as f64);
        let emitted_mean = emitted_mean(
            &config,
            mu * seeded.cells as f64,
            mu * cells as f64,
            self.duration_secs(),
        );
        // The band's share of the emitted liquid is its share of the seeded one (all of it
        // for a method without a band, or for a scene that seeds no liquid).
        let share = match seeded.cells {
            0 => 1.0,
            n => (band / (mu * n as f64)).min(1.0),
        };
        MemoryEstimate {
            cells,
            fluid_cells: seeded.cells,
            active_cells: seeded.active_cells,
            particles,
            held,
            held_most,
            held_mean: band + share * emitted_mean,
            liquid_cells_mean: seeded.cells as f64 + emitted_mean / mu,
            driven_share: driven_share(&config, emitted_mean, mu * seeded.cells as f64),
            fall_m: seeded.fall.liquid.max(seeded.fall.dropped) * config.cell_size_m,
            rest: rest(&config, seeded.fall.liquid),
            cell_bytes: footprint.cell_bytes(
                cells as f64,
                seeded.cells as f64,
                seeded.active_cells.unwrap_or(cells) as f64,
            ) + warm_start_bytes(&config, seeded.cells),
            particle_bytes: footprint.particle_bytes(held, held_most),
            start_bytes,
            recording_bytes: match recorded {
                true => RECORDING_PER_PARTICLE[D - 2] * held_most,
                false => 0.0,
            },
            recorded,
        }
    }

    /// Fails, naming the key that makes the run large and the limit it exceeds, when the
    /// estimate exceeds the memory left under the smallest limit on this process (the
    /// machine's, its cgroup's, its own: [`super::limits`]); passes where none can be read.
    /// Gives the estimate.
    pub fn ensure_fits_in_memory(&self, recorded: bool) -> Result<MemoryEstimate, SceneError> {
        let mut estimates = ensure_fit(&[self], recorded)?;
        Ok(estimates.remove(0))
    }
}

/// Fails when runs of `scenes` side by side in one process (`cellflip compare`) would not fit,
/// naming the first scene's file and the key that makes the runs large; gives each scene's
/// estimate.
pub fn ensure_fit(scenes: &[&Scene], recorded: bool) -> Result<Vec<MemoryEstimate>, SceneError> {
    let Some((first, _)) = scenes.split_first() else {
        return Ok(vec![]);
    };
    ensure_cells_fit(scenes, recorded)?;
    let estimates: Vec<MemoryEstimate> =
        scenes.iter().map(|s| s.memory_estimate(recorded)).collect();
    let sum = |f: fn(&MemoryEstimate) -> f64| estimates.iter().map(f).sum::<f64>();
    let bytes = process_bytes(recorded) + sum(MemoryEstimate::run_bytes);
    let Some(limit) = super::limits::smallest().filter(|l| bytes > l.bytes) else {
        return Ok(estimates);
    };
    let key = match sum(|e| e.particle_bytes + e.recording_bytes) > sum(|e| e.cell_bytes) {
        true => "simulation.ppc",
        false => "domain.cells",
    };
    let reason = format!(
        "{} about {:.1} GiB ({} cells, about {:.3e} particles{}), more than the {:.1} GiB \
         left under {}",
        runs_need(scenes.len()),
        gib(bytes),
        estimates[0].cells,
        estimates[0].particles,
        each(scenes.len()),
        gib(limit.bytes),
        limit.source
    );
    Err(refusal(first, key, reason))
}

/// Fails, as [`ensure_fit`] does, when the runs' cells alone would not fit: the estimate
/// itself builds arrays over each grid (the solids, the seeded liquid, a band's first
/// markings), which a grid far too large for the limit would fail to allocate.
fn ensure_cells_fit(scenes: &[&Scene], recorded: bool) -> Result<(), SceneError> {
    let floors: Vec<(usize, f64)> = scenes.iter().map(|s| s.cell_floor_bytes()).collect();
    let bytes = process_bytes(recorded) + floors.iter().map(|f| f.1).sum::<f64>();
    let Some(limit) = super::limits::smallest().filter(|l| bytes > l.bytes) else {
        return Ok(());
    };
    let reason = format!(
        "{} at least {:.1} GiB for the cells alone ({} cells{}), more than the {:.1} GiB left \
         under {}",
        runs_need(scenes.len()),
        gib(bytes),
        floors[0].0,
        each(scenes.len()),
        gib(limit.bytes),
        limit.source
    );
    Err(refusal(scenes[0], "domain.cells", reason))
}

fn gib(bytes: f64) -> f64 {
    bytes / (MIB * 1024.0)
}

/// "the run needs" or "`n` runs side by side need".
fn runs_need(n: usize) -> String {
    match n {
        1 => "the run needs".to_string(),
        n => format!("{n} runs side by side need"),
    }
}

/// " each" after one run's figures when `n` runs share the reason.
fn each(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        " each"
    }
}

/// The memory refusal of `scene`'s file at `key`.
fn refusal(scene: &Scene, key: &str, reason: String) -> SceneError {
    SceneError {
        file: scene.source.clone(),
        key: key.into(),
        kind: ErrorKind::Memory,
        reason,
    }
}

/// Peak resident memory of this process so far (Linux `VmHWM`), in MiB.
pub fn peak_memory_mib() -> Option<f64> {
    proc_kib("/proc/self/status", "VmHWM:").map(|kib| kib * 1024.0 / MIB)
}

/// The figure in KiB on the line starting with `key` of the `/proc` file `path`.
fn proc_kib(path: &str, key: &str) -> Option<f64> {
    super::limits::kib_field(&std::fs::read_to_string(path).ok()?, key)
}

/// The liquid a scene seeds, counted in cells: all of them, those whose particles the method
/// holds, and those it would hold were the liquid at rest.
struct SeededLiquid {
    cells: usize,
    held_cells: usize,
    rest_cells: usize,
    /// With a band, the active cells of the first markings.
    active_cells: Option<usize>,
    /// Cells the liquid, and an obstacle dropped into it, fall ([`falls`]).
    fall: Falls,
}

impl SeededLiquid {
    /// With a band of `layers`, the cells of the seeded liquid's first markings (the markings a
    /// run starts from, from the cells instead of the particles) less than `layers` deep and
    /// their active cells, and the band of that liquid settled over the floor: `layers` cells
    /// deep across the tank's section normal to gravity (along its largest component), at most
    /// the liquid's cells (none without gravity).
    fn new<const D: usize>(config: &SimConfig<D>, grid: &Grid<D>, holds: Holds) -> Self {
        let solids = Solids::new(
            grid,
            &config.solids,
            &config.obstacles,
            config.obstacle_mode,
        );
        let mut liquid = vec![false; grid.num_cells()];
        for region in &config.fluid {
            region
                .cells(grid)
                .for_each(|c| liquid[c] |= !solids.solid[c]);
        }
        let cells = liquid.iter().filter(|&&l| l).count();
        let fall = falls(config, grid, &liquid);
        let (held_cells, active_cells) = match holds {
            Holds::All => (cells, None),
            Holds::Band { layers, .. } => {
                let liquid = NearCells::new(grid, liquid);
                let (m, active) =
                    Markings::compute_keeping(grid, &[], solids.cells(), Some(&liquid));
                let held = (m.fluid_ranges().iter().flat_map(|r| r.clone()))
                    .filter(|&c| m.is_fluid(c) && m.depth(c) > -(layers as i32))
                    .count();
                (held, Some(active.num_cells()))
            }
        };
        let rest_cells = match holds {
            Holds::All => cells,
            Holds::Band { layers, .. } => cells.min(layers as usize * floor_cells(config, grid)),
        };
        Self {
            cells,
            held_cells,
            rest_cells,
            active_cells,
            fall,
        }
    }
}

/// The particles the emitters of `config` add, averaged over a run of `duration` seconds that
/// seeds `seeded` particles, `full` in a full tank (0 without emitters).
///
/// An emitter tops its cells up to `mu` particles each step ([`crate::stages::emit`]), so it
/// adds them as fast as its velocity carries the liquid out of its box: `mu` per cell of the
/// box's section across each axis times the speed along that axis, in cells per second (dam-2d at
/// 50^2: 3 cells x 75 cells/s x 4 = 900 particles/s). It does so from its start until it has
/// added what its fill leaves room for (`until_fill` of a full tank less the seeded particles; a
/// full tank without a fill), or it stops, or the run ends; the particles it adds over `[start,
/// filled]` count for `T - (start + filled) / 2` seconds of the run's `T` on average. Each
/// emitter is counted on its own. On the default matrix's emitter scenes this is within 7% of
/// the particles the runs held on average (docs/results/report.csv, 480cee2, `n_mean`: dam-2d
/// at 32^2 to 100^2 1,364 / 3,289 / 13,156 against 1,465 / 3,469 / 13,430; its 20 s run 4,316
/// against 4,251; the emitter at the speed limit 4,526 against 4,536).
fn emitted_mean<const D: usize>(
    config: &SimConfig<D>,
    seeded: f64,
    full: f64,
    duration: f64,
) -> f64 {
    let mu = config.mu() as f64;
    let mean = |e: &crate::stages::emit::Emitter<D>| {
        let Region::Box { min, max } = &e.region else {
            unreachable!("an emitter's region is a box (Scene::config)")
        };
        let size = max - min;
        let section = |k: usize| (0..D).filter(|&j| j != k).map(|j| size[j]).product::<f64>();
        let rate = mu
            * (0..D)
                .map(|k| e.velocity[k].abs() * section(k))
                .sum::<f64>();
        let room = e.until_particles.map_or(full, |u| u as f64) - seeded;
        let open = e.stop_secs.min(duration) - e.start_secs;
        if rate <= 0.0 || room <= 0.0 || open <= 0.0 || duration <= 0.0 {
            return 0.0;
        }
        let added = room.min(rate * open);
        let filled = e.start_secs + added / rate;
        added * (duration - (e.start_secs + filled) / 2.0) / duration
    };
    config.emitters.iter().map(mean).sum()
}

/// The share of the liquid, `seeded` particles and the emitters' `emitted` on average, that a
/// run drives: all of it under a lid that keeps moving, else the emitted share.
fn driven_share<const D: usize>(config: &SimConfig<D>, emitted: f64, seeded: f64) -> f64 {
    let lid = (config.obstacles.iter())
        .any(|o| matches!(o.motion, Motion::Constant) && o.velocity.norm() > 0.0);
    match (lid, seeded + emitted) {
        (true, _) => 1.0,
        (false, all) if all > 0.0 => emitted / all,
        _ => 0.0,
    }
}

/// How many cells the liquid falls, and a falling obstacle before it enters it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Falls {
    liquid: f64,
    dropped: f64,
}

/// How many cells the liquid falls and a falling obstacle before it enters it: the top of the
/// seeded `liquid` (its highest cell's top above the floor, along gravity's largest component)
/// and the highest falling obstacle's bottom, each above the level the liquid's cells make
/// spread over the floor, the whole tank's section (0 without gravity, for a liquid already
/// flat, or with nothing dropped into it). An obstacle enters the liquid at the speed of its
/// fall and throws it about as fast; solids are not counted (a liquid on a shelf is taken to
/// fall to the floor).
fn falls<const D: usize>(config: &SimConfig<D>, grid: &Grid<D>, liquid: &[bool]) -> Falls {
    let (axis, g) = config.gravity.map(f64::abs).argmax();
    if g <= 0.0 {
        return Falls {
            liquid: 0.0,
            dropped: 0.0,
        };
    }
    let n = grid.dims[axis];
    let height = |c: usize| match config.gravity[axis] < 0.0 {
        true => grid.cell_coords(c)[axis] + 1,
        false => n - grid.cell_coords(c)[axis],
    };
    let top = (0..liquid.len()).filter(|&c| liquid[c]).map(height).max();
    let level = liquid.iter().filter(|&&l| l).count() as f64 / floor_cells(config, grid) as f64;
    // Obstacles fall along axis 1, up (`Obstacle::bottom`).
    let dropped = (config.obstacles.iter())
        .filter(|o| matches!(o.motion, Motion::Falling { .. }))
        .map(|o| o.bottom());
    let above = |t: f64| (t - level).max(0.0);
    Falls {
        liquid: top.map_or(0.0, |t| above(t as f64)),
        dropped: dropped.map(above).fold(0.0, f64::max),
    }
}

/// Whether anything moves the liquid that falls `liquid_fall` cells to its level ([`Rest`]):
/// an emitter, a lid or a falling obstacle that the pressure sees (one with zero-velocity
/// boundary conditions it sees at rest: [`Rest::Entered`]), its own fall, or a pressure solve
/// started cold every step.
fn rest<const D: usize>(config: &SimConfig<D>, liquid_fall: f64) -> Rest {
    let moving: Vec<&Obstacle<D>> = (config.obstacles.iter())
        .filter(|o| matches!(o.motion, Motion::Falling { .. }) || o.velocity.norm() > 0.0)
        .collect();
    let seen = moving.iter().any(|o| !o.zero_velocity_bc);
    let entering = moving.iter().any(|o| o.zero_velocity_bc);
    let still = config.emitters.is_empty() && !seen && liquid_fall == 0.0;
    match (still && config.pressure_warm_start, entering) {
        (false, _) => Rest::Moving,
        (true, false) => Rest::Still,
        (true, true) => Rest::Entered,
    }
}

/// The cells of one layer of the grid across gravity's largest component (0 without gravity):
/// the floor a liquid at rest covers.
fn floor_cells<const D: usize>(config: &SimConfig<D>, grid: &Grid<D>) -> usize {
    let g = config.gravity.map(f64::abs);
    match g.argmax() {
        (axis, v) if v > 0.0 => grid.num_cells() / grid.dims[axis],
        _ => 0,
    }
}
