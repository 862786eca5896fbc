//! Signals: the one sample type every source produces, capture files, and blow
//! segmentation. Pure code: fed data, no IO, no clock.

pub mod align;
pub mod capture;
pub mod merge;
pub mod sample;
pub mod segment;
