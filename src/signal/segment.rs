//! Blow segmentation by acceleration trigger (being written).
