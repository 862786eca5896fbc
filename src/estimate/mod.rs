//! Per-blow estimation with the identified model on measured signals (DESIGN.md §2.4).
//! Pure code.

pub mod result;

pub use result::{BlowClass, BlowEstimate};
