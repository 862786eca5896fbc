//! The tokio side of the serial transport: open the port (tokio-serial), feed what it reads
//! to the sans-IO decoder of the configured format, and hand batches, gaps and status to
//! the service through `acquire::offer`, never waiting on a full channel. A read error or
//! end of file closes the port; it is reopened with backoff, and the sequence numbers of
//! the frames that follow record the samples lost meanwhile as a `Gap`. A port that cannot
//! be opened is logged at warn level with its path and cause (`acquire::outage`: again only
//! when the cause changes or every few minutes), and at info level when it opens again. A
//! path is reopened only while it leads to the device it first opened, unless it is a
//! `/dev/serial/by-id/` name (`identity` states the rule).

use std::future::Future;
use std::io;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt};
use tokio::sync::{mpsc, watch};

use super::ascii::{AsciiEvent, DEFAULT_ASCII_BATCH_S, LineDecoder};
use super::frame::FrameDecoder;
use super::identity::DeviceGuard;
use super::tracker::FrameTracker;
use crate::acquire::outage::OutageLog;
use crate::acquire::{BACKOFF_START_MS, Backpressure, ChannelSpec, Counters, SourceEvent, next_backoff_ms, offer};

/// Interval between periodic status reports, ms.
pub const DEFAULT_STATUS_INTERVAL_MS: u64 = 1000;
/// An ASCII batch in progress is closed after the line has been quiet this long, ms.
pub const ASCII_IDLE_FLUSH_MS: u64 = 50;
/// Read buffer size, bytes.
pub const READ_BUF_BYTES: usize = 64 * 1024;

/// Which of the two §7 encodings the device speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SerialFormat {
    /// COBS frames with CRC-32C (the default).
    Binary,
    /// `t_s,v0,v1,...` lines in physical units.
    Ascii,
}

/// One serial source.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialConfig {
    /// The source id (config name) stamped on every batch, gap and status.
    pub source: String,
    /// Device path, for example `/dev/serial/by-id/usb-FTDI_...-if00-port0` or `/dev/ttyUSB0`;
    /// `run` reopens it only while it is the device first opened (`identity`: a by-id path
    /// follows its adapter).
    pub path: String,
    pub baud: u32,
    pub format: SerialFormat,
    /// The channels in wire order (binary: gain and offset apply; ASCII: only the roles).
    pub channels: Vec<ChannelSpec>,
    pub status_interval_ms: u64,
    /// ASCII only: batch length, s.
    pub ascii_batch_s: f64,
    /// Whether the device can wait for the service (`Backpressure::Wait`, a simulated
    /// device run fast) or not (a real DAQ: the default).
    pub backpressure: Backpressure,
}

impl SerialConfig {
    /// A config with the default status interval and ASCII batch length.
    pub fn new(
        source: impl Into<String>,
        path: impl Into<String>,
        baud: u32,
        format: SerialFormat,
        channels: Vec<ChannelSpec>,
    ) -> Self {
        SerialConfig {
            source: source.into(),
            path: path.into(),
            baud,
            format,
            channels,
            status_interval_ms: DEFAULT_STATUS_INTERVAL_MS,
            ascii_batch_s: DEFAULT_ASCII_BATCH_S,
            backpressure: Backpressure::DropOldest,
        }
    }
}

/// The host clock, ns since the Unix epoch. Passed in so tests can fix it.
pub type HostClock = fn() -> i64;

/// `SystemTime::now()` in ns since the Unix epoch (the driver is IO code: it may read it).
pub fn system_clock_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
        .unwrap_or(0)
}

/// Why reading one stream stopped.
#[derive(Debug)]
pub enum StreamEnd {
    /// The reader returned end of file.
    Eof,
    /// The reader failed.
    Error(io::Error),
    /// The shutdown signal was raised.
    Shutdown,
    /// The service dropped its receiver.
    ReceiverGone,
}

/// One per source, never moved on a hot path: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
enum Decoder {
    Binary { frames: FrameDecoder, tracker: FrameTracker },
    Ascii(LineDecoder),
}

