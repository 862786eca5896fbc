//! A `candump -L` log as a live source of the service: bus traffic captured on the plant
//! floor (or written by the simulated device) replayed through the same decoder and the
//! same `SourceEvent`s as a SocketCAN interface, as fast as possible or at the pace the
//! log was recorded. Malformed lines are counted as decode errors and the first one is
//! named (file and line) in the status.
//!
//! Deterministic: batches are cut by the decoder alone (its batch length, gaps, the end),
//! never by the pace of the replay, and device time counts in integer ns from the first
//! frame, so two runs of the same log give byte-identical batches and results.

use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::{mpsc, watch};

use crate::acquire::{SourceEvent, offer};

use super::CanError;
use super::candump::CandumpReader;
use super::decoder::CanDecoder;
use super::live::CanSourceConfig;

/// Replay `path` into `tx`. With `realtime`, frames are released at the log's own pace
/// (measured from its first frame). Returns when the log ends, `shutdown` turns true, or
/// the receiver is dropped; only an unreadable file is an error.
pub async fn run_log(
    cfg: CanSourceConfig,
    path: PathBuf,
    realtime: bool,
    tx: mpsc::Sender<SourceEvent>,
    shutdown: watch::Receiver<bool>,
) -> Result<(), CanError> {
    let origin = path.display().to_string();
    let text =
        tokio::fs::read_to_string(&path).await.map_err(|source| CanError::Io { origin: origin.clone(), source })?;
    let mut dec = CanDecoder::new(cfg.name.clone(), cfg.mapping.clone(), cfg.timing);
    let mut reader = CandumpReader::new(origin.clone(), text.as_bytes());
    let mut events = Vec::new();
    let mut first_bad: Option<String> = None;
    let start = tokio::time::Instant::now();
    let mut t_first_ns: Option<i64> = None;
    let status = |dec: &mut CanDecoder, state: &str, first_bad: &Option<String>| {
        let detail = match first_bad {
            Some(b) => format!("{origin}: {}; first bad line {b}", dec.detail()),
            None => format!("{origin}: {}", dec.detail()),
        };
        let s = dec.counters().status(dec.source(), state, detail);
        offer(&tx, SourceEvent::Status(s), dec.counters_mut())
    };
    if !status(&mut dec, "connected", &first_bad) {
        return Ok(());
    }
    loop {
        if *shutdown.borrow() {
            break;
        }
        match reader.next_frame() {
            Ok(Some(f)) => {
                if realtime {
                    let t0 = *t_first_ns.get_or_insert(f.t_ns);
                    let due = start + Duration::from_nanos(f.t_ns.saturating_sub(t0).max(0) as u64);
                    // Wait without flushing: a batch cut at the pace of the replay would
                    // make each run's batches, and so its results, differ.
                    tokio::time::sleep_until(due).await;
                }
                f.feed(&mut dec, &mut events);
            }
            Ok(None) => break,
            Err(CanError::LogLine { origin, line, .. }) => {
                dec.counters_mut().decode_errors += 1;
                first_bad.get_or_insert(format!("{origin}:{line}"));
            }
            Err(e) => return Err(e),
        }
        for e in events.drain(..) {
            if !offer(&tx, e, dec.counters_mut()) {
                return Ok(());
            }
        }
    }
    dec.flush(&mut events);
    for e in events.drain(..) {
        offer(&tx, e, dec.counters_mut());
    }
    status(&mut dec, "finished", &first_bad);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{CanDevice, CanTiming, forgemon_mapping};
    use super::*;
    use crate::signal::capture::CaptureRow;

    #[tokio::test]
    async fn a_log_replays_as_batches_and_counts_bad_lines() {
        let rows: Vec<CaptureRow> = (0..500)
            .map(|k| CaptureRow { t_s: 3.0 + k as f64 * 200e-6, load_n: k as f64 * 100.0, disp_m: 0.1, acc_mps2: 9.75 })
            .collect();
        let mut log = Vec::new();
        CanDevice::new(forgemon_mapping()).write_log(&mut log, "can0", &rows).unwrap();
        log.extend_from_slice(b"garbage\n");
        let dir = std::env::temp_dir().join(format!("forgemon-can-log-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bus.log");
        std::fs::write(&path, &log).unwrap();
        let cfg = CanSourceConfig {
            name: "bus".into(),
            iface: "bus.log".into(),
            mapping: forgemon_mapping(),
            timing: CanTiming::new(5000.0, 0.02, true),
        };
        let (tx, mut rx) = mpsc::channel(100);
        let (_stop, stop_rx) = watch::channel(false);
        run_log(cfg, path.clone(), false, tx, stop_rx).await.unwrap();
        let mut samples = 0;
        let mut last = None;
        while let Some(e) = rx.recv().await {
            match e {
                SourceEvent::Batch(b) => samples += b.len(),
                SourceEvent::Gap(g) => panic!("{g:?}"),
                SourceEvent::Status(s) => last = Some(s),
            }
        }
        assert_eq!(samples, 500);
        let s = last.unwrap();
        assert_eq!((s.state.as_str(), s.decode_errors, s.samples), ("finished", 1, 500));
        assert!(s.detail.contains("bus.log:501"), "{}", s.detail);
        let e = run_log(
            CanSourceConfig {
                name: "x".into(),
                iface: "x".into(),
                mapping: forgemon_mapping(),
                timing: CanTiming::new(5000.0, 0.02, true),
            },
            dir.join("missing.log"),
            false,
            mpsc::channel(1).0,
            watch::channel(false).1,
        )
        .await
        .unwrap_err();
        assert!(e.to_string().contains("missing.log"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
