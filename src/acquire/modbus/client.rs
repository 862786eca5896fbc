//! The Modbus client driver (DESIGN.md §4): connects over TCP or RTU, polls the register
//! map or drains a block-mode ring, and hands `SourceEvent`s to the service without ever
//! waiting on it. Every request runs under `tokio::time::timeout` (tokio-modbus has
//! none); exceptions and timeouts are counted, never fatal; a lost link is reopened with
//! backoff and its outage recorded as a `Gap`. This is IO code: it reads the system clock
//! for host times.

use std::collections::BTreeMap;
use std::io;
use std::net::SocketAddr;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio::sync::{mpsc, watch};
use tokio::time::{Instant, MissedTickBehavior, timeout};
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::{ExceptionCode, Slave};

use super::block::{BlockError, BlockHeader, BlockPlan, BlockTracker, HEADER_REGISTERS, decode_slots};
use super::registers::{DecodeError, RegisterKind, RegisterSpec, Signal, decode_one, plan_reads};
use crate::acquire::outage::OutageLog;
use crate::acquire::serial::identity::DeviceGuard;
use crate::acquire::{ChannelSpec, Counters, SourceEvent, next_backoff_ms, offer};
use crate::signal::sample::Gap;
use crate::signal::sample::{Role, SampleBatch};

/// How often a connected driver reports its counters.
pub const STATUS_INTERVAL: Duration = Duration::from_secs(1);
/// Defaults for a config that names none: a request limit well above a loaded PLC's
/// reply time, slow signals polled 10 times a second, a block ring drained every 10 ms.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);
pub const DEFAULT_POLL_INTERVAL: Duration = Duration::from_millis(100);
pub const DEFAULT_BLOCK_POLL_INTERVAL: Duration = Duration::from_millis(10);

/// Where the device is.
#[derive(Debug, Clone, PartialEq)]
pub enum Transport {
    Tcp {
        addr: SocketAddr,
    },
    /// A serial port (or a pty) at `baud`; the slave address is `ModbusConfig::unit_id`.
    Rtu {
        path: String,
        baud: u32,
    },
}

/// What the driver reads.
#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    /// Read `ModbusConfig::map` every `poll_interval`: one 1-sample batch per poll.
    Poll,
    /// Drain the block-mode ring at `base` (module docs) every `poll_interval`; the ring's
    /// channels, in order, become physical values by `channels`.
    Block { base: u16, channels: Vec<ChannelSpec> },
}

/// One Modbus source.
#[derive(Debug, Clone, PartialEq)]
pub struct ModbusConfig {
    pub source: String,
    pub transport: Transport,
    /// Unit id (TCP) or slave address (RTU).
    pub unit_id: u8,
    pub poll_interval: Duration,
    /// Limit of every connect and every request.
    pub timeout: Duration,
    pub map: Vec<RegisterSpec>,
    pub mode: Mode,
}

