//! cellflip: cell-constrained particles for incompressible fluids (Z. Levi), with the methods
//! it is compared against, in 2D and 3D.

// Loops over axes `for k in 0..D` index several per-axis arrays at once; iterators would hide that.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod cli;
pub mod grid;
pub mod interrupt;
pub mod methods;
pub mod metrics;
pub mod out;
pub mod particles;
pub mod record;
pub mod report;
pub mod run;
pub mod runner;
pub mod scene;
pub mod sim;
pub mod solvers;
pub mod validation;
