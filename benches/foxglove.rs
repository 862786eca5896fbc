//! The Foxglove live view's cost per second of signal (issue 19: each face's CPU at
//! 3 × 100 kHz): one second of one source's samples, as the recorder hands them to the view
//! (100 batches of 10 ms, 3 000 doubles each, the demo DAQ's frames), published to a hub with
//! one client subscribed, then taken from the client's outbox and framed as the protocol's
//! message data, which is all the view does before the socket write. Reported per second of
//! signal, so the time per iteration is the fraction of a core; plus the same with no
//! client connected (the service's cost when nobody watches).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use forgemon::daemon::foxglove::hub::{CLIENT_QUEUE_BYTES, Hub, Outgoing};
use forgemon::daemon::foxglove::protocol::{Level, ServerMessage, message_data};
use forgemon::record::codec::encode_samples;
use forgemon::record::{MessageKind, TappedMessage};
use forgemon::signal::sample::{Role, SampleBatch};

/// 10 ms batches at 100 kHz: one second.
const BATCHES: usize = 100;
const BATCH_SAMPLES: usize = 1_000;

fn encoded_batches() -> Vec<Vec<u8>> {
    (0..BATCHES)
        .map(|k| {
            let batch = SampleBatch {
                source: "daq".into(),
                seq: k as u64,
                device_time_ns: k as i64 * 10_000_000,
                host_time_ns: 1_000_000_000 + k as i64 * 10_000_000,
                period_ns: 10_000.0,
                roles: vec![Role::Load, Role::Disp, Role::Acc],
                values: (0..3 * BATCH_SAMPLES).map(|i| (i as f64 * 0.37).sin() * 1e5).collect(),
            };
            let mut buf = Vec::new();
            encode_samples(&batch, &mut buf).expect("a well-formed batch");
            buf
        })
        .collect()
}

fn publish_all(hub: &Hub, batches: &[Vec<u8>]) {
    for (k, data) in batches.iter().enumerate() {
        let t = 1_000_000_000 + k as u64 * 10_000_000;
        hub.publish(&TappedMessage {
            topic: "/samples/daq",
            kind: MessageKind::Samples,
            data,
            log_time_ns: t,
            publish_time_ns: t,
        });
    }
}

fn bench(c: &mut Criterion) {
    let batches = encoded_batches();
    let mut g = c.benchmark_group("foxglove_one_second_of_3x100kHz");
    g.throughput(Throughput::Elements((BATCHES * BATCH_SAMPLES) as u64));
    g.sample_size(20);

    let hub = Hub::new(CLIENT_QUEUE_BYTES);
    publish_all(&hub, &batches[..1]); // the samples channel exists (id 8)
    let (client, outbox) = hub.connect(&ServerMessage::status(Level::Info, "bench"));
    let samples_channel = hub.channels().iter().find(|c| c.topic == "/samples/daq").map_or(0, |c| c.id);
    hub.on_text(client, &format!(r#"{{"op":"subscribe","subscriptions":[{{"id":1,"channelId":{samples_channel}}}]}}"#));
    while outbox.try_next().flatten().is_some() {}
    g.bench_function("one_client_publish_and_frame", |b| {
        b.iter(|| {
            publish_all(&hub, &batches);
            let mut bytes = 0;
            while let Some(out) = outbox.try_next().flatten() {
                if let Outgoing::Data(d) = out {
                    bytes += message_data(d.subscription_id, d.log_time_ns, &d.payload).len();
                }
            }
            black_box(bytes)
        })
    });
    assert_eq!(hub.stats().dropped, 0, "the bench drains what it publishes");

    let idle = Hub::new(CLIENT_QUEUE_BYTES);
    g.bench_function("no_client_publish", |b| b.iter(|| publish_all(&idle, black_box(&batches))));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
