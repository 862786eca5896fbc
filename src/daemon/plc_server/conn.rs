//! One PLC client's connection as tokio-modbus's server reads it: the socket behind the
//! frame gate (`gate.rs`), with the idle timeout and the connection's place under the cap.
//!
//! tokio-modbus 0.17 lets `on_connected` hand its server any transport; [`Gated`] is that
//! transport. A read returns only whole requests the gate passed; the gate's exception
//! answers are written here, between requests, so responses stay in request order. A
//! connection that completes no request within the idle timeout (counted from the accept
//! and from each request; bytes trickled in do not count) ends with `TimedOut`, and bytes
//! that are not Modbus TCP end it with `InvalidData`, and a connection whose place under
//! the cap went to a newer one (`daemon::slots`) with `ConnectionAborted`: tokio-modbus then drops
//! the socket.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::task::{Context, Poll, ready};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::{Instant, Sleep};

use super::gate::{self, Judged, MAX_ADU};
use crate::daemon::slots::Slot;

/// The socket `S` behind the frame gate (module doc).
pub struct Gated<S> {
    inner: S,
    /// Bytes read and not yet judged: at most one request and the start of the next.
    unjudged: Vec<u8>,
    /// The request being handed to the codec, and how much of it has been.
    passing: Vec<u8>,
    passed: usize,
    /// The gate's exception answer, and how much of it has been written.
    reply: Vec<u8>,
    replied: usize,
    idle: Pin<Box<Sleep>>,
    idle_timeout: Duration,
    /// Requests the gate answered itself.
    malformed: Arc<AtomicU64>,
    slot: Slot,
}

impl<S> Gated<S> {
    pub fn new(inner: S, idle_timeout: Duration, slot: Slot, malformed: Arc<AtomicU64>) -> Self {
        Gated {
            inner,
            unjudged: Vec::with_capacity(MAX_ADU),
            passing: Vec::with_capacity(MAX_ADU),
            passed: 0,
            reply: Vec::new(),
            replied: 0,
            idle: Box::pin(tokio::time::sleep(idle_timeout)),
            idle_timeout,
            malformed,
            slot,
        }
    }

    /// A request completed: the idle time counts again from now, and the connection keeps
    /// its place.
    fn active(&mut self) {
        self.idle.as_mut().reset(Instant::now() + self.idle_timeout);
        self.slot.admit();
    }

    /// Judge the first unjudged request: `true` when there was one to hand on or answer.
    fn judge(&mut self) -> io::Result<bool> {
        match gate::judge(&self.unjudged) {
            Judged::NeedMore => Ok(false),
            Judged::Pass { len } => {
                self.passing.clear();
                self.passing.extend(self.unjudged.drain(..len));
                self.passed = 0;
                self.active();
                Ok(true)
            }
            Judged::Answer { len, reply } => {
                self.unjudged.drain(..len);
                self.reply = reply.to_vec();
                self.replied = 0;
                self.malformed.fetch_add(1, Ordering::Relaxed);
                self.active();
                Ok(true)
            }
            Judged::Close(e) => Err(io::Error::new(io::ErrorKind::InvalidData, e)),
        }
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin> AsyncRead for Gated<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        if this.slot.poll_shed(cx) {
            let why = "closed for a newer connection: max_connections are open and this one made no request";
            return Poll::Ready(Err(io::Error::new(io::ErrorKind::ConnectionAborted, why)));
        }
        loop {
            // The gate's answer goes out before the next request is read.
            while this.replied < this.reply.len() {
                let n = ready!(Pin::new(&mut this.inner).poll_write(cx, &this.reply[this.replied..]))?;
                if n == 0 {
                    return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
                }
                this.replied += n;
            }
            if this.passed < this.passing.len() {
                let n = buf.remaining().min(this.passing.len() - this.passed);
                buf.put_slice(&this.passing[this.passed..this.passed + n]);
                this.passed += n;
                return Poll::Ready(Ok(()));
            }
            if this.judge()? {
                continue;
            }
            if this.idle.as_mut().poll(cx).is_ready() {
                let why = format!("no request for {:?}", this.idle_timeout);
                return Poll::Ready(Err(io::Error::new(io::ErrorKind::TimedOut, why)));
            }
            // The gate needs more, and a request is at most MAX_ADU long.
            let mut space = [0u8; MAX_ADU];
            let room = MAX_ADU.saturating_sub(this.unjudged.len()).max(1);
            let mut read = ReadBuf::new(&mut space[..room]);
            ready!(Pin::new(&mut this.inner).poll_read(cx, &mut read))?;
            if read.filled().is_empty() {
                // The client hung up; a half-sent request is dropped with it.
                return Poll::Ready(Ok(()));
            }
            this.unjudged.extend_from_slice(read.filled());
        }
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Gated<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
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
    use crate::daemon::slots::Slots;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    fn gated(s: tokio::io::DuplexStream, idle: Duration, slots: &Slots) -> Gated<tokio::io::DuplexStream> {
        Gated::new(s, idle, slots.open().expect("a slot"), Arc::new(AtomicU64::new(0)))
    }

    fn cx() -> Context<'static> {
        Context::from_waker(std::task::Waker::noop())
    }