/// One serial source's decoding state and counters; it outlives each connection, so the
/// sequence after a reconnect is compared with the one before it.
pub struct SerialSource {
    cfg: SerialConfig,
    clock: HostClock,
    decoder: Decoder,
    counters: Counters,
    /// Well-formed frames the tracker could not use (wrong channel count, zero period).
    refused: u64,
}

impl SerialSource {
    pub fn new(cfg: SerialConfig, clock: HostClock) -> Self {
        let decoder = match cfg.format {
            SerialFormat::Binary => Decoder::Binary {
                frames: FrameDecoder::new(),
                tracker: FrameTracker::new(cfg.source.clone(), cfg.channels.clone()),
            },
            SerialFormat::Ascii => Decoder::Ascii(LineDecoder::new(
                cfg.source.clone(),
                cfg.channels.iter().map(|c| c.role).collect(),
                cfg.ascii_batch_s,
            )),
        };
        SerialSource { cfg, clock, decoder, counters: Counters::default(), refused: 0 }
    }

    pub fn counters(&self) -> Counters {
        self.counters
    }

    pub fn config(&self) -> &SerialConfig {
        &self.cfg
    }

    /// Send the source's status in `state`; false once the receiver is gone.
    pub fn status(&mut self, tx: &mpsc::Sender<SourceEvent>, state: &str, detail: impl Into<String>) -> bool {
        let status = self.counters.status(&self.cfg.source, state, detail);
        offer(tx, SourceEvent::Status(status), &mut self.counters)
    }

    /// Decode `bytes`, sending what they complete; false once the receiver is gone.
    pub fn feed(&mut self, bytes: &[u8], tx: &mpsc::Sender<SourceEvent>) -> bool {
        let host_ns = (self.clock)();
        let mut open = true;
        match &mut self.decoder {
            Decoder::Binary { frames, tracker } => {
                frames.push(bytes);
                while let Some(result) = frames.next_frame() {
                    let frame = match result {
                        Ok(frame) => frame,
                        Err(e) => {
                            tracing::debug!(source = %self.cfg.source, "dropped: {e}");
                            continue;
                        }
                    };
                    match tracker.track(&frame, host_ns) {
                        Ok(t) => {
                            if let Some(gap) = t.gap {
                                self.counters.gaps += 1;
                                open &= offer(tx, SourceEvent::Gap(gap), &mut self.counters);
                            }
                            self.counters.samples += t.batch.len() as u64;
                            open &= offer(tx, SourceEvent::Batch(t.batch), &mut self.counters);
                        }
                        Err(e) => {
                            self.refused += 1;
                            tracing::debug!(source = %self.cfg.source, "frame not usable: {e}");
                        }
                    }
                }
                let s = frames.stats();
                self.counters.frames = s.frames;
                self.counters.crc_errors = s.crc_errors;
                self.counters.decode_errors = s.decode_errors + self.refused;
            }
            Decoder::Ascii(lines) => {
                lines.push(bytes, host_ns);
                open &= self.drain_ascii(tx);
            }
        }
        open
    }

    /// Close an ASCII batch in progress (the line went quiet); false once the receiver is gone.
    pub fn flush(&mut self, tx: &mpsc::Sender<SourceEvent>) -> bool {
        let host_ns = (self.clock)();
        if let Decoder::Ascii(lines) = &mut self.decoder {
            lines.flush(host_ns);
            return self.drain_ascii(tx);
        }
        true
    }

    /// The link closed: forget a partial frame or line.
    pub fn reset(&mut self, tx: &mpsc::Sender<SourceEvent>) -> bool {
        let host_ns = (self.clock)();
        match &mut self.decoder {
            Decoder::Binary { frames, .. } => {
                frames.reset();
                true
            }
            Decoder::Ascii(lines) => {
                lines.reset(host_ns);
                self.drain_ascii(tx)
            }
        }
    }