/// What can go wrong talking to a device. Exceptions and timeouts are expected values the
/// driver counts; the others end a connection, which the driver reopens.
#[derive(Debug, thiserror::Error)]
pub enum ModbusError {
    #[error("no reply within {timeout_ms} ms")]
    Timeout { timeout_ms: u64 },
    #[error("modbus exception {code:?}")]
    Exception { code: ExceptionCode },
    #[error("transport: {0}")]
    Io(#[from] io::Error),
    #[error("protocol: {0}")]
    Protocol(String),
    #[error(transparent)]
    Decode(#[from] DecodeError),
    #[error(transparent)]
    Block(#[from] BlockError),
}

impl ModbusError {
    /// The connection cannot be trusted after it (a timed-out request may still be
    /// answered late, and that reply would be taken for the next one's).
    fn ends_connection(&self) -> bool {
        matches!(self, ModbusError::Timeout { .. } | ModbusError::Io(_) | ModbusError::Protocol(_))
    }
}

/// Run one request under the limit, flattening tokio-modbus's two error layers.
async fn call<T>(limit: Duration, request: impl Future<Output = tokio_modbus::Result<T>>) -> Result<T, ModbusError> {
    match timeout(limit, request).await {
        Err(_) => Err(ModbusError::Timeout { timeout_ms: limit.as_millis() as u64 }),
        Ok(Ok(Ok(v))) => Ok(v),
        Ok(Ok(Err(code))) => Err(ModbusError::Exception { code }),
        Ok(Err(tokio_modbus::Error::Transport(e))) => Err(ModbusError::Io(e)),
        Ok(Err(tokio_modbus::Error::Protocol(e))) => Err(ModbusError::Protocol(e.to_string())),
    }
}

/// Connect over `transport`. An RTU port is opened through `guard` when there is one: a
/// reopen reads the device first opened at the path, as the serial source does
/// (`serial::identity`).
async fn connect(
    transport: &Transport,
    unit_id: u8,
    limit: Duration,
    guard: Option<&mut DeviceGuard>,
) -> Result<Context, ModbusError> {
    let slave = Slave(unit_id);
    let connecting = async {
        match transport {
            Transport::Tcp { addr } => tokio_modbus::client::tcp::connect_slave(*addr, slave).await,
            Transport::Rtu { path, baud } => {
                let open =
                    |p: &str| tokio_serial::SerialStream::open(&tokio_serial::new(p, *baud)).map_err(io::Error::from);
                let port = match guard {
                    Some(g) => g.open(open)?,
                    None => open(path)?,
                };
                Ok(tokio_modbus::client::rtu::attach_slave(port, slave))
            }
        }
    };
    match timeout(limit, connecting).await {
        Err(_) => Err(ModbusError::Timeout { timeout_ms: limit.as_millis() as u64 }),
        Ok(r) => Ok(r?),
    }
}

/// Write one coil on a PLC (the Modbus alert sink): connect, write, disconnect, each step
/// under `limit`.
pub async fn write_coil(
    addr: SocketAddr,
    unit: u8,
    coil: u16,
    value: bool,
    limit: Duration,
) -> Result<(), ModbusError> {
    let mut ctx = connect(&Transport::Tcp { addr }, unit, limit, None).await?;
    let written = call(limit, ctx.write_single_coil(coil, value)).await;
    let _ = timeout(limit, tokio_modbus::client::Client::disconnect(&mut ctx)).await;
    written
}

/// Host time now, ns since the Unix epoch.
fn host_now_ns() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0)
}

/// Counts beyond `Counters`, reported in the status detail as `key=value` words.
#[derive(Debug, Clone, Default)]
struct Extra {
    exceptions: u64,
    timeouts: u64,
    last_error: String,
    /// Latest values of named (non-role) signals.
    named: BTreeMap<String, f64>,
}

impl Extra {
    fn detail(&self, transport: &Transport) -> String {
        let mut d = format!("exceptions={} timeouts={}", self.exceptions, self.timeouts);
        for (k, v) in &self.named {
            d.push_str(&format!(" {k}={v}"));
        }
        match transport {
            Transport::Tcp { addr } => d.push_str(&format!(" tcp={addr}")),
            Transport::Rtu { path, baud } => d.push_str(&format!(" rtu={path}@{baud}")),
        }
        if !self.last_error.is_empty() {
            d.push_str(&format!(" last_error={}", self.last_error));
        }
        d
    }
}

/// A `key=value` count from a status detail written by this driver (for tests and
/// metrics): `detail_count("exceptions=3 timeouts=0", "exceptions") == Some(3)`.
pub fn detail_count(detail: &str, key: &str) -> Option<u64> {
    detail.split_whitespace().find_map(|w| w.strip_prefix(key)?.strip_prefix('=')?.parse().ok())
}

/// The driver's state across connections.
struct Driver<'a> {
    cfg: &'a ModbusConfig,
    tx: &'a mpsc::Sender<SourceEvent>,
    counters: Counters,
    extra: Extra,
    /// Block mode: where the ring reading stands.
    tracker: BlockTracker,
    /// Poll mode: poll ticks since start (the batch sequence) and the last good poll.
    tick: u64,
    last_poll: Option<Instant>,
    /// Batches sent (block mode sequence).
    batches: u64,
    /// The link went down at this host time and no read has succeeded since.
    outage: Option<i64>,
    /// Poll mode: the roles of the map, in map order.
    roles: Vec<Role>,
    values: Vec<f64>,
}

