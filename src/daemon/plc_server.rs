//! The PLC result image (docs/interfaces.md §8): the latest results as Modbus TCP holding
//! registers, served by tokio-modbus's server on `[plc_server] listen`, unit id 1, so that
//! the press's or hammer's PLC reads them every cycle; coil 0 acknowledges the latched
//! alert, coil 1 says a new billet is in the dies. Registers 22–29 count the die set's life;
//! the part block (registers 100–147, `part_block.rs`) is the PLC's to write the part id,
//! lot and die set in, which coil 2 (a new billet as the block says) and coil 3 (a die
//! change) apply.
//!
//! The image is rebuilt from the service's live feed (`live.rs`: each blow's result as the
//! pipeline produced it) and the status snapshot (counters, sources, the latched alert) on
//! every event and on the 1 s heartbeat; nothing is computed a second time. [`encode`] is
//! the pure register encoding (scales, saturation, big-endian u32), [`answer`] one request
//! against an image; the IO around them is the rest.
//!
//! Every connection passes the frame gate (`gate.rs`, `conn.rs`): a malformed request is
//! answered with exception 0x03 and the connection goes on; bytes that are not Modbus TCP
//! close it; so does a connection that completes no request within `[plc_server]
//! idle_timeout_s`. At most `max_connections` are open, counted when accepted: one more
//! takes the place of the oldest connection that has made no request yet, or is closed at
//! once when every open one has. Each of these is counted in [`PlcStats`]; the service and the other
//! clients go on.

pub mod conn;
pub mod gate;
pub mod part_block;

use std::future::{Ready, ready};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::Context;
use futures_util::future::BoxFuture;
use tokio::sync::{broadcast, mpsc, watch};
use tokio::task::JoinHandle;
use tokio_modbus::server::Service;
use tokio_modbus::server::tcp::Server;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

use super::Control;
use super::faces::{FaceContext, boxed};
use super::live::{Live, LiveEvent};
use super::status::{SharedStatus, StatusSnapshot};
use crate::config::service::PlcLimits;
use crate::estimate::result::AlertKind;
use crate::estimate::{BlowClass, BlowEstimate};
use crate::signal::sample::Role;

/// The unit id the image answers (docs/interfaces.md §8).
pub const PLC_UNIT_ID: u8 = 1;
/// Holding registers 0–29.
pub const IMAGE_WORDS: usize = 30;
/// Coils 0 (acknowledge), 1 (new billet), 2 (new billet as the part block says) and 3 (die
/// change).
pub const COILS: u16 = 4;
/// How often the heartbeat (register 0) counts up.
pub const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);

/// Register addresses of docs/interfaces.md §8 (a u32 takes its address and the next, high word
/// first).
pub mod reg {
    pub const HEARTBEAT: usize = 0;
    pub const STATUS_BITS: usize = 1;
    pub const BLOWS: usize = 2;
    pub const BILLETS: usize = 4;
    pub const CLASS: usize = 6;
    pub const EFFICIENCY: usize = 7;
    pub const PLASTIC_J: usize = 8;
    pub const KINETIC_J: usize = 10;
    pub const IMPACT_MM_PER_S: usize = 12;
    pub const PEAK_LOAD_100N: usize = 13;
    pub const HEIGHT_10UM: usize = 15;
    pub const JUDGEMENT: usize = 16;
    pub const BLOWS_TO_TARGET: usize = 17;
    pub const ADVISED_KINETIC_J: usize = 18;
    /// The last blow's sensing mode: the channels its estimate used (issue 43).
    pub const CHANNELS: usize = 20;
    pub const EFFICIENCY_SD: usize = 21;
    // 22–29: the die set in the hammer (issue 44).
    pub const DIE_BLOWS: usize = 22;
    pub const DIE_HARD_BLOWS: usize = 24;
    pub const DIE_ENERGY_KJ: usize = 26;
    pub const DIE_LEVEL: usize = 28;
    pub const DIE_USED_PERMILLE: usize = 29;
}

/// Bits of register 20: the channels the last blow's estimate used (0 before the first).
pub mod channel_bit {
    pub const LOAD: u16 = 1 << 0;
    pub const ACC: u16 = 1 << 1;
    pub const DISP: u16 = 1 << 2;
}

