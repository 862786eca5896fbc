//! A Foxglove client that stops reading must not slow the service (issue 19 §3): the real
//! service (`daemon::serve`, `[foxglove] listen` set) is fed a simulated hammer's billet as
//! fast as it takes it (a source that waits for room, so any stall in the service would
//! stall the feed and time the test out), while a WebSocket client subscribes to every
//! channel, raw samples included, and then never reads again. Every blow must still come
//! out, and the messages the client could not take must be counted as dropped, not queued
//! without bound.

mod common;

use std::io::Write;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use forgemon::acquire::SourceEvent;
use forgemon::config::service::ServiceConfig;
use forgemon::config::{parse_machine, parse_process};
use forgemon::daemon::{Hooks, SOURCE_CHANNEL_CAPACITY, ServiceParts, serve};
use forgemon::physics::effects::EffectSet;
use forgemon::record::{Payload, read_recording};
use forgemon::simdevice::{BilletPlan, SimMachine};
use forgemon::synth::{CaptureSpec, rows_batch};
use futures_util::{SinkExt, StreamExt};
use tokio::sync::{mpsc, oneshot, watch};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

const MACHINE: &str = include_str!("../config/hammer-lg1000.machine.toml");
const STEEL: &str = include_str!("../config/steel-16NiCrMo13.process.toml");
/// The demo's billet (`cli/demo.rs`): eight blows, 1.5 s apart, 12 s of 3 × 100 kHz samples
/// (about 29 MB of them), far more than a client's outbox (4 MiB) and the sockets hold.
const V0S: [f64; 8] = [3.9, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3, 5.3];
/// A stalled service would stall the feed forever; this long means it did.
const STALL: Duration = Duration::from_secs(120);

/// The log, captured to read the server's counts.
#[derive(Clone, Default)]
struct Log(Arc<Mutex<Vec<u8>>>);

