//! Runs that cannot fit are refused up front: a run's peak memory, estimated from its cell and
//! particle counts with its method's measured [`Footprint`], against the memory this machine
//! has available (Linux `MemAvailable`).
//!
//! The estimate is `BASE + per_cell * cells + per_particle * particles (+ the recording's)`,
//! where `particles` counts what is seeded plus what emitters may add. The footprints are fits
//! to the peak resident memory of whole runs (docs/benchmarks.md, "Memory", gives the
//! measurements, the ratio of estimate to peak per method and the command that repeats them).

use super::Scene;
use crate::grid::Grid;
use anyhow::{bail, Result};

/// The process before any simulation: code, the thread pool, the scene.
const BASE_BYTES: f64 = 12.0 * MIB;
/// What a recording adds, an allowance rather than a fit: rerun's SDK and buffers, the frame
/// worker's copies of the particles and, in 3D, the surface reconstruction. Measured with flip:
/// 42-49 MiB on dam-2d at 128^2 and 256^2; on dam-3d 70 MiB at 48^3, 180 at 64^3, 277 at 96^3,
/// that is 0.7 to 1.6 KB per particle beyond the fixed part.
const RECORDING_BASE_BYTES: f64 = 48.0 * MIB;
/// The recording's allowance per particle, [2D, 3D].
const RECORDING_PER_PARTICLE: [f64; 2] = [300.0, 1300.0];
const MIB: f64 = (1u64 << 20) as f64;

/// A run's size and estimated peak memory.
#[derive(Clone, Copy, Debug)]
pub struct MemoryEstimate {
    pub cells: usize,
    /// Particles seeded, plus what the emitters may add (up to their fill, or a full tank).
    pub particles: f64,
    /// The simulation's share: the cells' and the particles' bytes.
    pub cell_bytes: f64,
    pub particle_bytes: f64,
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

    /// This run's own share: what one more run side by side adds.
    fn run_bytes(&self) -> f64 {
        self.cell_bytes + self.particle_bytes + self.recording_bytes
    }
}

/// The process's share, whatever it runs: its base and, `recorded`, the recording's fixed part.
fn process_bytes(recorded: bool) -> f64 {
    BASE_BYTES + if recorded { RECORDING_BASE_BYTES } else { 0.0 }
}

impl Scene {
    /// The estimated peak of a run of this scene, `recorded` or not.
    pub fn memory_estimate(&self, recorded: bool) -> MemoryEstimate {
        match self.dim() {
            2 => self.memory_estimate_dim::<2>(recorded),
            _ => self.memory_estimate_dim::<3>(recorded),
        }
    }

    fn memory_estimate_dim<const D: usize>(&self, recorded: bool) -> MemoryEstimate {
        let config = self.config::<D>();
        let grid = Grid::new(config.dims);
        let cells = grid.num_cells();
        let mu = self.file.simulation.ppc as f64;
        let seeded: usize = config.fluid.iter().map(|r| r.cells(&grid).count()).sum();
        // The largest fill any emitter may reach (0 without emitters).
        let emitted = (self.file.emitter.iter())
            .map(|e| e.until_fill.unwrap_or(1.0))
            .fold(0.0, f64::max);
        let particles = mu * (seeded as f64 + emitted * cells as f64);
        let footprint = self.method.footprint(D);
        MemoryEstimate {
            cells,
            particles,
            cell_bytes: footprint.per_cell * cells as f64,
            particle_bytes: footprint.per_particle * particles,
            recording_bytes: match recorded {
                true => RECORDING_PER_PARTICLE[D - 2] * particles,
                false => 0.0,
            },
            recorded,
        }
    }

    /// Fails, naming the key that makes the run large, when the estimate exceeds the memory
    /// available now; passes where that is unknown (no `/proc/meminfo`).
    pub fn ensure_fits_in_memory(&self, recorded: bool) -> Result<()> {
        ensure_fit(&[self], recorded)
    }
}

/// Fails when runs of `scenes` side by side in one process (`cellflip compare`) would not fit,
/// naming the first scene's file and the key that makes the runs large.
pub fn ensure_fit(scenes: &[&Scene], recorded: bool) -> Result<()> {
    let Some((first, _)) = scenes.split_first() else {
        return Ok(());
    };
    let estimates: Vec<MemoryEstimate> =
        scenes.iter().map(|s| s.memory_estimate(recorded)).collect();
    let sum = |f: fn(&MemoryEstimate) -> f64| estimates.iter().map(f).sum::<f64>();
    let bytes = process_bytes(recorded) + sum(MemoryEstimate::run_bytes);
    let Some(available) = available_bytes() else {
        return Ok(());
    };
    if bytes <= available {
        return Ok(());
    }
    let key = match sum(|e| e.particle_bytes + e.recording_bytes) > sum(|e| e.cell_bytes) {
        true => "simulation.ppc",
        false => "domain.cells",
    };
    let gib = |b: f64| b / (MIB * 1024.0);
    let runs = match scenes.len() {
        1 => "the run needs".to_string(),
        n => format!("{n} runs side by side need"),
    };
    bail!(
        "{}: key '{key}': {runs} about {:.1} GiB ({} cells, about {:.3e} particles{}), \
         more than the {:.1} GiB this machine has available",
        first.source,
        gib(bytes),
        estimates[0].cells,
        estimates[0].particles,
        match scenes.len() {
            1 => "",
            _ => " each",
        },
        gib(available)
    )
}

/// `MemAvailable` from `/proc/meminfo`, bytes.
fn available_bytes() -> Option<f64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}