/// Bits of register 1 (docs/interfaces.md §8).
pub mod bit {
    pub const RUNNING: u16 = 1 << 0;
    pub const SOURCES_HEALTHY: u16 = 1 << 1;
    pub const ALERT_LATCHED: u16 = 1 << 2;
    pub const LAST_NOK: u16 = 1 << 3;
    pub const LAST_INCOMPLETE: u16 = 1 << 4;
    pub const MODEL_HEALTH: u16 = 1 << 5;
    pub const SENSOR: u16 = 1 << 6;
    /// The last blow was implausible (issue 36; an addition to docs/interfaces.md §8's bits 0–6).
    pub const LAST_IMPLAUSIBLE: u16 = 1 << 7;
}

/// Register 17 when the blows still needed are not known (no advisor, no measured height,
/// or no plan reaches the target).
pub const BLOWS_TO_TARGET_UNKNOWN: u16 = 0xFFFF;

/// The warnings the image keeps from the blows' alerts until the operator acknowledges
/// (bits 5 and 6): each kind stays set even when an alert of another kind is latched later.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Warnings {
    pub model_health: bool,
    pub sensor: bool,
}

impl Warnings {
    /// Take the kind of an alert a blow raised.
    pub fn raise(&mut self, kind: AlertKind) {
        match kind {
            AlertKind::ModelHealth => self.model_health = true,
            AlertKind::Sensor => self.sensor = true,
            AlertKind::ElasticBlow | AlertKind::Nok | AlertKind::Storage | AlertKind::DieLife | AlertKind::Drift => {}
        }
    }
}

/// `x` rounded to the nearest whole number within `0..=max`; not a number gives 0.
fn saturate(x: f64, max: u32) -> u32 {
    if x.is_nan() || x <= 0.0 { 0 } else { x.round().min(f64::from(max)) as u32 }
}

fn sat_u16(x: f64) -> u16 {
    saturate(x, u32::from(u16::MAX)) as u16
}

fn sat_u32(x: f64) -> u32 {
    saturate(x, u32::MAX)
}

/// A count that does not fit a u32 saturates.
fn count_u32(n: u64) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Store `v` at `at` and `at + 1`, high word first.
fn put_u32(words: &mut [u16; IMAGE_WORDS], at: usize, v: u32) {
    words[at] = (v >> 16) as u16;
    words[at + 1] = (v & 0xFFFF) as u16;
}

/// Register 6: 0 none yet, 1 soft, 2 intermediate, 3 hard, 4 incomplete, 5 implausible (an
/// addition to docs/interfaces.md §8's codes, issue 36).
pub fn class_code(class: Option<BlowClass>) -> u16 {
    match class {
        None => 0,
        Some(BlowClass::Soft) => 1,
        Some(BlowClass::Intermediate) => 2,
        Some(BlowClass::Hard) => 3,
        Some(BlowClass::Incomplete) => 4,
        Some(BlowClass::Implausible) => 5,
    }
}