/// Why a connection ended.
enum End {
    Shutdown,
    /// The pipeline's receiver is gone: nobody listens any more.
    Closed,
    Lost(ModbusError),
}

impl<'a> Driver<'a> {
    fn send(&mut self, event: SourceEvent) -> bool {
        offer(self.tx, event, &mut self.counters)
    }

    fn status(&mut self, state: &str) -> bool {
        let s = self.counters.status(&self.cfg.source, state, self.extra.detail(&self.cfg.transport));
        self.send(SourceEvent::Status(s))
    }

    /// Count an error: exceptions and timeouts in the detail, replies that do not decode
    /// in `decode_errors`; a lost link shows in `reconnects`.
    fn count(&mut self, e: &ModbusError) {
        match e {
            ModbusError::Exception { .. } => self.extra.exceptions += 1,
            ModbusError::Timeout { .. } => self.extra.timeouts += 1,
            ModbusError::Io(_) => {}
            ModbusError::Protocol(_) | ModbusError::Decode(_) | ModbusError::Block(_) => {
                self.counters.decode_errors += 1
            }
        }
        self.extra.last_error = e.to_string().replace(' ', "_");
    }

    async fn session(&mut self, ctx: &mut Context, shutdown: &mut watch::Receiver<bool>) -> End {
        let mut ticker = tokio::time::interval(self.cfg.poll_interval);
        ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
        let mut last_status = Instant::now();
        loop {
            tokio::select! {
                _ = shutdown.wait_for(|stop| *stop) => return End::Shutdown,
                _ = ticker.tick() => {}
            }
            let r = match &self.cfg.mode {
                Mode::Poll => self.poll(ctx).await,
                Mode::Block { base, channels } => self.drain(ctx, *base, channels).await,
            };
            match r {
                Ok(true) => {}
                Ok(false) => return End::Closed,
                Err(e) => {
                    self.count(&e);
                    if e.ends_connection() {
                        return End::Lost(e);
                    }
                }
            }
            if last_status.elapsed() >= STATUS_INTERVAL {
                last_status = Instant::now();
                if !self.status("connected") {
                    return End::Closed;
                }
            }
        }
    }

    /// Poll mode: read the map once; a 1-sample batch of its roles. Returns false when
    /// the receiver is gone.
    async fn poll(&mut self, ctx: &mut Context) -> Result<bool, ModbusError> {
        self.tick += 1;
        let limit = self.cfg.timeout;
        let mut decoded: Vec<Option<f64>> = vec![None; self.cfg.map.len()];
        for block in plan_reads(&self.cfg.map) {
            let words = match block.kind {
                RegisterKind::Holding => call(limit, ctx.read_holding_registers(block.start, block.count)).await?,
                RegisterKind::Input => call(limit, ctx.read_input_registers(block.start, block.count)).await?,
            };
            let end = block.start as u32 + block.count as u32;
            for (i, spec) in self.cfg.map.iter().enumerate() {
                if spec.kind == block.kind && spec.address >= block.start && spec.end() <= end {
                    decoded[i] = Some(decode_one(&words, block.start, spec)?);
                }
            }
        }
        let now = Instant::now();
        let host_ns = host_now_ns();
        let period_ns = self.cfg.poll_interval.as_nanos() as f64;
        if self.outage.take().is_some() {
            // Polls missed since the last good one.
            let missed = self.last_poll.map_or(0, |t| {
                ((now - t).as_secs_f64() / self.cfg.poll_interval.as_secs_f64()).round().max(1.0) as u64 - 1
            });
            let gap = Gap {
                source: self.cfg.source.clone(),
                t_s: host_ns as f64 * 1e-9,
                samples_lost: missed,
                reason: "link_down".into(),
            };
            self.counters.gaps += 1;
            if !self.send(SourceEvent::Gap(gap)) {
                return Ok(false);
            }
        }
        self.last_poll = Some(now);
        self.values.clear();
        for role in &self.roles {
            let i = self.cfg.map.iter().position(|s| s.signal == Signal::Role(*role));
            self.values.push(i.and_then(|i| decoded[i]).unwrap_or(f64::NAN));
        }
        for (spec, v) in self.cfg.map.iter().zip(&decoded) {
            if let (Signal::Named(n), Some(v)) = (&spec.signal, v) {
                self.extra.named.insert(n.clone(), *v);
            }
        }
        self.counters.frames += 1;
        if self.roles.is_empty() {
            return Ok(true);
        }
        self.counters.samples += 1;
        let batch = SampleBatch {
            source: self.cfg.source.clone(),
            seq: self.tick,
            device_time_ns: host_ns,
            host_time_ns: host_ns,
            period_ns,
            roles: self.roles.clone(),
            values: self.values.clone(),
        };
        Ok(self.send(SourceEvent::Batch(batch)))
    }