    fn drain_ascii(&mut self, tx: &mpsc::Sender<SourceEvent>) -> bool {
        let Decoder::Ascii(lines) = &mut self.decoder else { return true };
        let mut open = true;
        while let Some(ev) = lines.next_event() {
            match ev {
                AsciiEvent::Batch(b) => {
                    self.counters.frames += 1;
                    open &= offer(tx, SourceEvent::Batch(b), &mut self.counters);
                }
                AsciiEvent::Gap(g) => {
                    self.counters.gaps += 1;
                    open &= offer(tx, SourceEvent::Gap(g), &mut self.counters);
                }
            }
        }
        let s = lines.stats();
        self.counters.samples = s.samples;
        self.counters.decode_errors = s.malformed;
        open
    }

    /// Read `reader` until it ends, fails, the shutdown signal rises or the receiver goes
    /// away, sending status every `status_interval_ms`.
    pub async fn read_stream<R: AsyncRead + Unpin>(
        &mut self,
        mut reader: R,
        tx: &mpsc::Sender<SourceEvent>,
        shutdown: &mut watch::Receiver<bool>,
    ) -> StreamEnd {
        let mut buf = vec![0u8; READ_BUF_BYTES];
        let period = Duration::from_millis(self.cfg.status_interval_ms.max(1));
        let mut status_tick = tokio::time::interval_at(tokio::time::Instant::now() + period, period);
        status_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let idle = Duration::from_millis(ASCII_IDLE_FLUSH_MS);
        let is_ascii = matches!(self.decoder, Decoder::Ascii(_));
        let mut pending_flush = false;
        loop {
            if *shutdown.borrow() {
                return StreamEnd::Shutdown;
            }
            crate::acquire::room(tx, self.cfg.backpressure).await;
            tokio::select! {
                read = reader.read(&mut buf) => match read {
                    Ok(0) => return StreamEnd::Eof,
                    Ok(n) => {
                        pending_flush = is_ascii;
                        if !self.feed(&buf[..n], tx) {
                            return StreamEnd::ReceiverGone;
                        }
                    }
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return StreamEnd::Error(e),
                },
                _ = tokio::time::sleep(idle), if pending_flush => {
                    pending_flush = false;
                    if !self.flush(tx) {
                        return StreamEnd::ReceiverGone;
                    }
                }
                _ = status_tick.tick() => {
                    if !self.status(tx, "connected", self.cfg.path.clone()) {
                        return StreamEnd::ReceiverGone;
                    }
                }
                changed = shutdown.changed() => {
                    if changed.is_err() || *shutdown.borrow() {
                        return StreamEnd::Shutdown;
                    }
                }
            }
        }
    }
}

/// Read one stream (a pty, a socket, a file) with no reconnect: status "connected" at the
/// start and "stopped" at the end. Returns why it stopped and the final counters.
pub async fn run_on_stream<R: AsyncRead + Unpin>(
    cfg: SerialConfig,
    reader: R,
    clock: HostClock,
    tx: mpsc::Sender<SourceEvent>,
    mut shutdown: watch::Receiver<bool>,
) -> (StreamEnd, Counters) {
    let mut src = SerialSource::new(cfg, clock);
    let detail = src.cfg.path.clone();
    if !src.status(&tx, "connected", detail) {
        return (StreamEnd::ReceiverGone, src.counters());
    }
    let end = src.read_stream(reader, &tx, &mut shutdown).await;
    src.reset(&tx);
    let detail = match &end {
        StreamEnd::Eof => "end of stream".to_string(),
        StreamEnd::Error(e) => e.to_string(),
        StreamEnd::Shutdown => "shutdown".to_string(),
        StreamEnd::ReceiverGone => "receiver gone".to_string(),
    };
    src.status(&tx, "stopped", detail);
    (end, src.counters())
}

