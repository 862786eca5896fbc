//! The service's configuration (`forgemon run --config FILE`): the machine and process
//! files, the recording, the status endpoint, the alert rules and sinks, and the sources.
//! Read once, validated completely before anything is opened: every table denies unknown
//! keys ("did you mean"), every number is checked against its range (`limits.rs`), and
//! every error names the file, line, column and key. Relative paths are taken from the
//! configuration file's directory. The sources' tables are in `source.rs`.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::IgnoredAny;

use super::document::Document;
use super::limits::{
    ALERT_WINDOW_BLOWS, BILLET_IDLE_S, DEBOUNCE_BLOWS, EFFICIENCY, ENCODER_AT_DIE_M, KEEP_BYTES, KEEP_DAYS,
    MIN_FREE_BYTES, NEW_BILLET_RISE_M, PLC_IDLE_TIMEOUT_S, PLC_MAX_CONNECTIONS, RESIDUAL_LIMIT, ROTATE_BYTES,
    ROTATE_SECONDS, SENSOR_LIMIT,
};
use super::server_limits::{
    DEFAULT_PLC_IDLE_TIMEOUT_S, DEFAULT_PLC_MAX_CONNECTIONS, FoxgloveLimits, HttpLimits, RawLimits, foxglove_limits,
    http_limits,
};
use super::{ConfigError, source};
use crate::acquire::ChannelSpec;
use crate::alert::AlertConfig;
use crate::estimate::EncoderDirection;
use crate::signal::sample::Channels;

/// Default status/metrics address: loopback only.
pub const DEFAULT_HTTP_LISTEN: &str = "127.0.0.1:9187";
/// Default rotation: 512 MiB or one hour, whichever comes first.
pub const DEFAULT_ROTATE_BYTES: u64 = 512 * 1024 * 1024;
pub const DEFAULT_ROTATE_SECONDS: u64 = 3600;
/// Default low-space watermark: 2 GiB, about 45 minutes of a hammer recorded at 100 kHz
/// (some 70 GB a day): time to free space before the recording is suspended.
pub const DEFAULT_MIN_FREE_BYTES: u64 = 2 << 30;
/// Default serial speed.
pub const DEFAULT_BAUD: u32 = 921_600;

/// Serial line format (docs/interfaces.md §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SerialFormat {
    Binary,
    Ascii,
}

/// One source of samples.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceSpec {
    Serial {
        name: String,
        path: String,
        baud: u32,
        format: SerialFormat,
        channels: Vec<ChannelSpec>,
    },
    /// A SocketCAN interface or a `candump -L` log, signals from a DBC file or the config.
    Can(crate::acquire::can::CanSourceSpec),
    /// A Modbus TCP or RTU device: polled registers, or a DAQ's block-mode sample ring.
    Modbus(crate::acquire::modbus::ModbusConfig),
}

impl SourceSpec {
    pub fn name(&self) -> &str {
        match self {
            SourceSpec::Serial { name, .. } => name,
            SourceSpec::Can(c) => &c.name,
            SourceSpec::Modbus(m) => &m.source,
        }
    }

    /// The channels the source carries.
    pub fn channels(&self) -> Channels {
        use crate::acquire::can::CanSignals;
        use crate::acquire::modbus::{Mode, Signal};
        match self {
            SourceSpec::Serial { channels, .. } => Channels::of(&channels.iter().map(|c| c.role).collect::<Vec<_>>()),
            SourceSpec::Can(c) => match &c.signals {
                CanSignals::Dbc { names, .. } => Channels::of(&names.roles.iter().map(|(r, _)| *r).collect::<Vec<_>>()),
                CanSignals::Explicit(m) => Channels::of(&m.roles()),
            },
            SourceSpec::Modbus(m) => match &m.mode {
                Mode::Block { channels, .. } => Channels::of(&channels.iter().map(|c| c.role).collect::<Vec<_>>()),
                Mode::Poll => Channels::of(
                    &m.map
                        .iter()
                        .filter_map(|r| match r.signal {
                            Signal::Role(role) => Some(role),
                            Signal::Named(_) => None,
                        })
                        .collect::<Vec<_>>(),
                ),
            },
        }
    }
}

