//! The commands: what `cellflip <command>` does, on top of the library (the paper's steps in
//! `stages/`, the methods in `methods/`, the step in `step.rs`, scenes, recordings). Each
//! module is one command and its own machinery, and nothing below imports from here: the
//! library's core stands apart from its command line (CODE_STYLE.md, "Layers").

pub mod bench;
pub mod cli;
pub mod compare;
pub mod export;
pub mod report;
pub mod run;
pub mod solve;
pub mod view;