    /// Block mode: read the header, then every new slot; one batch of them.
    async fn drain(&mut self, ctx: &mut Context, base: u16, channels: &[ChannelSpec]) -> Result<bool, ModbusError> {
        let limit = self.cfg.timeout;
        let words = call(limit, ctx.read_holding_registers(base, HEADER_REGISTERS)).await?;
        let header = BlockHeader::parse(&words)?;
        let plan: BlockPlan = self.tracker.plan(header, channels.len())?;
        let mut values = Vec::with_capacity(plan.count as usize * channels.len());
        for read in &plan.reads {
            let words = call(limit, ctx.read_holding_registers(read.address, read.count)).await?;
            if words.len() != read.count as usize {
                return Err(BlockError::ShortRead { got: words.len(), expected: read.count as usize }.into());
            }
            decode_slots(&words, &header, channels, &mut values);
        }
        self.tracker.commit(&plan);
        let host_ns = host_now_ns();
        let period_ns = header.period_ns as f64;
        let outage = self.outage.take();
        let lost = match (plan.lost, outage) {
            (Some((first, n, reason)), None) => Some((first, n, reason)),
            (Some((first, n, _)), Some(_)) => Some((first, n, "link_down")),
            // The ring covered the outage: nothing lost, the outage is still recorded.
            (None, Some(_)) => Some((plan.first, 0, "link_down")),
            (None, None) => None,
        };
        if let Some((first, n, reason)) = lost {
            let gap = Gap {
                source: self.cfg.source.clone(),
                t_s: first as f64 * period_ns * 1e-9,
                samples_lost: n,
                reason: reason.into(),
            };
            self.counters.gaps += 1;
            if !self.send(SourceEvent::Gap(gap)) {
                return Ok(false);
            }
        }
        if plan.count == 0 {
            return Ok(true);
        }
        self.batches += 1;
        self.counters.frames += 1;
        self.counters.samples += plan.count;
        let batch = SampleBatch {
            source: self.cfg.source.clone(),
            seq: self.batches,
            device_time_ns: (plan.first as f64 * period_ns) as i64,
            host_time_ns: host_ns,
            period_ns,
            roles: channels.iter().map(|c| c.role).collect(),
            values,
        };
        Ok(self.send(SourceEvent::Batch(batch)))
    }
}

