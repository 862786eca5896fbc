//! Recording throughput benchmark (being written).
fn main() {}