/// The channels none of `sources` carries (a hammer without a load cell): the service's
/// merge does not wait for them and its blows are estimated without them (issue 43).
/// Without sources (the caller feeds the service) none is taken to be absent.
pub fn absent_channels(sources: &[SourceSpec]) -> Channels {
    if sources.is_empty() {
        return Channels::NONE;
    }
    let carried = sources.iter().fold(Channels::NONE, |c, s| s.channels().roles().fold(c, |c, r| c.with(r, true)));
    Channels::ALL.missing_from(carried)
}

/// A Modbus coil on the PLC set when an alert fires.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlcCoil {
    pub address: SocketAddr,
    pub unit: u8,
    pub coil: u16,
}

/// `[plc_server]`'s limits on its clients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlcLimits {
    /// `idle_timeout_s`: a connection that completes no request for this long is closed.
    pub idle_timeout_s: f64,
    /// `max_connections`: connections open at once; more are closed when accepted.
    pub max_connections: u64,
}

impl Default for PlcLimits {
    fn default() -> Self {
        PlcLimits { idle_timeout_s: DEFAULT_PLC_IDLE_TIMEOUT_S, max_connections: DEFAULT_PLC_MAX_CONNECTIONS }
    }
}

/// The validated service configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ServiceConfig {
    pub machine_path: PathBuf,
    pub process_path: Option<PathBuf>,
    /// `recipe`: the part's recipe file (docs/interfaces.md §9) every blow is judged against.
    pub recipe_path: Option<PathBuf>,
    pub recording_dir: PathBuf,
    pub rotate_bytes: u64,
    pub rotate_seconds: u64,
    /// `[recording] keep_bytes`: delete the oldest files while the recording holds more.
    pub keep_bytes: Option<u64>,
    /// `[recording] keep_days`: delete files last written longer ago than this.
    pub keep_days: Option<f64>,
    /// `[recording] min_free_bytes`: raise a `storage` alert when less is free.
    pub min_free_bytes: u64,
    pub http_listen: SocketAddr,
    /// `[http] token_file`: the file holding the bearer token every request needs when
    /// `listen` is not loopback (required then; read when the service starts).
    pub http_token_file: Option<PathBuf>,
    /// `[http] max_connections`, `header_timeout_s`, `idle_timeout_s` (`server_limits.rs`).
    pub http_limits: HttpLimits,
    /// `[plc_server] listen`: serve the PLC result image (docs/interfaces.md §8) here.
    pub plc_listen: Option<SocketAddr>,
    /// `[plc_server] idle_timeout_s`, `max_connections`.
    pub plc_limits: PlcLimits,
    /// `[foxglove] listen`: serve the Foxglove WebSocket protocol here.
    pub foxglove_listen: Option<SocketAddr>,
    /// `[foxglove] max_clients`, `handshake_timeout_s`, `idle_timeout_s`.
    pub foxglove_limits: FoxgloveLimits,
    /// `[opcua]`: the OPC UA Metal Forming server (`config/opcua.rs`).
    pub opcua: Option<super::opcua::OpcuaConfig>,
    pub alerts: AlertConfig,
    pub webhook: Option<String>,
    pub plc_coil: Option<PlcCoil>,
    /// `[billets] new_billet_rise_m`: the encoder's new-billet threshold, m (`None`: the
    /// estimator's default from the sheet's height, `estimate::billet`).
    pub new_billet_rise_m: Option<f64>,
    /// `[billets] idle_s`: the idle gap after which a smaller rise starts a billet, s.
    pub idle_new_billet_s: f64,
    /// `[billets] encoder_at_die_m`: the encoder's reading with the ram on the lower die, m
    /// (`None`: not known; `estimate::EstimatorConfig::encoder_at_die_m`).
    pub encoder_at_die_m: Option<f64>,
    /// `[encoder] direction`: which way the ram encoder counts (`Auto`: told by each blow's
    /// approach).
    pub encoder_direction: EncoderDirection,
    pub sources: Vec<SourceSpec>,
    /// The channels no source carries (`absent_channels` of `sources`; the demo's
    /// `--without`): the merge does not wait for them (issue 43).
    pub absent_channels: Channels,
    /// `[advisor]`: replan the billet's next blows after each one (issue 20).
    pub advisor: Option<super::advisor::AdvisorConfig>,
    /// `[uplink.mqtt]`: publish Sparkplug B to this broker (docs/interfaces.md §10, `uplink.rs`).
    pub uplink_mqtt: Option<super::uplink::MqttUplink>,
    /// `[history]`: the quality record's database (on by default), `None` when disabled.
    pub history: Option<super::history::HistoryConfig>,
    /// `[part]`: the part, lot and die set until they are set at run time.
    pub part: super::history::Trace,
    /// `[die_life]`: when a die set is due.
    pub die_life: super::history::DieLifeConfig,
    /// `[drift]`: the drift alarms, `None` when disabled.
    pub drift: Option<super::history::DriftConfig>,
}

