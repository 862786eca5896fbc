//! The Foxglove view's limits against the real binary (issue 39: the cap was checked when
//! a connection was accepted but a client was counted only after its handshake, so 200
//! clients that handshook together all got in; idle and half-open connections were never
//! closed).
//!
//! - N + 8 raw TCP clients that handshake together: exactly N (the default cap) get `101`,
//!   the others a `503` or a closed connection; once one leaves, a newcomer gets in.
//! - A connection that sends nothing, or half a handshake, is closed by the handshake
//!   timeout (`[foxglove] handshake_timeout_s`, short here).
//! - A connected client that answers no ping is closed by the idle timeout
//!   (`idle_timeout_s`, short here); one that reads, and so answers the pings, stays.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Child;
use std::time::{Duration, Instant};

use common::{Held, free_port, held, service_toml, spawn_service};
use forgemon::config::server_limits::DEFAULT_FOXGLOVE_MAX_CLIENTS;

/// A WebSocket upgrade asking for the Foxglove subprotocol (RFC 6455 §4.1).
const UPGRADE: &[u8] = b"GET / HTTP/1.1\r\nhost: 127.0.0.1\r\nupgrade: websocket\r\nconnection: Upgrade\r\n\
sec-websocket-key: dGhlIHNhbXBsZSBub25jZQ==\r\nsec-websocket-version: 13\r\n\
sec-websocket-protocol: foxglove.websocket.v1\r\n\r\n";

/// `forgemon run` with `[foxglove]` on a free port and the lines `foxglove_extra` in it.
fn service(dir: &std::path::Path, foxglove_extra: &str) -> (Child, u16) {
    let (http, fox) = (free_port(), free_port());
    let extra = format!("[foxglove]\nlisten = \"127.0.0.1:{fox}\"\n{foxglove_extra}\n");
    let cfg = service_toml(dir, http, "", &extra);
    (spawn_service(&cfg, http), fox)
}

fn connect(port: u16) -> TcpStream {
    TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_secs(5)).expect("connect")
}

/// The status code of the handshake's answer on `s`, `None` when it closed without one.
fn answer(s: &mut TcpStream) -> Option<u16> {
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        match s.read(&mut byte) {
            Ok(1) => head.push(byte[0]),
            _ => return None,
        }
    }
    String::from_utf8_lossy(&head).split_whitespace().nth(1)?.parse().ok()
}

fn stop(mut child: Child) {
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn clients_that_handshake_together_are_capped_at_accept() {
    let dir = tempfile::tempdir().unwrap();
    let (child, fox) = service(dir.path(), "");
    let cap = DEFAULT_FOXGLOVE_MAX_CLIENTS as usize;
    // Every connection open before any handshakes, then every handshake sent at once.
    let mut clients: Vec<TcpStream> = (0..cap + 8).map(|_| connect(fox)).collect();
    std::thread::sleep(Duration::from_millis(300));
    for c in &mut clients {
        let _ = c.write_all(UPGRADE);
    }
    let answers: Vec<Option<u16>> = clients.iter_mut().map(answer).collect();
    let admitted = answers.iter().filter(|a| **a == Some(101)).count();
    assert_eq!(admitted, cap, "{answers:?}");
    assert!(answers.iter().all(|a| matches!(a, Some(101 | 503) | None)), "{answers:?}");
    // One leaves: its place is free again.
    let gone = answers.iter().position(|a| *a == Some(101)).unwrap();
    clients.remove(gone);
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let mut newcomer = connect(fox);
        newcomer.write_all(UPGRADE).unwrap();
        if answer(&mut newcomer) == Some(101) {
            break;
        }
        assert!(Instant::now() < deadline, "a client left but no newcomer gets in");
        std::thread::sleep(Duration::from_millis(200));
    }
    stop(child);
}

#[test]
fn a_connection_that_never_completes_its_handshake_is_closed_by_the_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let (child, fox) = service(dir.path(), "handshake_timeout_s = 1.0");
    let mut silent = connect(fox);
    let mut half = connect(fox);
    half.write_all(&UPGRADE[..40]).unwrap();
    assert_eq!(held(&mut silent, Duration::from_secs(20)), Held::Closed, "silent");
    assert_eq!(held(&mut half, Duration::from_secs(20)), Held::Closed, "half a handshake");
    // The server still takes a client that handshakes.
    let mut ok = connect(fox);
    ok.write_all(UPGRADE).unwrap();
    assert_eq!(answer(&mut ok), Some(101));
    stop(child);
}

#[test]
fn a_client_that_answers_no_ping_is_closed_and_one_that_reads_stays() {
    use futures_util::StreamExt;
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let dir = tempfile::tempdir().unwrap();
    let (child, fox) = service(dir.path(), "idle_timeout_s = 2.0");
    // Handshakes, then neither reads nor writes: the pings go unanswered.
    let mut mute = connect(fox);
    mute.write_all(UPGRADE).unwrap();
    assert_eq!(answer(&mut mute), Some(101));
    // Reads (tungstenite answers each ping with a pong as it reads) for three idle timeouts.
    let rt = tokio::runtime::Runtime::new().unwrap();
    let live = rt.block_on(async {
        let mut req = format!("ws://127.0.0.1:{fox}/").into_client_request().unwrap();
        req.headers_mut().insert("sec-websocket-protocol", "foxglove.websocket.v1".parse().unwrap());
        let (mut ws, _) = tokio_tungstenite::connect_async(req).await.expect("the reading client connects");
        let until = tokio::time::Instant::now() + Duration::from_secs(6);
        let mut frames = 0;
        loop {
            match tokio::time::timeout_at(until, ws.next()).await {
                Err(_) => return Ok(frames),
                Ok(Some(Ok(m))) if !m.is_close() => frames += 1,
                Ok(other) => return Err(format!("closed after {frames} frames: {other:?}")),
            }
        }
    });
    let frames = live.expect("the client that reads was closed");
    assert!(frames >= 2, "serverInfo and advertise at least, got {frames}");
    assert_eq!(held(&mut mute, Duration::from_secs(20)), Held::Closed, "the mute client is still open");
    stop(child);
}