/// The register image of docs/interfaces.md §8. `last` is the last blow's result as the live feed
/// carried it; the counters, the sources and the latched alert come from `status`. A value
/// that is not known (an incomplete blow's energies, a height without a process sheet) is
/// 0; register 16 is the last blow's judgement against the active recipe, registers 17–19
/// the live advisor's plan (`status.advice`): "unknown" and "none" without one.
pub fn encode(
    heartbeat: u16,
    status: &StatusSnapshot,
    last: Option<&BlowEstimate>,
    warn: Warnings,
) -> [u16; IMAGE_WORDS] {
    let mut w = [0u16; IMAGE_WORDS];
    w[reg::HEARTBEAT] = heartbeat;
    let healthy = !status.sources.is_empty() && status.sources.values().all(|s| s.state == "connected");
    let flag = |on: bool, b: u16| if on { b } else { 0 };
    w[reg::STATUS_BITS] = bit::RUNNING
        | flag(healthy, bit::SOURCES_HEALTHY)
        | flag(status.latched_alert.is_some(), bit::ALERT_LATCHED)
        | flag(last.is_some_and(|b| !b.is_complete()), bit::LAST_INCOMPLETE)
        | flag(last.is_some_and(|b| b.class == BlowClass::Implausible), bit::LAST_IMPLAUSIBLE)
        | flag(last.and_then(|b| b.judgement.as_ref()).is_some_and(|j| !j.ok), bit::LAST_NOK)
        | flag(warn.model_health, bit::MODEL_HEALTH)
        | flag(warn.sensor, bit::SENSOR);
    put_u32(&mut w, reg::BLOWS, count_u32(status.blows));
    put_u32(&mut w, reg::BILLETS, count_u32(status.billets));
    w[reg::CLASS] = class_code(last.map(|b| b.class));
    if let Some(b) = last {
        w[reg::EFFICIENCY] = sat_u16(b.efficiency.unwrap_or(0.0) * 1e4);
        put_u32(&mut w, reg::PLASTIC_J, sat_u32(b.plastic_j.unwrap_or(0.0)));
        put_u32(&mut w, reg::KINETIC_J, sat_u32(b.kinetic_in_j.unwrap_or(0.0)));
        w[reg::IMPACT_MM_PER_S] = sat_u16(b.v_impact_mps * 1e3);
        put_u32(&mut w, reg::PEAK_LOAD_100N, sat_u32(b.peak_load_n / 100.0));
        w[reg::HEIGHT_10UM] = sat_u16(b.h_end_m.unwrap_or(0.0) * 1e5);
        // Registers 20–21: the sensing mode and the efficiency's 1σ (issue 43).
        let used = |role: Role, bit: u16| if b.channels.has(role) { bit } else { 0 };
        w[reg::CHANNELS] = used(Role::Load, channel_bit::LOAD)
            | used(Role::Acc, channel_bit::ACC)
            | used(Role::Disp, channel_bit::DISP);
        w[reg::EFFICIENCY_SD] = sat_u16(b.efficiency_sd.unwrap_or(0.0) * 1e4);
    }
    // Register 16: 0 no recipe (or a blow not judged: incomplete), 1 OK, 2 NOK.
    w[reg::JUDGEMENT] = match last.and_then(|b| b.judgement.as_ref()) {
        None => 0,
        Some(j) if j.ok => 1,
        Some(_) => 2,
    };
    // Registers 17–19: the live advisor's plan (`[advisor]`), unknown and none without one.
    let advice = status.advice.as_ref();
    w[reg::BLOWS_TO_TARGET] = advice
        .and_then(|a| a.blows_to_target())
        .map_or(BLOWS_TO_TARGET_UNKNOWN, |n| u16::try_from(n).unwrap_or(BLOWS_TO_TARGET_UNKNOWN - 1));
    put_u32(&mut w, reg::ADVISED_KINETIC_J, sat_u32(advice.and_then(|a| a.next_kinetic_j()).unwrap_or(0.0)));
    encode_die_life(&mut w, &status.die_life);
    w
}

/// Registers 22–29: the die set's blows, hard blows and energy (kJ), its level against
/// `[die_life]` (0 ok, 1 warning, 2 limit) and the share of its life used, in ‰ of the
/// nearer limit (0 without one).
fn encode_die_life(w: &mut [u16; IMAGE_WORDS], d: &super::die_life::DieLifeStatus) {
    put_u32(w, reg::DIE_BLOWS, count_u32(d.count.blows));
    put_u32(w, reg::DIE_HARD_BLOWS, count_u32(d.count.hard_blows));
    put_u32(w, reg::DIE_ENERGY_KJ, sat_u32(d.count.energy_j / 1e3));
    w[reg::DIE_LEVEL] = match d.level {
        crate::history::die::DieLevel::Ok => 0,
        crate::history::die::DieLevel::Warning => 1,
        crate::history::die::DieLevel::Limit => 2,
    };
    let by_blows = d.limit_blows.map(|l| d.count.blows as f64 / l as f64);
    let by_energy = d.limit_energy_j.map(|l| d.count.energy_j / l);
    let used = by_blows.into_iter().chain(by_energy).fold(0.0, f64::max);
    w[reg::DIE_USED_PERMILLE] = sat_u16(used * 1e3);
}

