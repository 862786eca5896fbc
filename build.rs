//! Build script: compiles `proto/forgemon.proto` with `protox` (a protobuf compiler in
//! Rust, so no `protoc` binary is needed) and generates the Rust types with `prost-build`.
//! It also writes the FileDescriptorSet, without source info, to
//! `$OUT_DIR/forgemon.fds.bin`; `src/record/schema.rs` embeds it so every MCAP schema record
//! carries the complete schema (DESIGN.md §3, "MCAP layout").
//! `proto/sparkplug_b.proto` (the Sparkplug B payload, `src/daemon/sparkplug`) is compiled
//! the same way, apart, so the embedded forgemon schema stays as it was.

use std::path::PathBuf;

use prost::Message;

const PROTO_DIR: &str = "proto";
const PROTO_FILE: &str = "proto/forgemon.proto";
const SPARKPLUG_FILE: &str = "proto/sparkplug_b.proto";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed={PROTO_FILE}");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={SPARKPLUG_FILE}");

    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);

    // With source info, so the generated Rust carries the .proto comments as doc comments.
    let fds = protox::compile([PROTO_FILE], [PROTO_DIR])?;

    // The embedded copy has no source info: it is only for decoders, and is much smaller.
    let mut embedded = fds.clone();
    for file in &mut embedded.file {
        file.source_code_info = None;
    }
    std::fs::write(out_dir.join("forgemon.fds.bin"), embedded.encode_to_vec())?;

    prost_build::Config::new()
        // Deterministic encoding of `map<..>` fields: equal inputs give equal bytes.
        .btree_map(["."])
        .out_dir(&out_dir)
        .compile_fds(fds)?;
    prost_build::Config::new().out_dir(&out_dir).compile_fds(protox::compile([SPARKPLUG_FILE], [PROTO_DIR])?)?;
    Ok(())
}