    #[tokio::test]
    async fn a_request_keeps_the_place_and_a_shed_connection_ends_aborted() {
        let slots = Slots::new(2);
        let (mut client_a, server_a) = tokio::io::duplex(1024);
        let (_client_b, server_b) = tokio::io::duplex(1024);
        let (mut a, mut b) =
            (gated(server_a, Duration::from_secs(5), &slots), gated(server_b, Duration::from_secs(5), &slots));
        client_a.write_all(&[0, 1, 0, 0, 0, 6, 1, 0x03, 0, 0, 0, 1]).await.expect("write");
        let mut got = [0u8; 12];
        a.read_exact(&mut got).await.expect("a's request passes");
        // At the cap, a newcomer takes b's place (b made no request), not a's.
        let _c = slots.open().expect("a place");
        let err = b.read(&mut got).await.expect_err("b was shed");
        assert_eq!(err.kind(), io::ErrorKind::ConnectionAborted);
        assert!(matches!(Pin::new(&mut a).poll_read(&mut cx(), &mut ReadBuf::new(&mut got)), Poll::Pending));
    }

    #[tokio::test]
    async fn requests_pass_whole_and_malformed_ones_are_answered_in_order() {
        let slots = Slots::new(1);
        let (mut client, server) = tokio::io::duplex(1024);
        let mut g = gated(server, Duration::from_secs(5), &slots);
        // A read of 0 registers (transaction 7), then a good read of 1 (transaction 8).
        client.write_all(&[0, 7, 0, 0, 0, 6, 1, 0x03, 0, 0, 0, 0]).await.expect("write");
        client.write_all(&[0, 8, 0, 0, 0, 6, 1, 0x03, 0, 0, 0, 1]).await.expect("write");
        let mut got = [0u8; 12];
        g.read_exact(&mut got).await.expect("the good request");
        assert_eq!(got, [0, 8, 0, 0, 0, 6, 1, 0x03, 0, 0, 0, 1]);
        let mut reply = [0u8; 9];
        client.read_exact(&mut reply).await.expect("the exception");
        // transaction 7, protocol 0, length 3, unit 1, 0x83, illegal data value
        assert_eq!(reply, [0, 7, 0, 0, 0, 3, 1, 0x83, 0x03]);
    }

    #[tokio::test]
    async fn an_idle_or_trickling_client_times_out_and_garbage_is_refused() {
        let slots = Slots::new(2);
        let (mut client, server) = tokio::io::duplex(1024);
        let mut g = gated(server, Duration::from_millis(200), &slots);
        // Trickled bytes of a request that never completes do not keep it open.
        client.write_all(&[0, 1, 0]).await.expect("write");
        let mut buf = [0u8; 16];
        let e = g.read(&mut buf).await.expect_err("times out");
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
        let (mut client, server) = tokio::io::duplex(1024);
        let mut g = gated(server, Duration::from_secs(30), &slots);
        client.write_all(b"GET / HTTP/1.1\r\n").await.expect("write");
        let e = g.read(&mut buf).await.expect_err("refused");
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(e.to_string().contains("protocol identifier"), "{e}");
    }
}
