//! The service's configuration (`forgemon run --config FILE`): the machine and process
//! files, the recording, the status endpoint, the alert rules and sinks, and the sources.
//! Read once, validated completely (every error names the key) before anything is opened.
//! Relative paths are taken from the configuration file's directory.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use super::{ConfigError, Keys, parse_table};
use crate::acquire::ChannelSpec;
use crate::alert::AlertConfig;
use crate::signal::sample::Role;

/// Default status/metrics address: loopback only.
pub const DEFAULT_HTTP_LISTEN: &str = "127.0.0.1:9187";
/// Default rotation: 512 MiB or one hour, whichever comes first.
pub const DEFAULT_ROTATE_BYTES: u64 = 512 * 1024 * 1024;
pub const DEFAULT_ROTATE_SECONDS: u64 = 3600;
/// Default serial speed.
pub const DEFAULT_BAUD: u32 = 921_600;

/// Serial line format (CONTRACTS.md §7).
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
}

/// A Modbus coil on the PLC set when an alert fires.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlcCoil {
    pub address: SocketAddr,
    pub unit: u8,
    pub coil: u16,
}

/// The validated service configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ServiceConfig {
    pub machine_path: PathBuf,
    pub process_path: Option<PathBuf>,
    pub recording_dir: PathBuf,
    pub rotate_bytes: u64,
    pub rotate_seconds: u64,
    pub http_listen: SocketAddr,
    pub alerts: AlertConfig,
    pub webhook: Option<String>,
    pub plc_coil: Option<PlcCoil>,
    pub sources: Vec<SourceSpec>,
}

/// Parse the text of the service configuration `origin`, whose directory is `base`.
pub fn parse_service(origin: &str, base: &Path, text: &str) -> Result<ServiceConfig, ConfigError> {
    let table = parse_table(origin, text)?;
    let keys = Keys::root(origin, &table);
    let path = |s: &str| {
        let p = PathBuf::from(s);
        if p.is_absolute() { p } else { base.join(p) }
    };
    let machine_path = path(keys.string("machine")?);
    let process_path = table.contains_key("process").then(|| keys.string("process")).transpose()?.map(path);

    let rec = keys.table("recording")?;
    let recording_dir = path(rec.string("dir")?);
    let rotate_bytes = match rec.opt_number("rotate_bytes")? {
        Some(_) => rec.positive("rotate_bytes")? as u64,
        None => DEFAULT_ROTATE_BYTES,
    };
    let rotate_seconds = match rec.opt_number("rotate_seconds")? {
        Some(_) => rec.positive("rotate_seconds")? as u64,
        None => DEFAULT_ROTATE_SECONDS,
    };

    let http_listen = match table.get("http") {
        None => DEFAULT_HTTP_LISTEN.parse().expect("a valid default address"),
        Some(_) => {
            let h = keys.table("http")?;
            let s = h.string("listen")?;
            s.parse().map_err(|_| h.invalid("listen", format!("'{s}' is not an address:port")))?
        }
    };

    let mut alerts = AlertConfig::default();
    let (mut webhook, mut plc_coil) = (None, None);
    if table.contains_key("alerts") {
        let a = keys.table("alerts")?;
        if let Some(x) = a.opt_number("low_efficiency")? {
            alerts.low_efficiency =
                if (0.0..=1.0).contains(&x) { x } else { return Err(a.invalid("low_efficiency", "must be in [0, 1]")) };
        }
        if a.opt_number("k_low")?.is_some() {
            alerts.k_low = a.non_negative("k_low")? as usize;
        }
        if a.opt_number("n_window")?.is_some() {
            alerts.n_window = a.positive("n_window")? as usize;
        }
        if alerts.k_low > alerts.n_window {
            return Err(a.invalid("k_low", format!("{} exceeds n_window {}", alerts.k_low, alerts.n_window)));
        }
        if a.opt_number("residual_limit")?.is_some() {
            alerts.residual_limit = a.positive("residual_limit")?;
        }
        if a.opt_number("debounce_blows")?.is_some() {
            alerts.debounce_blows = a.non_negative("debounce_blows")? as u32;
        }
        if a.table.contains_key("hard_blow") {
            alerts.on_hard_blow = match a.table.get("hard_blow") {
                Some(toml::Value::Boolean(b)) => *b,
                _ => return Err(a.invalid("hard_blow", "must be true or false")),
            };
        }
        if a.table.contains_key("webhook") {
            let url = a.string("webhook")?;
            if !(url.starts_with("http://") || url.starts_with("https://")) {
                return Err(a.invalid("webhook", format!("'{url}' is not an http(s) URL")));
            }
            webhook = Some(url.to_string());
        }
        if a.table.contains_key("plc_coil") {
            let c = a.table("plc_coil")?;
            let s = c.string("address")?;
            let address = s.parse().map_err(|_| c.invalid("address", format!("'{s}' is not an address:port")))?;
            let unit = c.non_negative("unit")?;
            let coil = c.non_negative("coil")?;
            if unit > 247.0 {
                return Err(c.invalid("unit", "must be 0..=247"));
            }
            if coil > 65535.0 {
                return Err(c.invalid("coil", "must be 0..=65535"));
            }
            plc_coil = Some(PlcCoil { address, unit: unit as u8, coil: coil as u16 });
        }
    }

    let sources = match table.get("sources") {
        Some(toml::Value::Array(list)) if !list.is_empty() => {
            let mut out = Vec::new();
            for (i, v) in list.iter().enumerate() {
                let key = format!("sources[{}]", i + 1);
                let toml::Value::Table(t) = v else { return Err(keys.invalid(&key, "must be a table ([[sources]])")) };
                let s = Keys { origin, prefix: key, table: t };
                out.push(parse_source(&s, base)?);
            }
            let mut names: Vec<&str> = out.iter().map(SourceSpec::name).collect();
            names.sort();
            if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
                return Err(keys.invalid("sources", format!("two sources are named '{}'", w[0])));
            }
            out
        }
        Some(_) => return Err(keys.invalid("sources", "must be a non-empty array of tables ([[sources]])")),
        None => return Err(keys.missing("sources")),
    };
    Ok(ServiceConfig {
        machine_path,
        process_path,
        recording_dir,
        rotate_bytes,
        rotate_seconds,
        http_listen,
        alerts,
        webhook,
        plc_coil,
        sources,
    })
}