/// What the server has done since it started (logged as it happens).
#[derive(Debug, Default)]
pub struct PlcStats {
    pub connections: AtomicU64,
    pub requests: AtomicU64,
    /// Requests answered with a Modbus exception.
    pub exceptions: AtomicU64,
    /// Connections that ended on an error: a reset, a failed write.
    pub connection_errors: AtomicU64,
    /// Connections closed at accept because `max_connections` were open and every one had
    /// made a request.
    pub refused: AtomicU64,
    /// Connections closed for a newer one: at the cap, without a request made.
    pub evicted: AtomicU64,
    /// Connections closed after `idle_timeout_s` without a request.
    pub idle_closed: AtomicU64,
    /// Connections closed because their bytes were not Modbus TCP.
    pub framing_closed: AtomicU64,
    /// Malformed requests the frame gate answered with exception 0x03 (or 0x01).
    pub malformed: Arc<AtomicU64>,
    /// Coil writes that reached the service.
    pub commands: AtomicU64,
}

/// One request against `image` and the part block (Modbus Application Protocol v1.1b3 §6):
/// holding registers 0–29 are read; registers 100–147 (`block`) are read and written; coils
/// 0–3 are written, and each coil written `true` sends its command through `command`. A
/// quantity outside the function's range is an illegal data value (§6.3: 1..=125
/// registers), checked before the address; every other function or address is refused
/// with an exception; a command the service cannot take now is "server device busy".
pub fn answer(
    image: &[u16; IMAGE_WORDS],
    block: &mut part_block::Block,
    request: Request<'_>,
    mut command: impl FnMut(Control) -> bool,
) -> Result<Response, ExceptionCode> {
    match request {
        Request::ReadHoldingRegisters(addr, n) => {
            let (start, end) = (usize::from(addr), usize::from(addr) + usize::from(n));
            if !(1..=125).contains(&n) {
                return Err(ExceptionCode::IllegalDataValue);
            }
            if let Some(at) = part_block::span(addr, usize::from(n)) {
                return Ok(Response::ReadHoldingRegisters(block[at?].to_vec()));
            }
            if end > IMAGE_WORDS {
                return Err(ExceptionCode::IllegalDataAddress);
            }
            Ok(Response::ReadHoldingRegisters(image[start..end].to_vec()))
        }
        // Only the part block is written; the image is read-only (a write to it is not a
        // function it offers).
        Request::WriteSingleRegister(addr, v) => {
            let at = part_block::span(addr, 1).ok_or(ExceptionCode::IllegalFunction)??;
            part_block::write(block, at, &[v])?;
            Ok(Response::WriteSingleRegister(addr, v))
        }
        Request::WriteMultipleRegisters(addr, words) => {
            let at = part_block::span(addr, words.len()).ok_or(ExceptionCode::IllegalFunction)??;
            part_block::write(block, at, &words)?;
            Ok(Response::WriteMultipleRegisters(addr, words.len() as u16))
        }
        Request::WriteSingleCoil(addr, on) => {
            coils(addr, &[on], block, &mut command)?;
            Ok(Response::WriteSingleCoil(addr, on))
        }
        Request::WriteMultipleCoils(addr, values) => {
            coils(addr, &values, block, &mut command)?;
            Ok(Response::WriteMultipleCoils(addr, values.len() as u16))
        }
        // Reading coils (write-only), input registers or anything else is not offered.
        _ => Err(ExceptionCode::IllegalFunction),
    }
}

/// Coils `addr..` set to `values`: the command of each one set `true` (coils 2 and 3 with
/// the part block's fields, checked before anything is sent).
fn coils(
    addr: u16,
    values: &[bool],
    block: &part_block::Block,
    command: &mut impl FnMut(Control) -> bool,
) -> Result<(), ExceptionCode> {
    if values.is_empty() || usize::from(addr) + values.len() > usize::from(COILS) {
        return Err(ExceptionCode::IllegalDataAddress);
    }
    let mut sends = Vec::new();
    for (k, &on) in values.iter().enumerate() {
        if !on {
            continue;
        }
        sends.push(match usize::from(addr) + k {
            0 => Control::Acknowledge,
            1 => Control::NewBillet { at_device_ns: None },
            2 => Control::NewBilletAs { at_device_ns: None, change: Box::new(part_block::billet_change(block)?) },
            _ => Control::DieChange(Box::new(part_block::die_change(block)?)),
        });
    }
    for c in sends {
        if !command(c) {
            return Err(ExceptionCode::ServerDeviceBusy);
        }
    }
    Ok(())
}

