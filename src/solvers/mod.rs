//! General numerics with no fluid knowledge.

pub mod lp;
pub mod min_cost_flow;
pub mod mps;
pub mod multigrid;
pub mod pcg;
pub mod sinkhorn;
