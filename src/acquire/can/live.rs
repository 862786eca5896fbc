//! The live SocketCAN driver: a few dozen lines of tokio around [`CanDecoder`]. It opens
//! the interface (`socketcan::tokio::CanSocket`), asks the kernel to stamp frames on
//! arrival (`SO_TIMESTAMPNS`; without it frames are stamped when read and the timestamps
//! are not trusted for gap counting), reconnects with `acquire::next_backoff_ms`, reports
//! its state and counters as `Status` events, flushes a partial batch when the bus goes
//! quiet, and hands everything over with `acquire::offer`, which never waits. A CAN FD
//! mapping opens an FD socket (`socketcan::tokio::CanFdSocket`, `CAN_RAW_FD_FRAMES`),
//! which receives classic and FD frames alike; [`LoggedFrame::feed`] decodes the kind the
//! mapping reads and counts the other.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use socketcan::tokio::{CanFdSocket, CanSocket};
use socketcan::{CanAnyFrame, SocketOptions};
use tokio::sync::{mpsc, watch};

use crate::acquire::outage::OutageLog;
use crate::acquire::{SourceEvent, next_backoff_ms, offer};

use super::candump::LoggedFrame;
use super::decoder::{CanDecoder, CanTiming};
use super::signal::CanMapping;

/// How often the driver reports its counters while running.
pub const STATUS_EVERY: Duration = Duration::from_secs(1);

/// One CAN source of the service.
#[derive(Debug, Clone, PartialEq)]
pub struct CanSourceConfig {
    /// The source's name (in batches, gaps and status).
    pub name: String,
    /// The SocketCAN interface, for example `can0` or `vcan0`.
    pub iface: String,
    pub mapping: CanMapping,
    pub timing: CanTiming,
}

fn ns_since_epoch(t: SystemTime) -> i64 {
    t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as i64)
}

/// A classic or an FD socket, by the mapping.
enum Sock {
    Classic(CanSocket),
    Fd(CanFdSocket),
}

impl Sock {
    fn open(iface: &str, fd: bool) -> std::io::Result<Sock> {
        Ok(if fd { Sock::Fd(CanFdSocket::open(iface)?) } else { Sock::Classic(CanSocket::open(iface)?) })
    }

    fn set_recv_timestamp(&self, on: bool) -> bool {
        match self {
            Sock::Classic(s) => s.set_recv_timestamp(on).is_ok(),
            Sock::Fd(s) => s.set_recv_timestamp(on).is_ok(),
        }
    }

    /// The next frame and its time, ns since the epoch: the kernel's stamp when
    /// `kernel_time`, else the time it was read.
    async fn read(&self, kernel_time: bool) -> std::io::Result<(LoggedFrame, i64)> {
        let now = || ns_since_epoch(SystemTime::now());
        let (frame, t_ns) = match (self, kernel_time) {
            (Sock::Classic(s), true) => {
                s.read_frame_with_timestamp().await.map(|(f, t)| (f.into(), ns_since_epoch(t)))?
            }
            (Sock::Classic(s), false) => s.read_frame().await.map(|f| (CanAnyFrame::from(f), now()))?,
            (Sock::Fd(s), true) => s.read_frame_with_timestamp().await.map(|(f, t)| (f, ns_since_epoch(t)))?,
            (Sock::Fd(s), false) => s.read_frame().await.map(|f| (f, now()))?,
        };
        Ok((LoggedFrame::from_any(&frame), t_ns))
    }
}

/// Send `events` and clear them; false once the service has gone.
fn send(tx: &mpsc::Sender<SourceEvent>, events: &mut Vec<SourceEvent>, dec: &mut CanDecoder) -> bool {
    let mut open = true;
    for e in events.drain(..) {
        open &= offer(tx, e, dec.counters_mut());
    }
    open
}

/// Report `state`; the detail defaults to the decoder's own counts.
fn status(tx: &mpsc::Sender<SourceEvent>, dec: &mut CanDecoder, state: &str, detail: Option<String>) -> bool {
    let detail = detail.unwrap_or_else(|| dec.detail());
    let s = dec.counters().status(dec.source(), state, detail);
    offer(tx, SourceEvent::Status(s), dec.counters_mut())
}