fn parse_source(s: &Keys<'_>, base: &Path) -> Result<SourceSpec, ConfigError> {
    let name = s.string("name")?.to_string();
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        return Err(s.invalid("name", "must be letters, digits, '_' or '-'"));
    }
    match s.string("kind")? {
        "serial" => {
            let format = match s.table.get("format").map(|_| s.string("format")).transpose()? {
                None | Some("binary") => SerialFormat::Binary,
                Some("ascii") => SerialFormat::Ascii,
                Some(other) => {
                    return Err(s.invalid("format", format!("must be \"binary\" or \"ascii\", got \"{other}\"")));
                }
            };
            let baud = match s.opt_number("baud")? {
                Some(_) => s.positive("baud")? as u32,
                None => DEFAULT_BAUD,
            };
            let channels = parse_channels(s)?;
            // CONTRACTS.md §7: 1..=16 channels per frame.
            if !(1..=16).contains(&channels.len()) {
                return Err(s.invalid("channels", format!("has {} entries; a frame carries 1 to 16", channels.len())));
            }
            Ok(SourceSpec::Serial { name, path: s.string("path")?.to_string(), baud, format, channels })
        }
        "modbus" => Ok(SourceSpec::Modbus(parse_modbus(s, name)?)),
        "can" => Ok(SourceSpec::Can(crate::acquire::can::parse_can_source(s.origin, &s.prefix, s.table, base)?)),
        other => Err(s.invalid("kind", format!("'{other}' is not a known source kind (serial, modbus, can)"))),
    }
}

