//! cellflip: cell-constrained particles for incompressible fluids (Z. Levi), with the methods
//! it is compared against, in 2D and 3D.

pub mod bench;
pub mod cli;
pub mod grid;
pub mod metrics;
pub mod particles;
pub mod record;
pub mod run;
pub mod scene;
pub mod sim;
pub mod solvers;
pub mod validation;
