//! The `forgemon` binary.
fn main() {}
