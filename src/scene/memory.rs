//! Runs that cannot fit are refused up front: a scene's peak memory, estimated from its cell
//! and particle counts, against the memory this machine has available (Linux `MemAvailable`).

use super::Scene;
use crate::grid::Grid;
use anyhow::{bail, Result};

/// Bytes per grid cell, an upper estimate: flip uses about 200 (dam-3d 32^3 -> 64^3 with
/// `cellflip bench`: 16 -> 91 MiB for 229k more cells and 97k more particles), powerpic's
/// finer transport grid about twice that.
const BYTES_PER_CELL: f64 = 400.0;
/// Bytes per particle, an upper estimate (the same measurements: about 300 for flip and ccp).
const BYTES_PER_PARTICLE: f64 = 600.0;

/// A run's size and estimated peak memory.
#[derive(Clone, Copy, Debug)]
pub struct MemoryEstimate {
    pub cells: usize,
    /// Particles seeded, plus what the emitters may add (up to their fill, or a full tank).
    pub particles: f64,
    pub bytes: f64,
}

impl Scene {
    pub fn memory_estimate(&self) -> MemoryEstimate {
        match self.dim() {
            2 => self.memory_estimate_dim::<2>(),
            _ => self.memory_estimate_dim::<3>(),
        }
    }

    fn memory_estimate_dim<const D: usize>(&self) -> MemoryEstimate {
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
        let bytes = BYTES_PER_CELL * cells as f64 + BYTES_PER_PARTICLE * particles;
        MemoryEstimate {
            cells,
            particles,
            bytes,
        }
    }

    /// Fails, naming the key that makes the run large, when the estimate exceeds the memory
    /// available now; passes where that is unknown (no `/proc/meminfo`).
    pub fn ensure_fits_in_memory(&self) -> Result<()> {
        let e = self.memory_estimate();
        let Some(available) = available_bytes() else {
            return Ok(());
        };
        if e.bytes <= available {
            return Ok(());
        }
        let key = match BYTES_PER_PARTICLE * e.particles > BYTES_PER_CELL * e.cells as f64 {
            true => "simulation.ppc",
            false => "domain.cells",
        };
        let gib = |b: f64| b / (1u64 << 30) as f64;
        bail!(
            "{}: key '{key}': the run needs about {:.1} GiB ({} cells, about {:.3e} particles), \
             more than the {:.1} GiB this machine has available",
            self.source,
            gib(e.bytes),
            e.cells,
            e.particles,
            gib(available)
        )
    }
}

/// `MemAvailable` from `/proc/meminfo`, bytes.
fn available_bytes() -> Option<f64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}
