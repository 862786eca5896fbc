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
//! counted; one that does not complete the handshake in time is dropped.

pub mod hub;
pub mod protocol;

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::Context;
use futures_util::{SinkExt, StreamExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::{Bytes, Message};

use super::faces::{Face, FaceContext, boxed};
use crate::record::tap::Tap;
use futures_util::future::BoxFuture;

use hub::{CLIENT_QUEUE_BYTES, Hub, HubStats, Outgoing};
use protocol::{SUBPROTOCOL, ServerMessage};

/// Clients served at once; more are refused at the handshake.
pub const MAX_CLIENTS: u64 = 16;
/// Time a connection has to complete the WebSocket handshake.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
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
        let (server, tap) = listen(addr, CLIENT_QUEUE_BYTES).await?;
        ctx.tap_recording(tap);
        Ok(boxed(Some(server)))
    })
}

impl Face for FoxgloveServer {}

/// The server listening on `addr`, and the tap that feeds its clients.
async fn listen(addr: SocketAddr, queue_bytes: usize) -> anyhow::Result<(FoxgloveServer, Tap)> {
    let listener = TcpListener::bind(addr).await.with_context(|| format!("foxglove.listen {addr}: cannot listen"))?;
    let local_addr = listener.local_addr().with_context(|| format!("foxglove.listen {addr}"))?;
    let hub = Hub::new(queue_bytes);
    let tap = hub.clone();
    let session_id = format!("forgemon-{}", super::host_now_ns());
    let accept = tokio::spawn(accept_loop(listener, hub.clone(), session_id));
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

async fn accept_loop(listener: TcpListener, hub: Hub, session_id: String) {
    let mut tick = tokio::time::interval(DROP_LOG_INTERVAL);
    let mut logged_drops = 0;
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    tokio::spawn(connection(stream, peer, hub.clone(), session_id.clone()));
                }
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

/// The handshake's answer: the subprotocol echoed, or a refusal saying what is spoken here.
#[allow(clippy::result_large_err, reason = "the type of tungstenite's handshake callback")]
fn negotiate(req: &Request, mut resp: Response, full: bool) -> Result<Response, ErrorResponse> {
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
    if full {
        return Err(refuse(StatusCode::SERVICE_UNAVAILABLE, format!("{MAX_CLIENTS} clients are connected already")));
    }
    resp.headers_mut().insert("sec-websocket-protocol", HeaderValue::from_static(SUBPROTOCOL));
    Ok(resp)
}

#[allow(clippy::result_large_err, reason = "the type of tungstenite's handshake callback")]
async fn connection(stream: TcpStream, peer: SocketAddr, hub: Hub, session_id: String) {
    let full = hub.stats().clients_now >= MAX_CLIENTS;
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_CLIENT_FRAME_BYTES))
        .max_frame_size(Some(MAX_CLIENT_FRAME_BYTES));
    let handshake = tokio_tungstenite::accept_hdr_async_with_config(
        stream,
        |req: &Request, resp| negotiate(req, resp, full),
        Some(config),
    );
    let ws = match tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake).await {
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
    let (mut sink, mut incoming) = ws.split();
    let reader = async {
        while let Some(frame) = incoming.next().await {
            match frame {
                Ok(Message::Text(t)) => hub.on_text(client, t.as_str()),
                Ok(Message::Binary(_)) => hub.on_unexpected(client, "binary"),
                Ok(Message::Close(_)) => break,
                Ok(_) => {} // ping/pong: tungstenite answers pings itself
                Err(e) => {
                    tracing::info!(%peer, client, error = %e, "foxglove: client read failed");
                    break;
                }
            }
        }
    };
    let writer = async {
        while let Some(out) = outbox.next().await {
            sink.feed(frame(out)).await?;
            // Send what is queued in one write, then flush.
            while let Some(Some(out)) = outbox.try_next() {
                sink.feed(frame(out)).await?;
            }
            sink.flush().await?;
        }
        let _ = sink.send(Message::Close(None)).await;
        Ok::<_, tokio_tungstenite::tungstenite::Error>(())
    };
    let why = tokio::select! {
        _ = reader => "the client closed".to_string(),
        // Also ends a connection whose writer is stuck on a client that does not read.
        _ = hub.stopped() => "the service stopped".to_string(),
        r = writer => match r {
            Ok(()) => "the server closed it (stopping, or the client left its messages unread)".to_string(),
            Err(e) => format!("write failed: {e}"),
        },
    };
    let dropped = hub.disconnect(client);
    tracing::info!(%peer, client, dropped, %why, "foxglove client disconnected");
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
        let ok = negotiate(&request(Some("other, foxglove.websocket.v1")), Response::new(()), false).expect("accepted");
        assert_eq!(ok.headers().get("sec-websocket-protocol").map(|v| v.as_bytes()), Some(SUBPROTOCOL.as_bytes()));
        let refused = |protocols, full| negotiate(&request(protocols), Response::new(()), full).expect_err("refused");
        for r in [refused(None, false), refused(Some("foxglove.websocket.v2"), false)] {
            assert_eq!(r.status(), StatusCode::BAD_REQUEST);
            assert!(r.body().as_deref().is_some_and(|b| b.contains(SUBPROTOCOL)));
        }
        let r = refused(Some(SUBPROTOCOL), true);
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert!(r.body().as_deref().is_some_and(|b| b.contains("16 clients")));
    }
}
