//! The Foxglove live view (issue 19 §3): `[foxglove] listen` serves the Foxglove WebSocket
//! protocol (`foxglove.websocket.v1`), so an engineer connects Foxglove to the service and
//! sees the samples, blows and results live, on the same channels and with the same protobuf
//! schemas as the MCAP recording. Every message comes from the recorder's tap
//! (`record::tap`): the very bytes recorded, no second computation.
//!
//! - [`protocol`]: the protocol's messages, to and from JSON and bytes (sans-IO).
//! - [`hub`]: channels, clients, subscriptions and each client's bounded outbox, which
//!   drops the oldest message data when the client falls behind, counted.
//! - here: the listener and one task pair per connection (read the client's subscriptions;
//!   write its outbox), on tokio-tungstenite.
//!
//! A slow or stuck client costs the service one copy of each message it subscribed to and
//! nothing else: the service's thread only queues (`Hub::publish`), the connection's task
//! waits on the socket. A client that sends garbage is answered with an error `status` and
//! counted.
//!
//! Limits (`[foxglove]`, issue 39): a connection takes one of `max_clients` permits when it
//! is accepted, before its handshake, and keeps it until it closes, so clients that
//! handshake together cannot outnumber the cap; one accepted past the cap is answered 503 (a
//! few at a time, briefly) or closed. A connection has `handshake_timeout` to complete its
//! handshake; the server pings every third of `idle_timeout` and closes a client from which
//! no frame, a pong included, came for `idle_timeout` (one that vanished or hangs).

pub mod hub;
pub mod protocol;

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use futures_util::{SinkExt, StreamExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::{Bytes, Message};

use super::faces::{Face, FaceContext, boxed};
use super::idle::IdleClock;
use crate::config::server_limits::FoxgloveLimits;
use crate::record::tap::Tap;
use futures_util::future::BoxFuture;

use hub::{CLIENT_QUEUE_BYTES, Hub, HubStats, Outgoing};
use protocol::{SUBPROTOCOL, ServerMessage};

/// Connections past the cap answered 503 at once; more are closed without a word.
pub const REFUSALS_AT_ONCE: usize = 4;
/// How long a connection past the cap has to send its handshake for the 503 answer.
pub const REFUSAL_TIMEOUT: Duration = Duration::from_secs(2);
/// Largest frame a client may send (its subscriptions are a few hundred bytes).
pub const MAX_CLIENT_FRAME_BYTES: usize = 1 << 20;
/// How often the drop count is logged while it grows.
pub const DROP_LOG_INTERVAL: Duration = Duration::from_secs(10);

/// The running server; dropping it stops it and closes every client.
pub struct FoxgloveServer {
    hub: Hub,
    local_addr: SocketAddr,
    accept: tokio::task::JoinHandle<()>,
}

/// `[foxglove]` as a face: listening on its address, fed by the recorder's messages.
pub fn face<'a>(ctx: &'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn Face>>>> {
    Box::pin(async move {
        let Some(addr) = ctx.config.foxglove_listen else { return Ok(None) };
        let (server, tap) = listen(addr, CLIENT_QUEUE_BYTES, ctx.config.foxglove_limits).await?;
        ctx.tap_recording(tap);
        Ok(boxed(Some(server)))
    })
}

impl Face for FoxgloveServer {}

/// The server listening on `addr`, and the tap that feeds its clients.
async fn listen(addr: SocketAddr, queue_bytes: usize, limits: FoxgloveLimits) -> anyhow::Result<(FoxgloveServer, Tap)> {
    let listener = TcpListener::bind(addr).await.with_context(|| format!("foxglove.listen {addr}: cannot listen"))?;
    let local_addr = listener.local_addr().with_context(|| format!("foxglove.listen {addr}"))?;
    let hub = Hub::new(queue_bytes);
    let tap = hub.clone();
    let session_id = format!("forgemon-{}", super::host_now_ns());
    let accept = tokio::spawn(accept_loop(listener, hub.clone(), session_id, limits));
    tracing::info!(listen = %local_addr, "foxglove live view listening");
    Ok((FoxgloveServer { hub, local_addr, accept }, Box::new(move |m| tap.publish(m))))
}

impl FoxgloveServer {
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    pub fn stats(&self) -> HubStats {
        self.hub.stats()
    }
}

impl Drop for FoxgloveServer {
    fn drop(&mut self) {
        self.accept.abort();
        self.hub.close_all();
        let s = self.hub.stats();
        tracing::info!(
            clients = s.clients_served,
            queued = s.queued,
            dropped = s.dropped,
            bad_frames = s.bad_frames,
            "foxglove live view stopped"
        );
    }
}

/// Accept connections, each with a permit or refused, and log the drops while they grow.
async fn accept_loop(listener: TcpListener, hub: Hub, session_id: String, limits: FoxgloveLimits) {
    let permits = Arc::new(Semaphore::new(limits.max_clients));
    let refusals = Arc::new(Semaphore::new(REFUSALS_AT_ONCE));
    let mut tick = tokio::time::interval(DROP_LOG_INTERVAL);
    let mut logged_drops = 0;
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => match permits.clone().try_acquire_owned() {
                    Ok(permit) => {
                        tokio::spawn(connection(stream, peer, hub.clone(), session_id.clone(), limits, permit));
                    }
                    // Past the cap: a 503 saying why while few are refused, else closed here.
                    Err(_) => {
                        if let Ok(permit) = refusals.clone().try_acquire_owned() {
                            tokio::spawn(refuse(stream, peer, limits, permit));
                        }
                    }
                },
                // Out of descriptors and the like: wait a little rather than spin.
                Err(e) => {
                    tracing::warn!(error = %e, "foxglove: accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            },
            _ = tick.tick() => {
                let s = hub.stats();
                if s.dropped > logged_drops {
                    tracing::warn!(dropped = s.dropped, clients = s.clients_now, "foxglove: slow clients lost their oldest messages");
                    logged_drops = s.dropped;
                }
            }
        }
    }
}

/// The handshake's answer: the subprotocol echoed, or a refusal saying what is spoken here
/// (or, with `full` the cap, that the cap is reached).
#[allow(clippy::result_large_err, reason = "the type of tungstenite's handshake callback")]
fn negotiate(req: &Request, mut resp: Response, full: Option<usize>) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .any(|v| v.split(',').any(|p| p.trim() == SUBPROTOCOL));
    let refuse = |status: StatusCode, why: String| {
        let mut r = ErrorResponse::new(Some(why));
        *r.status_mut() = status;
        r
    };
    if !offered {
        return Err(refuse(StatusCode::BAD_REQUEST, format!("this server speaks the {SUBPROTOCOL} subprotocol only")));
    }
    if let Some(cap) = full {
        return Err(refuse(StatusCode::SERVICE_UNAVAILABLE, format!("{cap} clients are connected already")));
    }
    resp.headers_mut().insert("sec-websocket-protocol", HeaderValue::from_static(SUBPROTOCOL));
    Ok(resp)
}

