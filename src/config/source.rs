//! The `[[sources]]` tables of the service configuration, one raw struct per `kind`
//! (serial, modbus; can in `can.rs`), each denying unknown keys.

use std::path::Path;
use std::time::Duration;

use serde::Deserialize;

use super::ConfigError;
use super::document::Document;
use super::limits::{BAUD, MODBUS_MS};
use super::service::{DEFAULT_BAUD, SerialFormat, SourceSpec, address};
use crate::acquire::ChannelSpec;
use crate::acquire::modbus::{DataType, ModbusConfig, Mode, RegisterKind, RegisterSpec, Signal, Transport, WordOrder};
use crate::signal::sample::Role;

/// Default speed of a Modbus RTU line.
pub const DEFAULT_RTU_BAUD: u32 = 19_200;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSerial {
    #[allow(dead_code)]
    name: String,
    #[allow(dead_code)]
    kind: String,
    /// The device. A `/dev/serial/by-id/...` path names one adapter and is followed to
    /// whatever `ttyUSBn` it comes back as when plugged in again; any other path is reopened
    /// only while it is the device first opened there (the same device number, and for a pty
    /// the same pty), else refused and retried (`acquire::serial::identity`).
    path: String,
    baud: Option<u64>,
    format: Option<RawFormat>,
    channels: Vec<RawChannel>,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawFormat {
    Binary,
    Ascii,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannel {
    role: String,
    gain: f64,
    offset: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModbus {
    #[allow(dead_code)]
    name: String,
    #[allow(dead_code)]
    kind: String,
    transport: RawTransport,
    address: Option<String>,
    path: Option<String>,
    baud: Option<u64>,
    unit: Option<u8>,
    poll_ms: Option<f64>,
    timeout_ms: Option<f64>,
    mode: Option<RawMode>,
    block_base: Option<u16>,
    registers: Option<Vec<RawRegister>>,
    channels: Option<Vec<RawChannel>>,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawTransport {
    Tcp,
    Rtu,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawMode {
    Poll,
    Block,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRegister {
    role: Option<String>,
    name: Option<String>,
    address: u16,
    register: Option<RawRegisterKind>,
    #[serde(rename = "type")]
    data_type: RawDataType,
    word_order: Option<RawWordOrder>,
    scale: Option<f64>,
    offset: Option<f64>,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawRegisterKind {
    Holding,
    Input,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawDataType {
    U16,
    I16,
    U32,
    I32,
    F32,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawWordOrder {
    Big,
    Little,
}

/// The `index`-th (from 1) `[[sources]]` table of `doc`, whose directory is `base`.
pub(super) fn parse_source(doc: &Document<'_>, index: usize, base: &Path) -> Result<SourceSpec, ConfigError> {
    let prefix = format!("sources[{index}]");
    let value = doc.get(&prefix).cloned().ok_or_else(|| doc.missing(&prefix))?;
    if value.get_ref().as_table().is_none() {
        return Err(doc.invalid(&prefix, "must be a table ([[sources]])"));
    }
    let name = source_name(doc, &format!("{prefix}.name"))?;
    match doc.choice(&format!("{prefix}.kind"), &["serial", "modbus", "can"])? {
        "serial" => {
            let raw: RawSerial = doc.read_value(value, &prefix)?;
            serial(doc, &prefix, name, raw)
        }
        "modbus" => {
            let raw: RawModbus = doc.read_value(value, &prefix)?;
            Ok(SourceSpec::Modbus(modbus(doc, &prefix, name, raw)?))
        }
        _ => can(doc, &prefix, value, base),
    }
}

/// A source's `name` at `key`: a string of letters, digits, '_' or '-'.
fn source_name(doc: &Document<'_>, key: &str) -> Result<String, ConfigError> {
    let name = match doc.get(key).map(|v| v.get_ref().as_str()) {
        None => return Err(doc.missing(key)),
        Some(None) => return Err(doc.invalid(key, "must be a string")),
        Some(Some(n)) => n.to_string(),
    };
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        return Err(doc.invalid(key, "must be letters, digits, '_' or '-'"));
    }
    Ok(name)
}

/// `kind = "can"`: `super::can`.
fn can(
    doc: &Document<'_>,
    prefix: &str,
    value: toml::Spanned<toml::de::DeValue<'_>>,
    base: &Path,
) -> Result<SourceSpec, ConfigError> {
    super::can::can_source(doc, prefix, value, base).map(SourceSpec::Can)
}

/// `kind = "serial"`: `path`, `baud`, `format` "binary"|"ascii" and 1 to 16
/// `[[sources.channels]]`.
fn serial(doc: &Document<'_>, prefix: &str, name: String, raw: RawSerial) -> Result<SourceSpec, ConfigError> {
    let key = |k: &str| format!("{prefix}.{k}");
    let baud = match raw.baud {
        Some(b) => doc.in_whole_range(&key("baud"), b, &BAUD)? as u32,
        None => DEFAULT_BAUD,
    };
    let format = match raw.format {
        None | Some(RawFormat::Binary) => SerialFormat::Binary,
        Some(RawFormat::Ascii) => SerialFormat::Ascii,
    };
    let channels = channels(doc, &key("channels"), &raw.channels)?;
    // docs/interfaces.md §7: 1..=16 channels per frame.
    if !(1..=16).contains(&channels.len()) {
        return Err(doc.invalid(&key("channels"), format!("has {} entries; a frame carries 1 to 16", channels.len())));
    }
    Ok(SourceSpec::Serial { name, path: raw.path, baud, format, channels })
}

/// `kind = "modbus"`: `transport` "tcp" (`address`) or "rtu" (`path`, `baud`), `unit`,
/// `poll_ms`, `timeout_ms`, and `mode` "poll" with `[[sources.registers]]` (`role` or
/// `name`, `address`, `register` "holding"|"input", `type` u16|i16|u32|i32|f32, `word_order`
/// "big"|"little", `scale`, `offset`) or "block" with `block_base` and `[[sources.channels]]`.
fn modbus(doc: &Document<'_>, prefix: &str, name: String, raw: RawModbus) -> Result<ModbusConfig, ConfigError> {
    use crate::acquire::modbus::client;
    let transport = transport(doc, prefix, &raw)?;
    let unit_id = unit(doc, prefix, raw.unit)?;
    let (poll_ms, timeout_ms) = (raw.poll_ms, raw.timeout_ms);
    let (mode, map, default_poll) = mode(doc, prefix, raw)?;
    Ok(ModbusConfig {
        source: name,
        transport,
        unit_id,
        poll_interval: millis(doc, &format!("{prefix}.poll_ms"), poll_ms, default_poll)?,
        timeout: millis(doc, &format!("{prefix}.timeout_ms"), timeout_ms, client::DEFAULT_TIMEOUT)?,
        map,
        mode,
    })
}

/// A Modbus source's `transport`: "tcp" needs `address`, "rtu" needs `path` (and `baud`).
fn transport(doc: &Document<'_>, prefix: &str, raw: &RawModbus) -> Result<Transport, ConfigError> {
    let key = |k: &str| format!("{prefix}.{k}");
    Ok(match raw.transport {
        RawTransport::Tcp => {
            let a = raw.address.as_deref().ok_or_else(|| doc.missing(&key("address")))?;
            Transport::Tcp { addr: address(doc, &key("address"), a)? }
        }
        RawTransport::Rtu => Transport::Rtu {
            path: raw.path.clone().ok_or_else(|| doc.missing(&key("path")))?,
            baud: match raw.baud {
                Some(b) => doc.in_whole_range(&key("baud"), b, &BAUD)? as u32,
                None => DEFAULT_RTU_BAUD,
            },
        },
    })
}

/// A Modbus unit id, 1 when not given; 248..=255 are reserved by the Modbus spec.
fn unit(doc: &Document<'_>, prefix: &str, unit: Option<u8>) -> Result<u8, ConfigError> {
    let unit = unit.unwrap_or(1);
    if unit > 247 {
        return Err(doc.invalid(&format!("{prefix}.unit"), "must be 0..=247"));
    }
    Ok(unit)
}

/// A duration given in ms at `key`, within `MODBUS_MS`, or `default`.
fn millis(doc: &Document<'_>, key: &str, given: Option<f64>, default: Duration) -> Result<Duration, ConfigError> {
    Ok(match given {
        Some(x) => Duration::from_secs_f64(doc.in_range(key, x, &MODBUS_MS)? / 1e3),
        None => default,
    })
}

/// A Modbus source's `mode`: "block" reads `[[sources.channels]]` from the ring at
/// `block_base`, "poll" (the default) reads `[[sources.registers]]`. Returns the mode, the
/// register map (empty in block mode) and the mode's default poll interval.
fn mode(doc: &Document<'_>, prefix: &str, raw: RawModbus) -> Result<(Mode, Vec<RegisterSpec>, Duration), ConfigError> {
    use crate::acquire::modbus::client;
    let key = |k: &str| format!("{prefix}.{k}");
    match raw.mode.unwrap_or(RawMode::Poll) {
        RawMode::Block => {
            let list = raw.channels.ok_or_else(|| doc.missing(&key("channels")))?;
            let channels = channels(doc, &key("channels"), &list)?;
            Ok((
                Mode::Block { base: raw.block_base.unwrap_or(0), channels },
                Vec::new(),
                client::DEFAULT_BLOCK_POLL_INTERVAL,
            ))
        }
        RawMode::Poll => {
            let list = raw.registers.ok_or_else(|| doc.missing(&key("registers")))?;
            let mut map = Vec::with_capacity(list.len());
            for (i, r) in list.into_iter().enumerate() {
                map.push(register(doc, &key(&format!("registers[{}]", i + 1)), r)?);
            }
            Ok((Mode::Poll, map, client::DEFAULT_POLL_INTERVAL))
        }
    }
}

/// One `[[sources.registers]]` entry at the dotted key `at`.
fn register(doc: &Document<'_>, at: &str, r: RawRegister) -> Result<RegisterSpec, ConfigError> {
    let key = |k: &str| format!("{at}.{k}");
    let signal = match (r.role, r.name) {
        (Some(n), _) => Signal::Role(role(doc, &key("role"), &n)?),
        (None, Some(n)) => Signal::Named(signal_name(doc, &key("name"), n)?),
        (None, None) => return Err(doc.missing(&key("name"))),
    };
    let finite = |k: &str, x: Option<f64>, default: f64| match x {
        Some(v) if !v.is_finite() => Err(doc.invalid(&key(k), format!("must be finite, got {v}"))),
        Some(v) => Ok(v),
        None => Ok(default),
    };
    Ok(RegisterSpec {
        signal,
        address: r.address,
        kind: match r.register.unwrap_or(RawRegisterKind::Holding) {
            RawRegisterKind::Holding => RegisterKind::Holding,
            RawRegisterKind::Input => RegisterKind::Input,
        },
        data_type: match r.data_type {
            RawDataType::U16 => DataType::U16,
            RawDataType::I16 => DataType::I16,
            RawDataType::U32 => DataType::U32,
            RawDataType::I32 => DataType::I32,
            RawDataType::F32 => DataType::F32,
        },
        word_order: match r.word_order.unwrap_or(RawWordOrder::Big) {
            RawWordOrder::Big => WordOrder::BigEndian,
            RawWordOrder::Little => WordOrder::LittleEndian,
        },
        scale: finite("scale", r.scale, 1.0)?,
        offset: finite("offset", r.offset, 0.0)?,
    })
}

/// Words the Modbus driver writes into its status detail itself (`acquire::modbus::client`).
const DETAIL_KEYS: [&str; 5] = ["exceptions", "timeouts", "tcp", "rtu", "last_error"];

/// A named register's `name`, which the status detail shows as one `name=value` word: not
/// empty, no space or `=`, and none of the driver's own keys.
fn signal_name(doc: &Document<'_>, at: &str, name: String) -> Result<String, ConfigError> {
    if name.is_empty() || name.chars().any(|c| c.is_whitespace() || c == '=') {
        return Err(doc.invalid(at, format!("must be a non-empty word without spaces or '=', not '{name}'")));
    }
    if DETAIL_KEYS.contains(&name.as_str()) {
        return Err(doc.invalid(at, format!("must not be '{name}', a key the status detail already uses")));
    }
    Ok(name)
}

/// A sample role by its column name.
fn role(doc: &Document<'_>, at: &str, name: &str) -> Result<Role, ConfigError> {
    Role::from_column(name).ok_or_else(|| doc.invalid(at, format!("'{name}' is not load_N, disp_m or acc_mps2")))
}

/// `[[sources.channels]]` at the dotted key `at`: physical = offset + gain * count.
fn channels(doc: &Document<'_>, at: &str, list: &[RawChannel]) -> Result<Vec<ChannelSpec>, ConfigError> {
    let mut out = Vec::with_capacity(list.len());
    for (i, c) in list.iter().enumerate() {
        let key = |k: &str| format!("{at}[{}].{k}", i + 1);
        let role = role(doc, &key("role"), &c.role)?;
        if c.gain == 0.0 {
            return Err(doc.invalid(&key("gain"), "must not be 0"));
        }
        if !c.gain.is_finite() {
            return Err(doc.invalid(&key("gain"), format!("must be finite, got {}", c.gain)));
        }
        let offset = c.offset.unwrap_or(0.0);
        if !offset.is_finite() {
            return Err(doc.invalid(&key("offset"), format!("must be finite, got {offset}")));
        }
        out.push(ChannelSpec { role, gain: c.gain, offset });
    }
    for role in Role::ALL {
        if out.iter().filter(|c| c.role == role).count() > 1 {
            return Err(doc.invalid(at, format!("role {role} appears twice")));
        }
    }
    Ok(out)
}
