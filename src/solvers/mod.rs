//! General numerics with no fluid knowledge.

pub mod awake;
pub mod cheapest;
pub mod lp;
pub mod min_cost_flow;
pub mod mps;
pub mod multigrid;
pub mod pcg;
pub mod sinkhorn;

/// "No index": an empty slot of a `u32` index map (a cell with no unknown, a node with no
/// parent).
pub const NONE: u32 = u32::MAX;