/// Read `cfg.iface` until `shutdown` turns true or the receiver of `tx` is dropped. Never
/// returns on a bus or socket error: it reports it and reconnects with backoff.
pub async fn run(cfg: CanSourceConfig, tx: mpsc::Sender<SourceEvent>, mut shutdown: watch::Receiver<bool>) {
    let mut dec = CanDecoder::new(cfg.name.clone(), cfg.mapping.clone(), cfg.timing);
    let quiet =
        Duration::from_secs_f64((2.0 * cfg.timing.period_ns * cfg.timing.batch_samples as f64 * 1e-9).max(0.02));
    let mut backoff_ms = 0;
    let mut ever_connected = false;
    let mut events = Vec::new();
    let mut outage = OutageLog::new();
    loop {
        if *shutdown.borrow() {
            break;
        }
        let sock = match Sock::open(&cfg.iface, cfg.mapping.is_fd()) {
            Ok(s) => s,
            Err(e) => {
                backoff_ms = next_backoff_ms(backoff_ms);
                if let Some(line) = outage.failed(&format!("{}: {e}", cfg.iface), ns_since_epoch(SystemTime::now())) {
                    tracing::warn!(source = %cfg.name, "{line}");
                }
                let detail = format!("{}: {e}; retry in {backoff_ms} ms", cfg.iface);
                if !status(&tx, &mut dec, "reconnecting", Some(detail)) {
                    return;
                }
                tokio::select! {
                    _ = tokio::time::sleep(Duration::from_millis(backoff_ms)) => {}
                    _ = shutdown.changed() => {}
                }
                continue;
            }
        };
        if ever_connected {
            dec.counters_mut().reconnects += 1;
        }
        if let Some(line) = outage.opened(&cfg.iface, ns_since_epoch(SystemTime::now())) {
            tracing::info!(source = %cfg.name, "{line}");
        }
        ever_connected = true;
        backoff_ms = 0;
        let kernel_time = sock.set_recv_timestamp(true);
        dec.set_trust_timestamps(kernel_time && cfg.timing.trust_timestamps);
        let detail = format!("{} ({} timestamps)", cfg.iface, if kernel_time { "kernel" } else { "host" });
        if !status(&tx, &mut dec, "connected", Some(detail)) {
            return;
        }
        let mut ticker = tokio::time::interval(STATUS_EVERY);
        let lost = loop {
            let read = sock.read(kernel_time);
            tokio::select! {
                _ = shutdown.changed() => {
                    dec.flush(&mut events);
                    send(&tx, &mut events, &mut dec);
                    status(&tx, &mut dec, "stopped", None);
                    return;
                }
                _ = ticker.tick() => {
                    if !status(&tx, &mut dec, "connected", None) {
                        return;
                    }
                }
                r = tokio::time::timeout(quiet, read) => match r {
                    Err(_) => dec.flush(&mut events),
                    Ok(Ok((frame, t_ns))) => frame.feed(t_ns, &mut dec, &mut events),
                    Ok(Err(e)) => break e,
                },
            }
            if !send(&tx, &mut events, &mut dec) {
                return;
            }
        };
        // The link went away (interface down, adapter unplugged): keep the decoder's
        // state, so the counter tells how many samples the outage cost on return.
        dec.flush(&mut events);
        if !send(&tx, &mut events, &mut dec) {
            return;
        }
        backoff_ms = next_backoff_ms(backoff_ms);
        tracing::warn!(source = %cfg.name, "link lost: {}: {lost}", cfg.iface);
        outage.lost(ns_since_epoch(SystemTime::now()));
        if !status(&tx, &mut dec, "reconnecting", Some(format!("{}: {lost}", cfg.iface))) {
            return;
        }
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_millis(backoff_ms)) => {}
            _ = shutdown.changed() => {}
        }
    }
    status(&tx, &mut dec, "stopped", None);
}