/// Read the streams `open` hands out, reopening with backoff after every end of file or
/// error, until shutdown or until the receiver goes away. Status "connected" on every
/// open (with `reconnects` counted after the first), "reconnecting" on every loss or
/// failed open, "stopped" at the end. A failed open is logged as `OutageLog` says, and the
/// open after an outage at info level. Returns the final counters.
pub async fn run_with<R, F, Fut>(
    cfg: SerialConfig,
    clock: HostClock,
    mut open: F,
    tx: mpsc::Sender<SourceEvent>,
    mut shutdown: watch::Receiver<bool>,
) -> Counters
where
    R: AsyncRead + Unpin,
    F: FnMut() -> Fut,
    Fut: Future<Output = io::Result<R>>,
{
    let mut src = SerialSource::new(cfg, clock);
    let mut backoff_ms = 0;
    let mut connected_before = false;
    let mut outage = OutageLog::new();
    loop {
        if *shutdown.borrow() {
            break;
        }
        if backoff_ms > 0 {
            tokio::select! {
                _ = tokio::time::sleep(Duration::from_millis(backoff_ms)) => {}
                changed = shutdown.changed() => {
                    if changed.is_err() {
                        break; // the shutdown sender is gone: nobody can stop us any more
                    }
                    continue;
                }
            }
        }
        let reader = match open().await {
            Ok(r) => r,
            Err(e) => {
                backoff_ms = next_backoff_ms(backoff_ms);
                let detail = format!("{}: {e}", src.cfg.path);
                if let Some(line) = outage.failed(&detail, clock()) {
                    tracing::warn!(source = %src.cfg.source, "{line}");
                }
                if !src.status(&tx, "reconnecting", detail) {
                    break;
                }
                continue;
            }
        };
        if connected_before {
            src.counters.reconnects += 1;
        }
        if let Some(line) = outage.opened(&src.cfg.path, clock()) {
            tracing::info!(source = %src.cfg.source, "{line}");
        }
        connected_before = true;
        let detail = src.cfg.path.clone();
        if !src.status(&tx, "connected", detail) {
            break;
        }
        let end = src.read_stream(reader, &tx, &mut shutdown).await;
        let open_rx = src.reset(&tx);
        match end {
            StreamEnd::Shutdown => break,
            StreamEnd::ReceiverGone => return src.counters(),
            StreamEnd::Eof | StreamEnd::Error(_) => {
                let detail = match end {
                    StreamEnd::Error(e) => format!("{}: {e}", src.cfg.path),
                    _ => format!("{}: end of stream", src.cfg.path),
                };
                tracing::warn!(source = %src.cfg.source, "link lost: {detail}");
                outage.lost(clock());
                if !open_rx || !src.status(&tx, "reconnecting", detail) {
                    return src.counters();
                }
                backoff_ms = BACKOFF_START_MS;
            }
        }
    }
    src.status(&tx, "stopped", "shutdown");
    src.counters()
}

/// Open `cfg.path` with tokio-serial at `cfg.baud`.
pub fn open_port(cfg: &SerialConfig) -> io::Result<tokio_serial::SerialStream> {
    use tokio_serial::SerialPortBuilderExt;
    tokio_serial::new(&cfg.path, cfg.baud).open_native_async().map_err(io::Error::from)
}

/// `open_port`, while the path leads to the device `guard` admits (`identity`); the first
/// device opened is remembered.
pub fn open_same_port(cfg: &SerialConfig, guard: &mut DeviceGuard) -> io::Result<tokio_serial::SerialStream> {
    guard.open(|_| open_port(cfg))
}

