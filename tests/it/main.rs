//! The integration tests, one test crate organised by topic (issue 37): each file under
//! `tests/` used to be its own crate, linking the rerun SDK once per file; one crate links it
//! once. `cargo test --release --test it band::` runs one topic.

mod common;

mod active;
mod band;
mod checkpoint;
mod checkpoint_content;
mod cli_process;
mod compare;
mod correction;
mod docs;
mod envelope;
mod export;
mod fuzz;
mod golden;
mod idp;
mod live;
mod nbflip;
mod powerpic;
mod recordings;
mod regression;
mod report;
mod scene_refusals;
mod scenes;
mod slurm;
mod solids;
mod surface;
mod sweep;
mod validation;
mod web;