/// Run one Modbus source until `shutdown` turns true (or its sender is dropped) or the
/// receiver of `tx` is gone. Never returns on a device fault: it reconnects with backoff.
pub async fn run(cfg: ModbusConfig, tx: mpsc::Sender<SourceEvent>, mut shutdown: watch::Receiver<bool>) {
    let mut roles: Vec<Role> = Vec::new();
    for s in &cfg.map {
        if let Signal::Role(r) = s.signal
            && !roles.contains(&r)
        {
            roles.push(r);
        }
    }
    let mut d = Driver {
        cfg: &cfg,
        tx: &tx,
        counters: Counters::default(),
        extra: Extra::default(),
        tracker: BlockTracker::new(match cfg.mode {
            Mode::Block { base, .. } => base,
            Mode::Poll => 0,
        }),
        tick: 0,
        last_poll: None,
        batches: 0,
        outage: None,
        roles,
        values: Vec::new(),
    };
    let mut backoff_ms = 0;
    let mut first = true;
    let mut log = OutageLog::new();
    let place = match &cfg.transport {
        Transport::Tcp { addr } => addr.to_string(),
        Transport::Rtu { path, .. } => path.clone(),
    };
    let mut guard = match &cfg.transport {
        Transport::Tcp { .. } => None,
        Transport::Rtu { path, .. } => Some(DeviceGuard::new(path.clone())),
    };
    loop {
        if *shutdown.borrow() {
            break;
        }
        // `down`: the link itself failed (connect refused, connection reset), as opposed
        // to a request that timed out on a live link.
        let (e, down) = match connect(&cfg.transport, cfg.unit_id, cfg.timeout, guard.as_mut()).await {
            Ok(mut ctx) => {
                if !first {
                    d.counters.reconnects += 1;
                }
                first = false;
                backoff_ms = 0;
                if let Some(line) = log.opened(&place, host_now_ns()) {
                    tracing::info!(source = %cfg.source, "{line}");
                }
                if !d.status("connected") {
                    break;
                }
                let end = d.session(&mut ctx, &mut shutdown).await;
                let _ = timeout(cfg.timeout, tokio_modbus::client::Client::disconnect(&mut ctx)).await;
                match end {
                    End::Shutdown | End::Closed => break,
                    End::Lost(e) => {
                        let down = matches!(e, ModbusError::Io(_));
                        if down {
                            tracing::warn!(source = %cfg.source, "link lost: {place}: {e}");
                            log.lost(host_now_ns());
                        }
                        (e, down)
                    }
                }
            }
            Err(e) => {
                d.count(&e);
                if let Some(line) = log.failed(&format!("{place}: {e}"), host_now_ns()) {
                    tracing::warn!(source = %cfg.source, "{line}");
                }
                (e, true)
            }
        };
        d.extra.last_error = e.to_string().replace(' ', "_");
        if down {
            d.outage.get_or_insert_with(host_now_ns);
        }
        if !d.status("reconnecting") {
            break;
        }
        // A request that timed out reconnects at once (a late reply must not be taken for
        // the next request's); a link that is down is retried with backoff.
        if down {
            backoff_ms = next_backoff_ms(backoff_ms);
            tokio::select! {
                _ = shutdown.wait_for(|stop| *stop) => break,
                _ = tokio::time::sleep(Duration::from_millis(backoff_ms)) => {}
            }
        }
    }
    d.status("stopped");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn tokio_modbus_results_become_one_error_type() {
        let limit = Duration::from_millis(20);
        let ok = call(limit, async { Ok(Ok(vec![1u16])) }).await;
        assert_eq!(ok.unwrap(), vec![1]);
        let exc = call(limit, async { tokio_modbus::Result::<()>::Ok(Err(ExceptionCode::ServerDeviceBusy)) }).await;
        assert!(matches!(exc, Err(ModbusError::Exception { code: ExceptionCode::ServerDeviceBusy })));
        assert!(!exc.unwrap_err().ends_connection(), "an exception is a value; the link is fine");
        let slow = call(limit, std::future::pending::<tokio_modbus::Result<()>>()).await;
        assert!(matches!(slow, Err(ModbusError::Timeout { timeout_ms: 20 })));
        let io = call(limit, async {
            tokio_modbus::Result::<()>::Err(io::Error::from(io::ErrorKind::ConnectionReset).into())
        })
        .await;
        assert!(io.unwrap_err().ends_connection());
    }

    #[test]
    fn counts_read_back_from_the_status_detail() {
        let mut extra = Extra { exceptions: 3, timeouts: 12, ..Extra::default() };
        extra.named.insert("setpoint_J".into(), 5200.0);
        let d = extra.detail(&Transport::Rtu { path: "/dev/ttyS0".into(), baud: 19200 });
        assert_eq!(d, "exceptions=3 timeouts=12 setpoint_J=5200 rtu=/dev/ttyS0@19200");
        assert_eq!(detail_count(&d, "exceptions"), Some(3));
        assert_eq!(detail_count(&d, "timeouts"), Some(12));
        assert_eq!(detail_count(&d, "time"), None);
        assert_eq!(detail_count("", "exceptions"), None);
    }
}