impl ServiceConfig {
    /// A service on `machine_path` recording to `recording_dir` with every other key at its
    /// default and nothing optional configured: the status endpoint on a free loopback port,
    /// no process sheet, no front end but the dashboard, no sources (the caller feeds it, as
    /// `forgemon demo` and the tests do). Set the rest with struct update syntax.
    pub fn minimal(machine_path: PathBuf, recording_dir: PathBuf) -> Self {
        ServiceConfig {
            machine_path,
            process_path: None,
            recipe_path: None,
            recording_dir: recording_dir.clone(),
            rotate_bytes: DEFAULT_ROTATE_BYTES,
            rotate_seconds: DEFAULT_ROTATE_SECONDS,
            keep_bytes: None,
            keep_days: None,
            min_free_bytes: DEFAULT_MIN_FREE_BYTES,
            http_listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            http_token_file: None,
            http_limits: HttpLimits::default(),
            plc_listen: None,
            plc_limits: PlcLimits::default(),
            foxglove_listen: None,
            foxglove_limits: FoxgloveLimits::default(),
            opcua: None,
            alerts: AlertConfig::default(),
            webhook: None,
            plc_coil: None,
            new_billet_rise_m: None,
            encoder_at_die_m: None,
            encoder_direction: EncoderDirection::Auto,
            idle_new_billet_s: crate::estimate::billet::DEFAULT_IDLE_NEW_BILLET_S,
            sources: Vec::new(),
            absent_channels: Channels::NONE,
            advisor: None,
            uplink_mqtt: None,
            history: Some(super::history::HistoryConfig::in_dir(&recording_dir)),
            part: super::history::Trace::default(),
            die_life: super::history::DieLifeConfig::default(),
            drift: Some(super::history::DriftConfig::default()),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawService {
    machine: String,
    process: Option<String>,
    recipe: Option<String>,
    recording: RawRecording,
    http: Option<RawHttp>,
    plc_server: Option<RawPlcServer>,
    foxglove: Option<RawFoxglove>,
    opcua: Option<super::opcua::RawOpcua>,
    alerts: Option<RawAlerts>,
    billets: Option<RawBillets>,
    encoder: Option<RawEncoder>,
    advisor: Option<super::advisor::RawAdvisor>,
    history: Option<super::history::RawHistory>,
    part: Option<super::history::RawPart>,
    die_life: Option<super::history::RawDieLife>,
    drift: Option<super::history::RawDrift>,
    /// Each read by its `kind` (`source.rs`).
    sources: Vec<IgnoredAny>,
    /// Read by `uplink.rs`.
    #[serde(rename = "uplink")]
    _uplink: Option<IgnoredAny>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRecording {
    dir: String,
    rotate_bytes: Option<u64>,
    rotate_seconds: Option<u64>,
    keep_bytes: Option<u64>,
    keep_days: Option<f64>,
    min_free_bytes: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHttp {
    listen: String,
    token_file: Option<String>,
    max_connections: Option<u64>,
    header_timeout_s: Option<f64>,
    idle_timeout_s: Option<f64>,
}

/// `[foxglove]`: the address and the limits.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFoxglove {
    listen: String,
    max_clients: Option<u64>,
    handshake_timeout_s: Option<f64>,
    idle_timeout_s: Option<f64>,
}

/// `[plc_server]`: the PLC image's address and its limits on clients.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlcServer {
    listen: String,
    idle_timeout_s: Option<f64>,
    max_connections: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAlerts {
    hard_blow: Option<bool>,
    low_efficiency: Option<f64>,
    k_low: Option<u64>,
    n_window: Option<u64>,
    residual_limit: Option<f64>,
    scale_drift_limit: Option<f64>,
    model_residual_limit: Option<f64>,
    sensor_limit: Option<f64>,
    sensor_k: Option<u64>,
    sensor_n: Option<u64>,
    debounce_blows: Option<u64>,
    webhook: Option<String>,
    plc_coil: Option<RawPlcCoil>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBillets {
    new_billet_rise_m: Option<f64>,
    encoder_at_die_m: Option<f64>,
    idle_s: Option<f64>,
}

/// `[encoder]`: how the ram encoder is mounted; its value is read as a choice
/// (`parse_encoder`), so the error names the allowed words.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEncoder {
    #[allow(dead_code)]
    direction: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlcCoil {
    address: String,
    unit: u8,
    coil: u16,
}

/// Parse the text of the service configuration `origin`, whose directory is `base`.
pub fn parse_service(origin: &str, base: &Path, text: &str) -> Result<ServiceConfig, ConfigError> {
    let doc = Document::parse(origin, text)?;
    let raw: RawService = doc.read()?;
    let path = |s: &str| relative_to(base, s);
    let (rotate_bytes, rotate_seconds) = parse_rotation(&doc, &raw.recording)?;
    let (http_listen, http_token_file) = parse_http(&doc, raw.http.as_ref(), base)?;
    let plc_listen = raw.plc_server.as_ref().map(|r| address(&doc, "plc_server.listen", &r.listen)).transpose()?;
    let plc_limits = parse_plc_limits(&doc, raw.plc_server.as_ref())?;
    let foxglove_listen = raw.foxglove.as_ref().map(|r| address(&doc, "foxglove.listen", &r.listen)).transpose()?;
    let (http_limits, foxglove_limits) = parse_server_limits(&doc, &raw)?;
    let (alerts, webhook, plc_coil) = match &raw.alerts {
        Some(a) => parse_alerts(&doc, a)?,
        None => (AlertConfig::default(), None, None),
    };
    let (new_billet_rise_m, idle_new_billet_s, encoder_at_die_m) = parse_billets(&doc, raw.billets.as_ref())?;
    let encoder_direction = parse_encoder(&doc, raw.encoder.as_ref())?;
    let sources = parse_sources(&doc, raw.sources.len(), base)?;
    let absent_channels = absent_channels(&sources);
    let advisor = super::advisor::parse_advisor(&doc, raw.advisor.as_ref())?;
    let recording_dir = path(&raw.recording.dir);
    let history = super::history::parse_history(&doc, raw.history.as_ref(), &recording_dir, &path)?;
    let part = super::history::parse_part(&doc, raw.part.as_ref())?;
    let die_life = super::history::parse_die_life(&doc, raw.die_life.as_ref())?;
    let drift = super::history::parse_drift(&doc, raw.drift.as_ref())?;
    Ok(ServiceConfig {
        machine_path: path(&raw.machine),
        process_path: raw.process.as_deref().map(path),
        recipe_path: raw.recipe.as_deref().map(path),
        recording_dir,
        rotate_bytes,
        rotate_seconds,
        keep_bytes: raw
            .recording
            .keep_bytes
            .map(|b| doc.in_whole_range("recording.keep_bytes", b, &KEEP_BYTES))
            .transpose()?,
        keep_days: raw.recording.keep_days.map(|d| doc.in_range("recording.keep_days", d, &KEEP_DAYS)).transpose()?,
        min_free_bytes: match raw.recording.min_free_bytes {
            Some(b) => doc.in_whole_range("recording.min_free_bytes", b, &MIN_FREE_BYTES)?,
            None => DEFAULT_MIN_FREE_BYTES,
        },
        http_listen,
        http_token_file,
        http_limits,
        plc_listen,
        plc_limits,
        foxglove_listen,
        foxglove_limits,
        opcua: super::opcua::parse_opcua(&doc, raw.opcua.as_ref(), base)?,
        alerts,
        webhook,
        plc_coil,
        new_billet_rise_m,
        idle_new_billet_s,
        encoder_at_die_m,
        encoder_direction,
        sources,
        absent_channels,
        advisor,
        uplink_mqtt: super::uplink::parse_uplink(&doc)?,
        history,
        part,
        die_life,
        drift,
    })
}

/// `s` as a path: absolute as given, relative from the configuration's directory `base`.
fn relative_to(base: &Path, s: &str) -> PathBuf {
    let p = PathBuf::from(s);
    if p.is_absolute() { p } else { base.join(p) }
}

/// `[recording]`'s rotation: bytes and seconds, each within its range or the default.
fn parse_rotation(doc: &Document<'_>, rec: &RawRecording) -> Result<(u64, u64), ConfigError> {
    let rotate_bytes = match rec.rotate_bytes {
        Some(b) => doc.in_whole_range("recording.rotate_bytes", b, &ROTATE_BYTES)?,
        None => DEFAULT_ROTATE_BYTES,
    };
    let rotate_seconds = match rec.rotate_seconds {
        Some(s) => doc.in_whole_range("recording.rotate_seconds", s, &ROTATE_SECONDS)?,
        None => DEFAULT_ROTATE_SECONDS,
    };
    Ok((rotate_bytes, rotate_seconds))
}

/// `[http]`'s and `[foxglove]`'s connection caps and timeouts, each over its default.
fn parse_server_limits(doc: &Document<'_>, raw: &RawService) -> Result<(HttpLimits, FoxgloveLimits), ConfigError> {
    let http = match &raw.http {
        Some(h) => {
            let raw = RawLimits { cap: h.max_connections, first_s: h.header_timeout_s, idle_s: h.idle_timeout_s };
            http_limits(doc, &raw)?
        }
        None => HttpLimits::default(),
    };
    let foxglove = match &raw.foxglove {
        Some(f) => {
            let raw = RawLimits { cap: f.max_clients, first_s: f.handshake_timeout_s, idle_s: f.idle_timeout_s };
            foxglove_limits(doc, &raw)?
        }
        None => FoxgloveLimits::default(),
    };
    Ok((http, foxglove))
}

/// `[plc_server]`'s idle timeout and connection cap, each within its range or the default.
fn parse_plc_limits(doc: &Document<'_>, plc: Option<&RawPlcServer>) -> Result<PlcLimits, ConfigError> {
    let d = PlcLimits::default();
    let Some(plc) = plc else { return Ok(d) };
    Ok(PlcLimits {
        idle_timeout_s: match plc.idle_timeout_s {
            Some(s) => doc.in_range("plc_server.idle_timeout_s", s, &PLC_IDLE_TIMEOUT_S)?,
            None => d.idle_timeout_s,
        },
        max_connections: match plc.max_connections {
            Some(n) => doc.in_whole_range("plc_server.max_connections", n, &PLC_MAX_CONNECTIONS)?,
            None => d.max_connections,
        },
    })
}

/// `[http] listen`, or the loopback default, and the token file, which an address other
/// than loopback requires (its requests then need `Authorization: Bearer <token>`).
fn parse_http(
    doc: &Document<'_>,
    http: Option<&RawHttp>,
    base: &Path,
) -> Result<(SocketAddr, Option<PathBuf>), ConfigError> {
    let Some(h) = http else {
        return Ok((DEFAULT_HTTP_LISTEN.parse().expect("a valid default address"), None));
    };
    let listen = address(doc, "http.listen", &h.listen)?;
    let token_file = h.token_file.as_deref().map(|f| relative_to(base, f));
    if token_file.is_none() && !listen.ip().is_loopback() {
        return Err(doc.invalid(
            "http.token_file",
            format!("is required when http.listen ({listen}) is not loopback: a file holding the bearer token"),
        ));
    }
    Ok((listen, token_file))
}

/// The `count` `[[sources]]` tables: at least one, each read by its kind, names unique.
fn parse_sources(doc: &Document<'_>, count: usize, base: &Path) -> Result<Vec<SourceSpec>, ConfigError> {
    if count == 0 {
        return Err(doc.invalid("sources", "must be a non-empty array of tables ([[sources]])"));
    }
    let sources = (1..=count).map(|i| source::parse_source(doc, i, base)).collect::<Result<Vec<_>, _>>()?;
    let mut names: Vec<&str> = sources.iter().map(SourceSpec::name).collect();
    names.sort();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(doc.invalid("sources", format!("two sources are named '{}'", w[0])));
    }
    Ok(sources)
}

/// What a service file sets of the pipeline's own thresholds: what a replay needs to judge
/// blows and find billets as the live run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipelineTuning {
    pub alerts: AlertConfig,
    pub new_billet_rise_m: Option<f64>,
    pub idle_new_billet_s: f64,
    pub encoder_at_die_m: Option<f64>,
    pub encoder_direction: EncoderDirection,
}

/// Only the tables a [`PipelineTuning`] reads; the rest of the file is not looked at (a
/// recording's copy names paths and ports of another machine).
#[derive(Deserialize)]
struct RawTuning {
    alerts: Option<RawAlerts>,
    billets: Option<RawBillets>,
    encoder: Option<RawEncoder>,
}

/// `[alerts]`, `[billets]` and `[encoder]` of the service configuration text `origin`,
/// checked like the whole file is by [`parse_service`].
pub fn parse_tuning(origin: &str, text: &str) -> Result<PipelineTuning, ConfigError> {
    let doc = Document::parse(origin, text)?;
    let raw: RawTuning = doc.read()?;
    let alerts = match &raw.alerts {
        Some(a) => parse_alerts(&doc, a)?.0,
        None => AlertConfig::default(),
    };
    let (new_billet_rise_m, idle_new_billet_s, encoder_at_die_m) = parse_billets(&doc, raw.billets.as_ref())?;
    let encoder_direction = parse_encoder(&doc, raw.encoder.as_ref())?;
    Ok(PipelineTuning { alerts, new_billet_rise_m, idle_new_billet_s, encoder_at_die_m, encoder_direction })
}

impl ServiceConfig {
    /// The pipeline thresholds this file sets.
    pub fn tuning(&self) -> PipelineTuning {
        PipelineTuning {
            alerts: self.alerts,
            new_billet_rise_m: self.new_billet_rise_m,
            idle_new_billet_s: self.idle_new_billet_s,
            encoder_at_die_m: self.encoder_at_die_m,
            encoder_direction: self.encoder_direction,
        }
    }
}

/// `[encoder] direction`: `"auto"` (the default: each blow's approach tells), `"down"` or
/// `"up"` (docs/interfaces.md §1: an encoder that counts the other way is a configuration matter).
fn parse_encoder(doc: &Document<'_>, encoder: Option<&RawEncoder>) -> Result<EncoderDirection, ConfigError> {
    if encoder.and_then(|e| e.direction.as_ref()).is_none() {
        return Ok(EncoderDirection::Auto);
    }
    let word = doc.choice("encoder.direction", &EncoderDirection::WORDS)?;
    Ok(EncoderDirection::parse(word).expect("one of the words"))
}

/// `[billets]`: the new-billet rise (`None`: the estimator's default), idle gap and the
/// encoder's reading on the die.
fn parse_billets(
    doc: &Document<'_>,
    billets: Option<&RawBillets>,
) -> Result<(Option<f64>, f64, Option<f64>), ConfigError> {
    let new_billet_rise_m = match billets.and_then(|b| b.new_billet_rise_m) {
        Some(r) => Some(doc.in_range("billets.new_billet_rise_m", r, &NEW_BILLET_RISE_M)?),
        None => None,
    };
    let idle_new_billet_s = match billets.and_then(|b| b.idle_s) {
        Some(s) => doc.in_range("billets.idle_s", s, &BILLET_IDLE_S)?,
        None => crate::estimate::billet::DEFAULT_IDLE_NEW_BILLET_S,
    };
    let encoder_at_die_m = match billets.and_then(|b| b.encoder_at_die_m) {
        Some(x) => Some(doc.in_range("billets.encoder_at_die_m", x, &ENCODER_AT_DIE_M)?),
        None => None,
    };
    Ok((new_billet_rise_m, idle_new_billet_s, encoder_at_die_m))
}

/// `[alerts]` over the defaults, with its webhook and PLC coil.
fn parse_alerts(
    doc: &Document<'_>,
    a: &RawAlerts,
) -> Result<(AlertConfig, Option<String>, Option<PlcCoil>), ConfigError> {
    let mut alerts = AlertConfig::default();
    efficiency_rule(doc, a, &mut alerts)?;
    if let Some(r) = a.residual_limit {
        alerts.residual_limit = doc.in_range("alerts.residual_limit", r, &RESIDUAL_LIMIT)?;
    }
    if let Some(r) = a.scale_drift_limit {
        alerts.scale_drift_limit = doc.in_range("alerts.scale_drift_limit", r, &RESIDUAL_LIMIT)?;
    }
    if let Some(r) = a.model_residual_limit {
        alerts.model_residual_limit = doc.in_range("alerts.model_residual_limit", r, &RESIDUAL_LIMIT)?;
    }
    sensor_rule(doc, a, &mut alerts)?;
    if let Some(d) = a.debounce_blows {
        alerts.debounce_blows = doc.in_whole_range("alerts.debounce_blows", d, &DEBOUNCE_BLOWS)? as u32;
    }
    if let Some(b) = a.hard_blow {
        alerts.on_hard_blow = b;
    }
    Ok((alerts, webhook(doc, a.webhook.as_deref())?, plc_coil(doc, a.plc_coil.as_ref())?))
}

/// The low-efficiency rule: `k_low` of the last `n_window` blows below `low_efficiency`.
fn efficiency_rule(doc: &Document<'_>, a: &RawAlerts, alerts: &mut AlertConfig) -> Result<(), ConfigError> {
    if let Some(x) = a.low_efficiency {
        alerts.low_efficiency = doc.in_range("alerts.low_efficiency", x, &EFFICIENCY)?;
    }
    if let Some(n) = a.n_window {
        alerts.n_window = doc.in_whole_range("alerts.n_window", n, &ALERT_WINDOW_BLOWS)? as usize;
    }
    if let Some(k) = a.k_low {
        alerts.k_low = doc.in_whole_range("alerts.k_low", k, &ALERT_WINDOW_BLOWS)? as usize;
    }
    if alerts.k_low > alerts.n_window {
        return Err(doc.invalid("alerts.k_low", format!("{} exceeds n_window {}", alerts.k_low, alerts.n_window)));
    }
    Ok(())
}

/// The sensor-health rule: `sensor_k` of the last `sensor_n` blows beyond `sensor_limit`.
fn sensor_rule(doc: &Document<'_>, a: &RawAlerts, alerts: &mut AlertConfig) -> Result<(), ConfigError> {
    if let Some(x) = a.sensor_limit {
        alerts.sensor_limit = doc.in_range("alerts.sensor_limit", x, &SENSOR_LIMIT)?;
    }
    if let Some(n) = a.sensor_n {
        alerts.sensor_n = doc.in_whole_range("alerts.sensor_n", n, &ALERT_WINDOW_BLOWS)? as usize;
    }
    if let Some(k) = a.sensor_k {
        alerts.sensor_k = doc.in_whole_range("alerts.sensor_k", k, &ALERT_WINDOW_BLOWS)? as usize;
    }
    if alerts.sensor_k > alerts.sensor_n {
        return Err(doc.invalid("alerts.sensor_k", format!("{} exceeds sensor_n {}", alerts.sensor_k, alerts.sensor_n)));
    }
    Ok(())
}

/// `alerts.webhook`: an http(s) URL.
fn webhook(doc: &Document<'_>, url: Option<&str>) -> Result<Option<String>, ConfigError> {
    match url {
        Some(url) if !(url.starts_with("http://") || url.starts_with("https://")) => {
            Err(doc.invalid("alerts.webhook", format!("'{url}' is not an http(s) URL")))
        }
        other => Ok(other.map(str::to_string)),
    }
}

/// `[alerts.plc_coil]`: the PLC's address:port, a Modbus unit id and the coil.
fn plc_coil(doc: &Document<'_>, c: Option<&RawPlcCoil>) -> Result<Option<PlcCoil>, ConfigError> {
    let Some(c) = c else { return Ok(None) };
    if c.unit > 247 {
        return Err(doc.invalid("alerts.plc_coil.unit", "must be 0..=247"));
    }
    Ok(Some(PlcCoil { address: address(doc, "alerts.plc_coil.address", &c.address)?, unit: c.unit, coil: c.coil }))
}

/// `s`, the value of `key`, as an address:port.
pub(super) fn address(doc: &Document<'_>, key: &str, s: &str) -> Result<SocketAddr, ConfigError> {
    s.parse().map_err(|_| doc.invalid(key, format!("'{s}' is not an address:port")))
}

#[cfg(test)]
#[path = "service_tests.rs"]
mod tests;
