//! MCAP recording and reading (placeholder; being written).
