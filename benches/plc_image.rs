//! The PLC result image's cost (issue 19 §2: what the face costs the service): rebuilding
//! the 20 registers from the status snapshot and a blow's result (done on every live event
//! and once a second), and answering one "read holding registers 0–19" request (done once
//! per PLC poll). Reported, not asserted; the machine is shared, so expect ±2×.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use forgemon::daemon::plc_server::{Warnings, answer, encode};
use forgemon::daemon::status::{SourceState, StatusSnapshot};
use forgemon::estimate::{BlowClass, BlowEstimate};
use tokio_modbus::Request;

fn blow() -> BlowEstimate {
    BlowEstimate {
        kinetic_in_j: Some(10_548.0),
        plastic_j: Some(7_669.0),
        friction_j: Some(900.0),
        damped_j: Some(500.0),
        elastic_j: Some(100.0),
        efficiency: Some(0.727),
        final_load_n: 1.0e6,
        h_end_m: Some(0.027),
        class: BlowClass::Intermediate,
        peak_load_n: 2.2e6,
        residual: Some(0.0),
        sensor_check: Some(0.01),
        h_start_m: Some(0.03),
        ..BlowEstimate::incomplete(7, 1.0, 5.3, 1.02)
    }
}

fn image(c: &mut Criterion) {
    let mut status = StatusSnapshot::new("hammer");
    for name in ["daq0", "daq1", "daq2"] {
        status.sources.insert(name.into(), SourceState { state: "connected".into(), ..Default::default() });
    }
    status.blows = 1234;
    let b = blow();
    c.bench_function("plc_image/encode", |bench| {
        bench.iter(|| encode(black_box(17), black_box(&status), Some(black_box(&b)), Warnings::default()))
    });
    let words = encode(17, &status, Some(&b), Warnings::default());
    let mut block = [0u16; forgemon::daemon::plc_server::part_block::WORDS];
    c.bench_function("plc_image/answer_read_20", |bench| {
        bench.iter(|| answer(black_box(&words), &mut block, Request::ReadHoldingRegisters(0, 20), |_| true))
    });
}

criterion_group!(benches, image);
criterion_main!(benches);