fn ws_config() -> WebSocketConfig {
    WebSocketConfig::default()
        .max_message_size(Some(MAX_CLIENT_FRAME_BYTES))
        .max_frame_size(Some(MAX_CLIENT_FRAME_BYTES))
}

/// A connection past the cap: its handshake read (briefly) and answered 503.
#[allow(clippy::result_large_err, reason = "the type of tungstenite's handshake callback")]
async fn refuse(stream: TcpStream, peer: SocketAddr, limits: FoxgloveLimits, _permit: OwnedSemaphorePermit) {
    let cap = limits.max_clients;
    let handshake = tokio_tungstenite::accept_hdr_async_with_config(
        stream,
        |req: &Request, resp| negotiate(req, resp, Some(cap)),
        Some(ws_config()),
    );
    let _ = tokio::time::timeout(REFUSAL_TIMEOUT.min(limits.handshake_timeout), handshake).await;
    tracing::debug!(%peer, cap, "foxglove: a client was refused, the cap is reached");
}

/// One client, holding its permit until it leaves: the handshake, then its session.
#[allow(clippy::result_large_err, reason = "the type of tungstenite's handshake callback")]
async fn connection(
    stream: TcpStream,
    peer: SocketAddr,
    hub: Hub,
    session_id: String,
    limits: FoxgloveLimits,
    _permit: OwnedSemaphorePermit,
) {
    let handshake = tokio_tungstenite::accept_hdr_async_with_config(
        stream,
        |req: &Request, resp| negotiate(req, resp, None),
        Some(ws_config()),
    );
    let ws = match tokio::time::timeout(limits.handshake_timeout, handshake).await {
        Ok(Ok(ws)) => ws,
        Ok(Err(e)) => {
            tracing::info!(%peer, error = %e, "foxglove: handshake refused");
            return;
        }
        Err(_) => {
            tracing::info!(%peer, "foxglove: no handshake in time");
            return;
        }
    };
    let info = ServerMessage::ServerInfo {
        name: format!("forgemon {}", env!("CARGO_PKG_VERSION")),
        capabilities: Vec::new(),
        supported_encodings: Vec::new(),
        metadata: Default::default(),
        session_id,
    };
    let (client, outbox) = hub.connect(&info);
    tracing::info!(%peer, client, "foxglove client connected");
    let why = session(ws, &hub, client, &outbox, limits.idle_timeout).await;
    let dropped = hub.disconnect(client);
    tracing::info!(%peer, client, dropped, %why, "foxglove client disconnected");
}

