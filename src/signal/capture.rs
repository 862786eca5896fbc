//! Capture CSV files and capture directories (CONTRACTS.md §1–2) (being written).