/// The Modbus service of one connection: the latest image, the control channel.
#[derive(Clone)]
struct ImageService {
    image: watch::Receiver<[u16; IMAGE_WORDS]>,
    /// The part block, one for every connection.
    block: Arc<std::sync::Mutex<part_block::Block>>,
    control: mpsc::Sender<Control>,
    stats: Arc<PlcStats>,
}

impl Service for ImageService {
    type Request = SlaveRequest<'static>;
    type Response = Response;
    type Exception = ExceptionCode;
    type Future = Ready<Result<Response, ExceptionCode>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        self.stats.requests.fetch_add(1, Ordering::Relaxed);
        let reply = if req.slave != PLC_UNIT_ID {
            // Modbus TCP: the unit id names a device behind a gateway; there is no other.
            Err(ExceptionCode::GatewayTargetDevice)
        } else {
            let image = *self.image.borrow();
            let mut block = self.block.lock().unwrap_or_else(|p| p.into_inner());
            answer(&image, &mut block, req.request, |c| {
                let said = format!("{c:?}");
                let sent = self.control.try_send(c).is_ok();
                if sent {
                    self.stats.commands.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(command = said, "PLC coil");
                }
                sent
            })
        };
        if let Err(e) = &reply {
            self.stats.exceptions.fetch_add(1, Ordering::Relaxed);
            tracing::debug!(exception = ?e, "PLC request refused");
        }
        ready(reply)
    }
}

/// The running PLC server; dropping it stops the server and the image's updates.
pub struct PlcServer {
    pub addr: SocketAddr,
    pub stats: Arc<PlcStats>,
    tasks: [JoinHandle<()>; 2],
}

