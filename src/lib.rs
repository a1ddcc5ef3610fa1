//! cellflip: cell-constrained particles for incompressible fluids (Z. Levi), with the methods
//! it is compared against, in 2D and 3D.

// Loops over axes `for k in 0..D` index several per-axis arrays at once; iterators would hide that.
#![allow(clippy::needless_range_loop)]

/// The fewest items of light work (a vector entry, a face, a cell) a parallel loop gives one
/// task: below it, waking a second thread costs more than the work. At dam-2d 50², thread
/// wake-ups and their locks were 45% of a flip step before loops had a grain.
pub const PAR_GRAIN: usize = 16384;

/// As [`PAR_GRAIN`] for a particle's stencil work (tens of face reads or writes each).
pub const PAR_GRAIN_PARTICLES: usize = 1024;

// The modules by layer, from the bottom (CODE_STYLE.md, "Layers"): each imports only from its
// own layer and those before it. Data, numerics and measures that know no fluid method:
pub mod grid;
pub mod interrupt;
pub mod machine;
pub mod metrics;
pub mod out;
pub mod particles;
pub mod snapshot;
pub mod solvers;

// The paper's stages, which know no method.
pub mod stages;

// The drawing vocabulary a method records in.
pub mod draw;

// The fluid methods, behind one seam.
pub mod methods;

// The step, the scene files, the step loop and what runs beside it.
pub mod scene;
pub mod step;

pub mod runner;
pub mod surface;

pub mod frames;
pub mod validation;

// The recordings (the only module that imports rerun), then a run's checkpoints.
pub mod record;

pub mod checkpoint;

// The commands.
pub mod cmd;