/// `kind = "modbus"`: `transport` "tcp" (`address`) or "rtu" (`path`, `baud`), `unit`,
/// `poll_ms`, `timeout_ms`, and `mode` "poll" with `[[sources.registers]]` (`role` or
/// `name`, `address`, `register` "holding"|"input", `type` u16|i16|u32|i32|f32, `word_order`
/// "big"|"little", `scale`, `offset`) or "block" with `block_base` and `[[sources.channels]]`.
fn parse_modbus(s: &Keys<'_>, name: String) -> Result<crate::acquire::modbus::ModbusConfig, ConfigError> {
    use crate::acquire::modbus::{
        DataType, ModbusConfig, Mode, RegisterKind, RegisterSpec, Signal, Transport, WordOrder, client,
    };
    use std::time::Duration;
    let transport = match s.string("transport")? {
        "tcp" => {
            let a = s.string("address")?;
            Transport::Tcp {
                addr: a.parse().map_err(|_| s.invalid("address", format!("'{a}' is not an address:port")))?,
            }
        }
        "rtu" => Transport::Rtu {
            path: s.string("path")?.to_string(),
            baud: match s.opt_number("baud")? {
                Some(_) => s.positive("baud")? as u32,
                None => 19_200,
            },
        },
        other => return Err(s.invalid("transport", format!("must be \"tcp\" or \"rtu\", got \"{other}\""))),
    };
    let unit = match s.opt_number("unit")? {
        Some(_) => s.non_negative("unit")?,
        None => 1.0,
    };
    if unit > 247.0 {
        return Err(s.invalid("unit", "must be 0..=247"));
    }
    let ms = |key: &str, default: Duration| -> Result<Duration, ConfigError> {
        Ok(match s.opt_number(key)? {
            Some(_) => Duration::from_secs_f64(s.positive(key)? / 1e3),
            None => default,
        })
    };
    let (mode, map, default_poll) = match s.table.get("mode").map(|_| s.string("mode")).transpose()?.unwrap_or("poll") {
        "block" => {
            let base = match s.opt_number("block_base")? {
                Some(_) => s.non_negative("block_base")?,
                None => 0.0,
            };
            if base > 65535.0 {
                return Err(s.invalid("block_base", "must be a register address 0..=65535"));
            }
            (
                Mode::Block { base: base as u16, channels: parse_channels(s)? },
                Vec::new(),
                client::DEFAULT_BLOCK_POLL_INTERVAL,
            )
        }
        "poll" => {
            let Some(toml::Value::Array(list)) = s.table.get("registers") else { return Err(s.missing("registers")) };
            let mut map = Vec::new();
            for (i, v) in list.iter().enumerate() {
                let key = format!("registers[{}]", i + 1);
                let toml::Value::Table(t) = v else { return Err(s.invalid(&key, "must be a table")) };
                let r = Keys { origin: s.origin, prefix: s.path(&key), table: t };
                let signal = if r.table.contains_key("role") {
                    let n = r.string("role")?;
                    Signal::Role(
                        Role::from_column(n)
                            .ok_or_else(|| r.invalid("role", format!("'{n}' is not load_N, disp_m or acc_mps2")))?,
                    )
                } else {
                    Signal::Named(r.string("name")?.to_string())
                };
                let address = r.non_negative("address")?;
                if address > 65535.0 {
                    return Err(r.invalid("address", "must be 0..=65535"));
                }
                let kind = match r.table.get("register").map(|_| r.string("register")).transpose()?.unwrap_or("holding")
                {
                    "holding" => RegisterKind::Holding,
                    "input" => RegisterKind::Input,
                    other => {
                        return Err(r.invalid("register", format!("must be \"holding\" or \"input\", got \"{other}\"")));
                    }
                };
                let data_type = match r.string("type")? {
                    "u16" => DataType::U16,
                    "i16" => DataType::I16,
                    "u32" => DataType::U32,
                    "i32" => DataType::I32,
                    "f32" => DataType::F32,
                    other => return Err(r.invalid("type", format!("'{other}' is not u16, i16, u32, i32 or f32"))),
                };
                let word_order =
                    match r.table.get("word_order").map(|_| r.string("word_order")).transpose()?.unwrap_or("big") {
                        "big" => WordOrder::BigEndian,
                        "little" => WordOrder::LittleEndian,
                        other => {
                            return Err(
                                r.invalid("word_order", format!("must be \"big\" or \"little\", got \"{other}\""))
                            );
                        }
                    };
                let scale = r.opt_number("scale")?.map(|_| r.finite("scale")).transpose()?.unwrap_or(1.0);
                let offset = r.opt_number("offset")?.map(|_| r.finite("offset")).transpose()?.unwrap_or(0.0);
                map.push(RegisterSpec { signal, address: address as u16, kind, data_type, word_order, scale, offset });
            }
            (Mode::Poll, map, client::DEFAULT_POLL_INTERVAL)
        }
        other => return Err(s.invalid("mode", format!("must be \"poll\" or \"block\", got \"{other}\""))),
    };
    Ok(ModbusConfig {
        source: name,
        transport,
        unit_id: unit as u8,
        poll_interval: ms("poll_ms", default_poll)?,
        timeout: ms("timeout_ms", client::DEFAULT_TIMEOUT)?,
        map,
        mode,
    })
}

