//! Signals: the one sample type every source produces, capture files, blow segmentation
//! and spectra. Pure code: fed data, no IO, no clock.

pub mod align;
pub mod capture;
pub mod fir;
pub mod merge;
mod pretrigger;
pub mod resample;
pub mod sample;
pub mod segment;
pub mod spectrum;
