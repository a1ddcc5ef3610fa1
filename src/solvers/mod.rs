//! General numerics with no fluid knowledge.

pub mod pcg;