impl Write for Log {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().map_err(|_| std::io::Error::other("poisoned"))?.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn parts(dir: &std::path::Path, foxglove: std::net::SocketAddr) -> ServiceParts {
    let config = ServiceConfig {
        foxglove_listen: Some(foxglove),
        ..ServiceConfig::minimal(PathBuf::from("hammer-lg1000.machine.toml"), dir.to_path_buf())
    };
    common::demo_hammer_parts(dir, config)
}

/// Connect with a small receive buffer (so the socket soaks up little), read the server's
/// JSON until `/samples/daq` is advertised, subscribe to every channel, wait until the server
/// has applied the subscription, and return the connection unread from then on.
async fn subscribe_then_stall(addr: std::net::SocketAddr) -> tokio_tungstenite::WebSocketStream<tokio::net::TcpStream> {
    let mut tries = 0;
    let stream = loop {
        let socket = tokio::net::TcpSocket::new_v4().expect("socket");
        socket.set_recv_buffer_size(4096).expect("SO_RCVBUF");
        match socket.connect(addr).await {
            Ok(s) => break s,
            // The server starts a moment after `serve` is spawned.
            Err(e) if tries < 200 => {
                tries += 1;
                tracing::debug!(error = %e, "not listening yet");
                tokio::time::sleep(Duration::from_millis(25)).await;
            }
            Err(e) => panic!("the Foxglove server does not listen on {addr}: {e}"),
        }
    };
    let mut request = format!("ws://{addr}").into_client_request().expect("request");
    request.headers_mut().insert("sec-websocket-protocol", "foxglove.websocket.v1".parse().expect("header"));
    let (mut ws, response) = tokio_tungstenite::client_async(request, stream).await.expect("handshake");
    assert_eq!(
        response.headers().get("sec-websocket-protocol").map(|v| v.as_bytes()),
        Some(&b"foxglove.websocket.v1"[..])
    );
    let mut ids = Vec::new();
    while !ids.iter().any(|(_, t): &(u64, String)| t == "/samples/daq") {
        let frame = ws.next().await.expect("a frame").expect("a good frame");
        let Message::Text(text) = frame else { continue };
        let v: serde_json::Value = serde_json::from_str(text.as_str()).expect("JSON");
        for c in v["channels"].as_array().into_iter().flatten() {
            ids.push((c["id"].as_u64().expect("id"), c["topic"].as_str().unwrap_or_default().to_string()));
        }
    }
    let subs: Vec<_> = ids.iter().map(|(id, _)| serde_json::json!({"id": id, "channelId": id})).collect();
    let msg = serde_json::json!({"op": "subscribe", "subscriptions": subs}).to_string();
    ws.send(Message::text(msg)).await.expect("subscribe");
    // The protocol acknowledges no subscription, but the server applies a connection's
    // messages in order: the status refusing to unsubscribe an id never used comes back once
    // the subscription is in place. Only then may the feed go on: when it went on as soon as
    // the subscription was sent, a CI run on a loaded machine published 17 batches before the
    // server applied it (1183 of 1200 queued for this client).
    let probe = serde_json::json!({"op": "unsubscribe", "subscriptionIds": [u32::MAX]}).to_string();
    ws.send(Message::text(probe)).await.expect("probe");
    loop {
        let frame = ws.next().await.expect("a frame").expect("a good frame");
        let Message::Text(text) = frame else { continue };
        let v: serde_json::Value = serde_json::from_str(text.as_str()).expect("JSON");
        if v["op"] == "status" && v["message"].as_str().is_some_and(|m| m.contains("no such subscription")) {
            break;
        }
    }
    ws
}

#[test]
fn a_client_that_never_reads_does_not_stall_the_service_and_its_losses_are_counted() {
    let log = Log::default();
    let sink = log.clone();
    tracing_subscriber::fmt()
        .with_env_filter("forgemon::daemon::foxglove=info")
        .with_ansi(false)
        .with_writer(move || sink.clone())
        .init();
    let dir = tempfile::tempdir().expect("temp dir");
    let addr = std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a free port");
    let machine = parse_machine("m", MACHINE).expect("machine").machine;
    let plan = BilletPlan { process: parse_process("p", STEEL).expect("process"), v0s_mps: V0S.to_vec() };
    let mut sim = SimMachine::new(machine, EffectSet::NONE, vec![plan], CaptureSpec::hammer(7), 1.5);
    let blows = Arc::new(Mutex::new(0u32));
    let seen = blows.clone();
    let service_parts = parts(dir.path(), addr);
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let (summary, frames) = rt.block_on(async move {
        let (tx, rx) = mpsc::channel(SOURCE_CHANNEL_CAPACITY);
        let (shutdown_tx, _) = watch::channel(false);
        let (_stop_tx, stop_rx) = watch::channel(false);
        let (subscribed_tx, subscribed_rx) = oneshot::channel::<()>();
        // The source: one batch, then (once the client has subscribed) the rest as fast as
        // the service takes them.
        let feed = tokio::spawn(async move {
            let mut n = 0i64;
            let mut subscribed = Some(subscribed_rx);
            while !sim.finished() {
                let rows = sim.next_rows(1000).expect("rows");
                let batch = rows_batch("daq", n as u64 / 1000, n * 10_000, 10_000.0, &rows);
                n += rows.len() as i64;
                if tx.send(SourceEvent::Batch(batch)).await.is_err() {
                    break;
                }
                if let Some(s) = subscribed.take() {
                    s.await.expect("the client subscribed");
                }
            }
        });
        let hooks = Hooks { on_blow: Some(Box::new(move |_| *seen.lock().expect("lock") += 1)), ..Hooks::default() };
        let service = tokio::spawn(serve(service_parts, rx, shutdown_tx, stop_rx, hooks, None));
        let client = subscribe_then_stall(addr).await;
        let _ = subscribed_tx.send(());
        let summary = tokio::time::timeout(STALL, service).await.expect("the service stalled").expect("join");
        feed.await.expect("feed");
        // The service stopped: the connection it could not write to is closed too (the
        // client reads what the sockets still held, then the end).
        let mut client = client;
        let ended = tokio::time::timeout(STALL, async {
            let mut frames = 0u64;
            while let Some(Ok(_)) = client.next().await {
                frames += 1;
            }
            frames
        });
        let frames = ended.await.expect("the server closed the stalled connection when the service stopped");
        (summary.expect("the service ran"), frames)
    });
    let log = String::from_utf8_lossy(&log.0.lock().expect("lock")).to_string();

    // Every blow of the billet came out, live and recorded.
    assert_eq!(*blows.lock().expect("lock"), V0S.len() as u32, "{log}");
    assert_eq!(summary.blows, V0S.len() as u64);
    assert_eq!(summary.dropped_events, 0, "the service itself kept up");
    // The server's final count: what it queued for the client, and what it dropped.
    let count = |key: &str| -> u64 {
        let line = log.lines().find(|l| l.contains("foxglove live view stopped")).unwrap_or_else(|| panic!("{log}"));
        let at = line.find(&format!("{key}=")).unwrap_or_else(|| panic!("no {key} in {line}")) + key.len() + 1;
        line[at..].split(|c: char| !c.is_ascii_digit()).next().and_then(|d| d.parse().ok()).expect("a number")
    };
    let batches: usize = summary
        .files
        .iter()
        .map(|f| {
            read_recording(f)
                .expect("read")
                .messages
                .iter()
                .filter(|m| matches!(m.payload, Payload::Samples(_)))
                .count()
        })
        .sum();
    // Every batch after the first (before the subscription) was queued for the client, and
    // more than the outbox and the sockets hold was dropped (29 MB against 4 MiB + a few MB).
    assert!(count("queued") as usize >= batches - 1, "{} queued, {batches} batches recorded", count("queued"));
    let dropped = count("dropped");
    assert!(dropped > 0 && dropped < count("queued"), "dropped {dropped} of {}", count("queued"));
    // What the client read at the end is at most what was not dropped, plus the JSON
    // (serverInfo, two advertisements, a status or two): dropped data never went out.
    assert!(frames <= count("queued") - dropped + 5, "{frames} frames read");
    println!(
        "{} messages queued for the stalled client, {dropped} dropped, {frames} frames read at the end; {batches} sample batches",
        count("queued")
    );
}
