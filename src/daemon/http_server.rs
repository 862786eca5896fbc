//! The HTTP server under `/status`, `/metrics`, the dashboard and the faces' routes (issue
//! 39): hyper's HTTP/1 connections on the service's listener, with limits that keep a
//! client without the token from starving those with it.
//!
//! - **A cap, counted at accept** ([`Slots`]): at most `max_connections` connections are
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

use std::collections::BTreeMap;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;
use tokio::task::JoinSet;
use tower::ServiceExt as _;

use super::idle::IdleClock;
use crate::config::server_limits::HttpLimits;

/// How long accept waits after a failure (out of descriptors) before it tries again.
pub const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);
/// How often shed and refused connections and failed accepts are logged while they grow.
const LOG_INTERVAL: Duration = Duration::from_secs(10);

/// A request's connection as the token check sees it (a request extension): marked once a
/// request on it passed.
#[derive(Clone, Debug, Default)]
pub struct Admission(Arc<AtomicBool>);

impl Admission {
    /// A request on this connection passed the token.
    pub fn admit(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    pub fn is_admitted(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// One connection's slot: its place in accept order, its admission, and how it is told to
/// close when a newcomer takes the slot.
#[derive(Clone, Debug)]
pub struct Slot {
    pub id: u64,
    pub admission: Admission,
    shed: Arc<Notify>,
}

impl Slot {
    /// Resolves once a newcomer took this slot.
    pub async fn shed(&self) {
        self.shed.notified().await;
    }
}

/// What the slots have done since the server started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlotCounts {
    /// Connections closed to make room for a newcomer (or a descriptor, when accept failed).
    pub shed: u64,
    /// Newcomers closed because every slot held an admitted connection.
    pub refused: u64,
    /// Accepts that failed (out of descriptors and the like).
    pub accept_failures: u64,
}

/// The connections held, in accept order, and the cap.
#[derive(Debug)]
pub struct Slots {
    cap: usize,
    open: BTreeMap<u64, Slot>,
    next_id: u64,
    pub counts: SlotCounts,
}

impl Slots {
    pub fn new(cap: usize) -> Self {
        Slots { cap: cap.max(1), open: BTreeMap::new(), next_id: 0, counts: SlotCounts::default() }
    }

    /// A slot for a connection just accepted: a free one, or the oldest unadmitted
    /// connection's, which is told to close; `None` when admitted connections hold them all.
    pub fn open(&mut self) -> Option<Slot> {
        if self.open.len() >= self.cap && !self.shed_oldest_unadmitted() {
            self.counts.refused += 1;
            return None;
        }
        let slot = Slot { id: self.next_id, admission: Admission::default(), shed: Arc::new(Notify::new()) };
        self.next_id += 1;
        self.open.insert(slot.id, slot.clone());
        Some(slot)
    }

    /// Tell the oldest connection that has not passed the token to close and free its slot;
    /// whether there was one.
    pub fn shed_oldest_unadmitted(&mut self) -> bool {
        let Some(id) = self.open.values().find(|s| !s.admission.is_admitted()).map(|s| s.id) else {
            return false;
        };
        if let Some(slot) = self.open.remove(&id) {
            slot.shed.notify_one();
            self.counts.shed += 1;
        }
        true
    }

    /// The connection `id` ended (a no-op when it was shed).
    pub fn close(&mut self, id: u64) {
        self.open.remove(&id);
    }

    /// Connections held now.
    pub fn len(&self) -> usize {
        self.open.len()
    }

    pub fn is_empty(&self) -> bool {
        self.open.is_empty()
    }
}

/// Serve `app` on `listener` within `limits`, until the task is dropped (which closes every
/// connection).
pub async fn serve(listener: TcpListener, app: Router, limits: HttpLimits) {
    let slots = Arc::new(Mutex::new(Slots::new(limits.max_connections)));
    let mut connections = JoinSet::new();
    let mut log = tokio::time::interval(LOG_INTERVAL);
    let mut logged = SlotCounts::default();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => {
                    // Refused: the stream is dropped here, closing it.
                    if let Some(slot) = slots.lock().ok().and_then(|mut s| s.open()) {
                        connections.spawn(connection(stream, slot, app.clone(), limits, slots.clone()));
                    }
                }
                // Out of descriptors (EMFILE) or the like: free one if an unadmitted
                // connection holds it, and wait a moment rather than spin.
                Err(_) => {
                    if let Ok(mut s) = slots.lock() {
                        s.counts.accept_failures += 1;
                        s.shed_oldest_unadmitted();
                    }
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                }
            },
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
            _ = log.tick() => log_counts(&slots, &mut logged),
        }
    }
}

/// Log the slots' counts when they grew since `logged`.
fn log_counts(slots: &Mutex<Slots>, logged: &mut SlotCounts) {
    let Ok((now, held)) = slots.lock().map(|s| (s.counts, s.len())) else { return };
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
async fn connection(stream: TcpStream, slot: Slot, app: Router, limits: HttpLimits, slots: Arc<Mutex<Slots>>) {
    let activity = Arc::new(IdleClock::new());
    let io = TokioIo::new(Watched { inner: stream, activity: activity.clone() });
    let admission = slot.admission.clone();
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
    tracing::trace!(id = slot.id, admitted = slot.admission.is_admitted(), %why, "http connection ended");
    if let Ok(mut s) = slots.lock() {
        s.close(slot.id);
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `slot` was told to close.
    fn was_shed(slot: &Slot) -> bool {
        let shed = slot.shed();
        let mut shed = std::pin::pin!(shed);
        let waker = std::task::Waker::noop();
        shed.as_mut().poll(&mut Context::from_waker(waker)).is_ready()
    }

    #[test]
    fn at_the_cap_a_newcomer_sheds_the_oldest_unadmitted_connection() {
        let mut slots = Slots::new(3);
        let s: Vec<Slot> = (0..3).map(|_| slots.open().expect("room")).collect();
        assert_eq!(slots.len(), 3);
        s[0].admission.admit();
        // The fourth takes the slot of the oldest not admitted (1), not of the admitted 0.
        let d = slots.open().expect("a slot shed");
        assert!(was_shed(&s[1]) && !was_shed(&s[0]) && !was_shed(&s[2]));
        assert_eq!((slots.len(), slots.counts.shed), (3, 1));
        // A shed connection ending frees nothing more; one that ends frees its slot.
        slots.close(s[1].id);
        assert_eq!(slots.len(), 3);
        s[2].admission.admit();
        d.admission.admit();
        // Every slot admitted: the newcomer is refused, and no one is shed.
        assert!(slots.open().is_none());
        assert_eq!(slots.counts, SlotCounts { shed: 1, refused: 1, accept_failures: 0 });
        assert!(!slots.shed_oldest_unadmitted());
        slots.close(s[0].id);
        let e = slots.open().expect("a free slot");
        assert!(!was_shed(&e));
        assert_eq!((slots.len(), slots.counts.shed), (3, 1));
    }

    #[test]
    fn a_cap_of_zero_still_holds_one_connection() {
        let mut slots = Slots::new(0);
        let a = slots.open().expect("one");
        let b = slots.open().expect("sheds the first");
        assert!(was_shed(&a) && !was_shed(&b));
        assert_eq!(slots.len(), 1);
    }
}
