//! forgemon: blow-by-blow monitoring of energy-driven forging machines (gravity drop
//! hammers and screw presses). See ARCHITECTURE.md for the map of the crate.

pub mod acquire;
pub mod advise;
pub mod alert;
pub mod cli;
pub mod config;
pub mod daemon;
pub mod daq;
pub mod diagnose;
pub mod estimate;
pub mod history;
pub mod identify;
pub mod physics;
pub mod pipeline;
pub mod recipe;
pub mod record;
pub mod report;
pub mod session;
pub mod signal;
pub mod simdevice;
pub mod synth;