impl Drop for PlcServer {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

impl super::faces::Face for PlcServer {}

/// The image as a face (`faces::FACES`): `[plc_server] listen`.
pub fn face<'a>(ctx: &'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn super::faces::Face>>>> {
    Box::pin(async move {
        let (listen, limits) = (ctx.config.plc_listen, ctx.config.plc_limits);
        Ok(boxed(start(listen, limits, ctx.status.clone(), ctx.bus, ctx.control.clone()).await?))
    })
}

/// Serve the image on `listen` when it is set (`[plc_server] listen`) with `limits` on its
/// clients; `None` otherwise. Fails only when the address cannot be listened on.
pub async fn start(
    listen: Option<SocketAddr>,
    limits: PlcLimits,
    status: SharedStatus,
    live: &Live,
    control: mpsc::Sender<Control>,
) -> anyhow::Result<Option<PlcServer>> {
    let Some(listen) = listen else { return Ok(None) };
    let listener = tokio::net::TcpListener::bind(listen)
        .await
        .with_context(|| format!("plc_server.listen {listen}: cannot listen"))?;
    let addr = listener.local_addr().with_context(|| format!("plc_server.listen {listen}"))?;
    let status = Arc::new(status.lock().unwrap_or_else(|p| p.into_inner()).clone());
    let (image_tx, image_rx) = watch::channel(encode(0, &status, None, Warnings::default()));
    let stats = Arc::new(PlcStats::default());
    let updater = tokio::spawn(update(live.subscribe(), status, image_tx));
    let block = Arc::new(std::sync::Mutex::new([0u16; part_block::WORDS]));
    let service = ImageService { image: image_rx, block, control, stats: stats.clone() };
    let server = tokio::spawn(serve(Server::new(listener), service, limits));
    tracing::info!(%addr, "PLC result image (Modbus TCP, unit {PLC_UNIT_ID}) listening");
    Ok(Some(PlcServer { addr, stats, tasks: [updater, server] }))
}

/// Accept clients until aborted, each behind the frame gate and under the cap (module
/// doc); a failed accept (out of file descriptors) is logged and retried after a pause.
async fn serve(server: Server, service: ImageService, limits: PlcLimits) {
    let stats = service.stats.clone();
    let slots = crate::daemon::slots::Slots::new(usize::try_from(limits.max_connections).unwrap_or(usize::MAX));
    let idle = Duration::from_secs_f64(limits.idle_timeout_s);
    let on_connected = |stream, peer: SocketAddr| {
        let service = service.clone();
        let slot = slots.open();
        async move {
            let Some(slot) = slot else {
                service.stats.refused.fetch_add(1, Ordering::Relaxed);
                tracing::debug!(%peer, "PLC client refused: {} connections open", limits.max_connections);
                return Ok(None);
            };
            service.stats.connections.fetch_add(1, Ordering::Relaxed);
            tracing::info!(%peer, "PLC client connected");
            let malformed = service.stats.malformed.clone();
            Ok(Some((service, conn::Gated::new(stream, idle, slot, malformed))))
        }
    };
    let on_error = move |e: std::io::Error| match e.kind() {
        std::io::ErrorKind::TimedOut => {
            stats.idle_closed.fetch_add(1, Ordering::Relaxed);
            tracing::debug!("PLC client closed: {e}");
        }
        std::io::ErrorKind::ConnectionAborted => {
            stats.evicted.fetch_add(1, Ordering::Relaxed);
            tracing::debug!("PLC client closed: {e}");
        }
        std::io::ErrorKind::InvalidData => {
            stats.framing_closed.fetch_add(1, Ordering::Relaxed);
            tracing::info!("PLC client closed, not Modbus TCP: {e}");
        }
        _ => {
            stats.connection_errors.fetch_add(1, Ordering::Relaxed);
            tracing::warn!("PLC client connection ended: {e}");
        }
    };
    loop {
        if let Err(e) = server.serve(&on_connected, on_error.clone()).await {
            tracing::error!("PLC server: accepting a client failed: {e}");
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
    }
}

/// Rebuild the image on every live event and heartbeat, until the service stops: the
/// counters, sources and latched alert from the bus's last status snapshot (`status` until
/// the first), the last blow and the warnings from the bus's results and alerts.
async fn update(
    mut live: broadcast::Receiver<LiveEvent>,
    mut status: Arc<StatusSnapshot>,
    image: watch::Sender<[u16; IMAGE_WORDS]>,
) {
    let mut heartbeat = 0u16;
    let mut last: Option<Arc<BlowEstimate>> = None;
    let mut warn = Warnings::default();
    // Fell behind the bus: the next snapshot has the last blow and the latched alert.
    let mut behind = false;
    let mut tick = tokio::time::interval_at(tokio::time::Instant::now() + HEARTBEAT_PERIOD, HEARTBEAT_PERIOD);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            ev = live.recv() => match ev {
                Ok(LiveEvent::Blow(b)) => {
                    if let Some(a) = &b.alert {
                        warn.raise(a.kind);
                    }
                    last = Some(b);
                }
                Ok(LiveEvent::Status(s)) => {
                    if std::mem::take(&mut behind) {
                        last = s.last_blow.clone().map(Arc::new);
                        if let Some(a) = &s.latched_alert {
                            warn.raise(a.kind);
                        }
                    }
                    status = s;
                }
                // The advisor's plan comes after the blow's snapshot.
                Ok(LiveEvent::Advice(a)) => Arc::make_mut(&mut status).advice = Some((*a).clone()),
                Ok(LiveEvent::Acknowledged) => {
                    warn = Warnings::default();
                    Arc::make_mut(&mut status).acknowledge();
                }
                Ok(LiveEvent::Billet(_) | LiveEvent::NewBillet | LiveEvent::Alert { .. } | LiveEvent::Stopping) => {}
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    tracing::warn!(events = n, "PLC image fell behind the live feed");
                    behind = true;
                }
                Err(broadcast::error::RecvError::Closed) => break,
            },
            _ = tick.tick() => heartbeat = heartbeat.wrapping_add(1),
        }
        image.send_replace(encode(heartbeat, &status, last.as_deref(), warn));
    }
}

#[cfg(test)]
pub(crate) mod tests;
