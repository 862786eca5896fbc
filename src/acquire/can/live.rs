//! The live SocketCAN driver: a few dozen lines of tokio around [`CanDecoder`]. It opens
//! the interface (`socketcan::tokio::CanSocket`), asks the kernel to stamp frames on
//! arrival (`SO_TIMESTAMPNS`; without it frames are stamped when read and the timestamps
//! are not trusted for gap counting), reconnects with `acquire::next_backoff_ms`, reports
//! its state and counters as `Status` events, flushes a partial batch when the bus goes
//! quiet, and hands everything over with `acquire::offer`, which never waits.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use socketcan::tokio::CanSocket;
use socketcan::{CanFrame, EmbeddedFrame, Id, SocketOptions};
use tokio::sync::{mpsc, watch};

use crate::acquire::{SourceEvent, next_backoff_ms, offer};

use super::decoder::{CanDecoder, CanTiming};
use super::signal::{CanMapping, FrameId};

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
    loop {
        if *shutdown.borrow() {
            break;
        }
        let sock = match CanSocket::open(&cfg.iface) {
            Ok(s) => s,
            Err(e) => {
                backoff_ms = next_backoff_ms(backoff_ms);
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
        ever_connected = true;
        backoff_ms = 0;
        let kernel_time = sock.set_recv_timestamp(true).is_ok();
        dec.set_trust_timestamps(kernel_time && cfg.timing.trust_timestamps);
        let detail = format!("{} ({} timestamps)", cfg.iface, if kernel_time { "kernel" } else { "host" });
        if !status(&tx, &mut dec, "connected", Some(detail)) {
            return;
        }
        let mut ticker = tokio::time::interval(STATUS_EVERY);
        let lost = loop {
            let read = async {
                if kernel_time {
                    sock.read_frame_with_timestamp().await.map(|(f, t)| (f, ns_since_epoch(t)))
                } else {
                    sock.read_frame().await.map(|f| (f, ns_since_epoch(SystemTime::now())))
                }
            };
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
                    Ok(Ok((CanFrame::Data(f), t_ns))) => {
                        let frame = match f.id() {
                            Id::Standard(id) => FrameId::standard(id.as_raw()),
                            Id::Extended(id) => FrameId::extended(id.as_raw()),
                        };
                        dec.push(t_ns, frame, f.data(), &mut events);
                    }
                    Ok(Ok(_)) => dec.skip_unsupported(),
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
