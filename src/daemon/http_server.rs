//! The HTTP server under `/status`, `/metrics`, the dashboard and the faces' routes (issue
//! 39): hyper's HTTP/1 connections on the service's listener, with limits that keep a
//! client without the token from starving those with it.
//!
//! - **A cap, counted at accept** (`daemon::slots`): at most `max_connections` connections are
//!   held. At the cap a newcomer takes the slot of the oldest connection that has not yet
//!   passed the token (it sent nothing, part of a head, or only refused requests), which is
//!   closed; when every connection has passed it, the newcomer is closed instead.
//! - **A header timeout** (hyper's `header_read_timeout`): a request head must be complete
//!   within `header_timeout` of the connection's opening or of the end of its previous
//!   response, so a client that sends nothing, half a head or a byte at a time is closed.
//! - **An idle timeout**: a connection on which no byte moves either way for `idle_timeout`
//!   is closed (a stalled body, a response its client does not read).
//! - A request refused for want of the token is answered and its connection closed
//!   (`dashboard::auth`).
//! - **Accept never stops**: when it fails (out of descriptors), the oldest unadmitted
//!   connection is shed and accept tries again a moment later, neither spinning nor giving up.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinSet;
use tower::ServiceExt as _;

use super::idle::IdleClock;
use super::slots::{Slot, SlotCounts, Slots};
use crate::config::server_limits::HttpLimits;

/// How long accept waits after a failure (out of descriptors) before it tries again.
pub const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);
/// How often shed and refused connections and failed accepts are logged while they grow.
const LOG_INTERVAL: Duration = Duration::from_secs(10);

/// Serve `app` on `listener` within `limits`, until the task is dropped (which closes every
/// connection).
pub async fn serve(listener: TcpListener, app: Router, limits: HttpLimits) {
    let slots = Slots::new(limits.max_connections);
    let mut connections = JoinSet::new();
    let mut log = tokio::time::interval(LOG_INTERVAL);
    let mut logged = SlotCounts::default();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    // Refused: the stream is dropped here, closing it.
                    if let Some(slot) = slots.open() {
                        connections.spawn(connection(stream, slot, app.clone(), limits));
                    }
                }
                // Out of descriptors (EMFILE) or the like: free one if an unadmitted
                // connection holds it, and wait a moment rather than spin.
                Err(_) => {
                    slots.accept_failed();
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                }
            },
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
            _ = log.tick() => log_counts(&slots, &mut logged),
        }
    }
}

/// Log the slots' counts when they grew since `logged`.
fn log_counts(slots: &Slots, logged: &mut SlotCounts) {
    let (now, held) = (slots.counts(), slots.len());
    if now != *logged {
        tracing::warn!(
            held,
            shed = now.shed,
            refused = now.refused,
            accept_failures = now.accept_failures,
            "http: connections at the cap (shed: oldest without the token; refused: every slot held with it)"
        );
        *logged = now;
    }
}

/// One connection, until it ends, times out or is shed; then its slot is freed.
async fn connection(stream: TcpStream, slot: Slot, app: Router, limits: HttpLimits) {
    let activity = Arc::new(IdleClock::new());
    let io = TokioIo::new(Watched { inner: stream, activity: activity.clone() });
    let admission = slot.admission();
    let service = hyper::service::service_fn(move |mut req: hyper::Request<hyper::body::Incoming>| {
        req.extensions_mut().insert(admission.clone());
        app.clone().oneshot(req)
    });
    let mut http1 = hyper::server::conn::http1::Builder::new();
    http1.timer(TokioTimer::new()).header_read_timeout(limits.header_timeout);
    let why = tokio::select! {
        r = http1.serve_connection(io, service) => match r {
            Ok(()) => "closed".to_string(),
            Err(e) => format!("{e}"),
        },
        () = slot.shed() => "shed for a newcomer at the cap".to_string(),
        () = activity.idle_for(limits.idle_timeout) => "idle".to_string(),
    };
    tracing::trace!(id = slot.id(), admitted = slot.is_admitted(), %why, "http connection ended");
}

/// A connection's stream that notes each time bytes move (`IdleClock`).
struct Watched {
    inner: TcpStream,
    activity: Arc<IdleClock>,
}

impl Watched {
    fn moved<T>(&self, r: Poll<io::Result<T>>, moved: bool) -> Poll<io::Result<T>> {
        if moved {
            self.activity.touch();
        }
        r
    }
}

impl AsyncRead for Watched {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let r = Pin::new(&mut self.inner).poll_read(cx, buf);
        let moved = buf.filled().len() > before;
        self.moved(r, moved)
    }
}

impl AsyncWrite for Watched {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write(cx, buf);
        let moved = matches!(r, Poll::Ready(Ok(n)) if n > 0);
        self.moved(r, moved)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        let moved = matches!(r, Poll::Ready(Ok(n)) if n > 0);
        self.moved(r, moved)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