/// A connected client's session: its frames read, its outbox written with a ping every
/// third of `idle`, until it leaves, goes quiet for `idle`, or the service stops; why it
/// ended.
async fn session(
    ws: WebSocketStream<TcpStream>,
    hub: &Hub,
    client: u64,
    outbox: &hub::Outbox,
    idle: Duration,
) -> String {
    let heard = IdleClock::new();
    let (mut sink, mut incoming) = ws.split();
    let reader = async {
        while let Some(frame) = incoming.next().await {
            heard.touch();
            match frame {
                Ok(Message::Text(t)) => hub.on_text(client, t.as_str()),
                Ok(Message::Binary(_)) => hub.on_unexpected(client, "binary"),
                Ok(Message::Close(_)) => break,
                Ok(_) => {} // ping/pong: tungstenite answers pings itself
                Err(e) => return format!("read failed: {e}"),
            }
        }
        "the client closed".to_string()
    };
    let writer = async {
        let every = (idle / 3).max(Duration::from_millis(10));
        let mut ping = tokio::time::interval_at(tokio::time::Instant::now() + every, every);
        ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tokio::select! {
                out = outbox.next() => {
                    let Some(out) = out else { break };
                    sink.feed(frame(out)).await?;
                    // Send what is queued in one write, then flush.
                    while let Some(Some(out)) = outbox.try_next() {
                        sink.feed(frame(out)).await?;
                    }
                    sink.flush().await?;
                }
                _ = ping.tick() => sink.send(Message::Ping(Bytes::new())).await?,
            }
        }
        let _ = sink.send(Message::Close(None)).await;
        Ok::<_, tokio_tungstenite::tungstenite::Error>(())
    };
    tokio::select! {
        why = reader => why,
        // Also ends a connection whose writer is stuck on a client that does not read.
        _ = hub.stopped() => "the service stopped".to_string(),
        () = heard.idle_for(idle) => format!("no frame from the client in {} s", idle.as_secs_f64()),
        r = writer => match r {
            Ok(()) => "the server closed it (stopping, or the client left its messages unread)".to_string(),
            Err(e) => format!("write failed: {e}"),
        },
    }
}

fn frame(out: Outgoing) -> Message {
    match out {
        Outgoing::Text(t) => Message::text(t),
        Outgoing::Data(d) => {
            Message::Binary(Bytes::from(protocol::message_data(d.subscription_id, d.log_time_ns, &d.payload)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(protocols: Option<&str>) -> Request {
        let mut r = Request::builder().uri("ws://127.0.0.1:8765/");
        if let Some(p) = protocols {
            r = r.header("Sec-WebSocket-Protocol", p);
        }
        r.body(()).expect("a request")
    }

    #[test]
    fn the_handshake_echoes_the_subprotocol_or_refuses_saying_why() {
        let ok = negotiate(&request(Some("other, foxglove.websocket.v1")), Response::new(()), None).expect("accepted");
        assert_eq!(ok.headers().get("sec-websocket-protocol").map(|v| v.as_bytes()), Some(SUBPROTOCOL.as_bytes()));
        let refused = |protocols, full| negotiate(&request(protocols), Response::new(()), full).expect_err("refused");
        for r in [refused(None, None), refused(Some("foxglove.websocket.v2"), None)] {
            assert_eq!(r.status(), StatusCode::BAD_REQUEST);
            assert!(r.body().as_deref().is_some_and(|b| b.contains(SUBPROTOCOL)));
        }
        let r = refused(Some(SUBPROTOCOL), Some(16));
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert!(r.body().as_deref().is_some_and(|b| b.contains("16 clients")));
    }
}
