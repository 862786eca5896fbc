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
}

impl SourceSpec {
    pub fn name(&self) -> &str {
        match self {
            SourceSpec::Serial { name, .. } => name,
            SourceSpec::Can(c) => &c.name,
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
        "can" => Ok(SourceSpec::Can(crate::acquire::can::parse_can_source(s.origin, &s.prefix, s.table, base)?)),
        other => Err(s.invalid("kind", format!("'{other}' is not a known source kind (serial, can)"))),
    }
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
        for name in ["hammer-serial.service.toml", "hammer-can.service.toml"] {
            let text = std::fs::read_to_string(dir.join(name)).unwrap();
            let c = parse_service(name, &dir, &text).unwrap();
            assert!(c.machine_path.exists(), "{name}: {}", c.machine_path.display());
            assert!(c.process_path.as_ref().is_none_or(|p| p.exists()), "{name}");
        }
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