/// The serial transport: open the port named in `cfg` (the same device on every reopen,
/// `open_same_port`), decode, reconnect with backoff, stamp host time from the system
/// clock. Runs until `shutdown` turns true or the receiver is dropped.
pub async fn run(cfg: SerialConfig, tx: mpsc::Sender<SourceEvent>, shutdown: watch::Receiver<bool>) -> Counters {
    let port_cfg = cfg.clone();
    let mut guard = DeviceGuard::new(cfg.path.clone());
    run_with(cfg, system_clock_ns, move || std::future::ready(open_same_port(&port_cfg, &mut guard)), tx, shutdown)
        .await
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquire::serial::frame::{Frame, encode_frame};
    use crate::signal::sample::Role;

    fn clock() -> i64 {
        123
    }

    fn config() -> SerialConfig {
        let ch = ChannelSpec { role: Role::Load, gain: 1.0, offset: 0.0 };
        SerialConfig::new("s", "mem", 115_200, SerialFormat::Binary, vec![ch])
    }

    fn wire(seqs: impl IntoIterator<Item = u32>) -> Vec<u8> {
        seqs.into_iter()
            .flat_map(|s| {
                encode_frame(&Frame {
                    channel_count: 1,
                    sample_count: 10,
                    sequence: s,
                    device_time_ns: s as u64 * 1000,
                    sample_period_ns: 100,
                    counts: vec![s as i32; 10],
                })
            })
            .collect()
    }

    #[tokio::test]
    async fn a_full_channel_drops_and_counts_instead_of_waiting() {
        let (tx, mut rx) = mpsc::channel(4);
        let (_stop_tx, stop) = watch::channel(false);
        let bytes = wire(0..100);
        let (end, counters) = run_on_stream(config(), &bytes[..], clock, tx, stop).await;
        assert!(matches!(end, StreamEnd::Eof));
        assert_eq!(counters.frames, 100);
        assert_eq!(counters.samples, 1000);
        // 4 slots: the "connected" status and 3 batches got through; the rest was dropped.
        assert_eq!(counters.drops, 100 + 1 - 3);
        let mut got = Vec::new();
        while let Ok(ev) = rx.try_recv() {
            got.push(ev);
        }
        assert_eq!(got.len(), 4);
        assert!(matches!(&got[0], SourceEvent::Status(s) if s.state == "connected"));
        assert!(matches!(&got[1], SourceEvent::Batch(b) if b.host_time_ns == 123 && b.seq == 0));
    }

    #[tokio::test]
    async fn end_of_stream_reopens_and_the_missing_frames_are_a_gap() {
        let (tx, mut rx) = mpsc::channel(1000);
        let (stop_tx, stop) = watch::channel(false);
        let mut streams = vec![wire(0..5), wire(8..10)].into_iter();
        let opened = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let opens = opened.clone();
        let open = move || {
            opens.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            let next = streams.next();
            async move {
                match next {
                    Some(bytes) => Ok(std::io::Cursor::new(bytes)),
                    None => Err(io::Error::new(io::ErrorKind::NotFound, "unplugged")),
                }
            }
        };
        let task = tokio::spawn(run_with(config(), clock, open, tx, stop));
        // Two streams, then failed opens with backoff.
        while opened.load(std::sync::atomic::Ordering::SeqCst) < 4 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        stop_tx.send(true).unwrap();
        let counters = task.await.unwrap();
        let mut states = Vec::new();
        let mut gaps = Vec::new();
        while let Ok(ev) = rx.try_recv() {
            match ev {
                SourceEvent::Status(s) => states.push(s.state),
                SourceEvent::Gap(g) => gaps.push(g),
                SourceEvent::Batch(_) => {}
            }
        }
        assert_eq!(counters.reconnects, 1);
        assert_eq!((counters.frames, counters.samples, counters.gaps), (7, 70, 1));
        assert_eq!(gaps.len(), 1);
        assert_eq!(gaps[0].samples_lost, 30); // frames 5, 6, 7 × 10 samples
        assert_eq!(&states[..4], &["connected", "reconnecting", "connected", "reconnecting"]);
        assert_eq!(states.last().map(String::as_str), Some("stopped"));
    }

    #[tokio::test]
    async fn ascii_through_the_driver_flushes_at_end_of_stream() {
        let mut cfg = config();
        cfg.format = SerialFormat::Ascii;
        let (tx, mut rx) = mpsc::channel(100);
        let (_stop_tx, stop) = watch::channel(false);
        let text = b"0.000,1\n0.001,2\nnot a line\n0.002,3\n";
        let (_, counters) = run_on_stream(cfg, &text[..], clock, tx, stop).await;
        assert_eq!((counters.samples, counters.decode_errors, counters.frames), (3, 1, 1));
        let mut values = Vec::new();
        while let Ok(ev) = rx.try_recv() {
            if let SourceEvent::Batch(b) = ev {
                values.extend(b.values);
            }
        }
        assert_eq!(values, vec![1.0, 2.0, 3.0]);
    }
}