fn parse_channels(s: &Keys<'_>) -> Result<Vec<ChannelSpec>, ConfigError> {
    let Some(toml::Value::Array(list)) = s.table.get("channels") else {
        return Err(if s.table.contains_key("channels") {
            s.invalid("channels", "must be an array of tables")
        } else {
            s.missing("channels")
        });
    };
    let mut out = Vec::new();
    for (i, v) in list.iter().enumerate() {
        let key = format!("channels[{}]", i + 1);
        let toml::Value::Table(t) = v else { return Err(s.invalid(&key, "must be a table")) };
        let c = Keys { origin: s.origin, prefix: s.path(&key), table: t };
        let role_name = c.string("role")?;
        let role = Role::from_column(role_name)
            .ok_or_else(|| c.invalid("role", format!("'{role_name}' is not load_N, disp_m or acc_mps2")))?;
        let gain = c.finite("gain")?;
        if gain == 0.0 {
            return Err(c.invalid("gain", "must not be 0"));
        }
        let offset = c.opt_number("offset")?.map(|_| c.finite("offset")).transpose()?.unwrap_or(0.0);
        out.push(ChannelSpec { role, gain, offset });
    }
    for role in Role::ALL {
        if out.iter().filter(|c| c.role == role).count() > 1 {
            return Err(s.invalid("channels", format!("role {role} appears twice")));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
machine = "hammer.machine.toml"
process = "/etc/forgemon/steel.process.toml"
[recording]
dir = "rec"
[alerts]
low_efficiency = 0.55
webhook = "http://127.0.0.1:9999/alerts"
[alerts.plc_coil]
address = "127.0.0.1:502"
unit = 1
coil = 7
[[sources]]
name = "daq"
kind = "serial"
path = "/dev/ttyUSB0"
[[sources.channels]]
role = "load_N"
gain = 10.0
[[sources.channels]]
role = "disp_m"
gain = 1e-6
offset = 0.1
[[sources.channels]]
role = "acc_mps2"
gain = 0.01
"#;

    #[test]
    fn a_full_configuration_parses_with_defaults() {
        let c = parse_service("s.toml", Path::new("/etc/forgemon"), GOOD).unwrap();
        assert_eq!(c.machine_path, PathBuf::from("/etc/forgemon/hammer.machine.toml"));
        assert_eq!(c.process_path, Some(PathBuf::from("/etc/forgemon/steel.process.toml")));
        assert_eq!(c.recording_dir, PathBuf::from("/etc/forgemon/rec"));
        assert_eq!(c.http_listen.to_string(), DEFAULT_HTTP_LISTEN);
        assert_eq!(c.alerts.low_efficiency, 0.55);
        assert_eq!(c.plc_coil.unwrap().coil, 7);
        let SourceSpec::Serial { baud, format, channels, .. } = &c.sources[0] else { panic!("a serial source") };
        assert_eq!((*baud, *format), (DEFAULT_BAUD, SerialFormat::Binary));
        assert_eq!(channels[1], ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.1 });
    }

    #[test]
    fn the_example_service_configs_parse_and_name_existing_files() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
        for name in ["hammer-serial.service.toml", "hammer-can.service.toml", "press-modbus-serial.service.toml"] {
            let text = std::fs::read_to_string(dir.join(name)).unwrap();
            let c = parse_service(name, &dir, &text).unwrap();
            assert!(c.machine_path.exists(), "{name}: {}", c.machine_path.display());
            assert!(c.process_path.as_ref().is_none_or(|p| p.exists()), "{name}");
        }
    }

    #[test]
    fn a_modbus_source_reads_its_register_map() {
        use crate::acquire::modbus::{DataType, Mode, Transport, WordOrder};
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
        let text = std::fs::read_to_string(dir.join("press-modbus-serial.service.toml")).unwrap();
        let c = parse_service("press", &dir, &text).unwrap();
        let SourceSpec::Modbus(m) = &c.sources[1] else { panic!("a modbus source") };
        assert!(matches!(m.transport, Transport::Tcp { .. }) && matches!(m.mode, Mode::Poll));
        assert_eq!(
            (m.map[0].address, m.map[0].data_type, m.map[0].word_order),
            (100, DataType::U32, WordOrder::BigEndian)
        );
        assert_eq!(m.map[1].scale, 0.1);
        assert_eq!(m.timeout, std::time::Duration::from_millis(200));
        let e = parse_service("p", &dir, &text.replace("type = \"i16\"", "type = \"i8\"")).unwrap_err();
        assert!(e.to_string().contains("key 'sources[2].registers[2].type'"), "{e}");
    }

    #[test]
    fn errors_name_the_key() {
        let e = |text: &str| parse_service("s.toml", Path::new("/"), text).unwrap_err().to_string();
        assert_eq!(e(&GOOD.replace("machine = \"hammer.machine.toml\"\n", "")), "s.toml: missing key 'machine'");
        assert!(e(&GOOD.replace("kind = \"serial\"", "kind = \"usb\"")).contains("key 'sources[1].kind'"));
        assert!(
            e(&GOOD.replace("role = \"disp_m\"", "role = \"displacement\""))
                .contains("key 'sources[1].channels[2].role'")
        );
        assert!(
            e(&GOOD.replace("gain = 0.01", "gain = 0")).contains("key 'sources[1].channels[3].gain' must not be 0")
        );
        assert!(e(&GOOD.replace("http://127.0.0.1:9999/alerts", "ftp://x")).contains("key 'alerts.webhook'"));
        assert!(
            e(&GOOD.replace("address = \"127.0.0.1:502\"", "address = \"plc\""))
                .contains("key 'alerts.plc_coil.address'")
        );
        assert!(e(&GOOD.replace("role = \"acc_mps2\"", "role = \"load_N\"")).contains("role load_N appears twice"));
        assert!(e(&format!("{GOOD}[http]\nlisten = \"nowhere\"\n")).contains("key 'http.listen'"));
    }
}
