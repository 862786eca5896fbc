//! A CAN source's configuration, read from the service config's `[[sources]]` table with
//! `kind = "can"` in two steps: [`parse_can_source`] validates the keys (pure, every
//! error names the key), and [`CanSourceSpec::resolve`] reads the DBC file, if any, into
//! the mapping. Both run before anything is opened.
//!
//! ```toml
//! [[sources]]
//! name = "bus"
//! kind = "can"
//! interface = "can0"        # live SocketCAN; or log = "capture.log" (candump -L)
//! sample_rate_hz = 5000     # the DAQ's sample rate (frames carry no time)
//! batch_s = 0.05            # optional
//! fd = false                # optional: CAN FD frames (`##`, up to 64 bytes)
//! samples_per_frame = 1     # optional: a block of N samples a frame, DBC signals
//!                           # Load_0 .. Load_{N-1} for the role's "Load" (needs dbc)
//! dbc = "hammer.dbc"        # relative to the config file
//! [sources.signals]         # role = DBC signal ("Signal" or "Message.Signal")
//! load_N = "Load"
//! disp_m = "Disp"
//! acc_mps2 = "Acc"
//! sequence = "Seq"          # optional counter
//! ```
//!
//! Without `dbc`, each signal is a table of `[[sources.can_signals]]` with `role`
//! (`load_N`, `disp_m`, `acc_mps2` or `sequence`), `id`, `extended` (default false),
//! `start_bit`, `length`, `byte_order` (`"intel"` or `"motorola"`), `signed`, `factor`
//! and `offset` (default 0).

use std::path::{Path, PathBuf};

use crate::config::{ConfigError, Keys};
use crate::signal::capture::DEFAULT_BATCH_S;
use crate::signal::sample::Role;

use super::CanError;
use super::dbc::{DbcNames, block_mapping_from_dbc};
use super::decoder::CanTiming;
use super::live::CanSourceConfig;
use super::signal::{ByteOrder, CLASSIC_MAX_LEN, CanMapping, CanSignalSpec, FD_MAX_LEN, FrameId, SignalLayout};

/// Where the frames come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CanInput {
    /// A SocketCAN interface.
    Interface(String),
    /// A `candump -L` log file.
    Log(PathBuf),
}

/// How the signals are mapped.
#[derive(Debug, Clone, PartialEq)]
pub enum CanSignals {
    Dbc { path: PathBuf, names: DbcNames },
    Explicit(CanMapping),
}

/// A validated `[[sources]]` table of kind `can`, before its DBC file is read.
#[derive(Debug, Clone, PartialEq)]
pub struct CanSourceSpec {
    pub name: String,
    pub input: CanInput,
    pub sample_rate_hz: f64,
    pub batch_s: f64,
    /// CAN FD frames (the live driver opens an FD socket).
    pub fd: bool,
    /// Samples a sample frame carries (a block, `acquire::can` docs); 1 for classic.
    pub samples_per_frame: usize,
    pub signals: CanSignals,
}

/// The most samples one frame can carry (a 64-byte payload of 1-byte samples).
pub const MAX_SAMPLES_PER_FRAME: i64 = 64;

impl CanSourceSpec {
    /// Read the DBC file (if any) and build the driver's configuration. A log's receive
    /// times are trusted; a live socket's are trusted when the kernel stamps them.
    pub fn resolve(&self) -> Result<CanSourceConfig, CanError> {
        let mapping = match &self.signals {
            CanSignals::Explicit(m) => m.clone(),
            CanSignals::Dbc { path, names } => {
                let origin = path.display().to_string();
                let text =
                    std::fs::read_to_string(path).map_err(|source| CanError::Io { origin: origin.clone(), source })?;
                block_mapping_from_dbc(&origin, &text, names, self.samples_per_frame, self.fd)?
            }
        };
        let iface = match &self.input {
            CanInput::Interface(i) => i.clone(),
            CanInput::Log(p) => p.display().to_string(),
        };
        Ok(CanSourceConfig {
            name: self.name.clone(),
            iface,
            mapping,
            timing: CanTiming::new(self.sample_rate_hz, self.batch_s, true),
        })
    }
}

fn integer(k: &Keys<'_>, key: &str) -> Result<Option<i64>, ConfigError> {
    match k.table.get(key) {
        Some(toml::Value::Integer(i)) => Ok(Some(*i)),
        Some(_) => Err(k.invalid(key, "must be an integer")),
        None => Ok(None),
    }
}

fn boolean(k: &Keys<'_>, key: &str, default: bool) -> Result<bool, ConfigError> {
    match k.table.get(key) {
        Some(toml::Value::Boolean(b)) => Ok(*b),
        Some(_) => Err(k.invalid(key, "must be true or false")),
        None => Ok(default),
    }
}

/// Validate the keys of a `kind = "can"` source: `table` is the source's table in the
/// file `origin`, found under the dotted key `prefix` (for example `sources[2]`), which
/// errors name; `base` is the config file's directory.
pub fn parse_can_source(
    origin: &str,
    prefix: &str,
    table: &toml::Table,
    base: &Path,
) -> Result<CanSourceSpec, ConfigError> {
    parse_keys(&Keys { origin, prefix: prefix.to_string(), table }, base)
}

fn parse_keys(s: &Keys<'_>, base: &Path) -> Result<CanSourceSpec, ConfigError> {
    let name = s.string("name")?.to_string();
    let input = match (s.table.contains_key("interface"), s.table.contains_key("log")) {
        (true, false) => CanInput::Interface(s.string("interface")?.to_string()),
        (false, true) => CanInput::Log(base.join(s.string("log")?)),
        (true, true) => return Err(s.invalid("log", "give either 'interface' or 'log', not both")),
        (false, false) => return Err(s.missing("interface")),
    };
    let sample_rate_hz = s.positive("sample_rate_hz")?;
    let batch_s = match s.opt_number("batch_s")? {
        Some(_) => s.positive("batch_s")?,
        None => DEFAULT_BATCH_S,
    };
    let fd = boolean(s, "fd", false)?;
    let samples_per_frame = match integer(s, "samples_per_frame")? {
        None => 1,
        Some(n) if (1..=MAX_SAMPLES_PER_FRAME).contains(&n) => n as usize,
        Some(n) => return Err(s.invalid("samples_per_frame", format!("{n} is not 1..={MAX_SAMPLES_PER_FRAME}"))),
    };
    if samples_per_frame > 1 && !s.table.contains_key("dbc") {
        return Err(s.invalid("samples_per_frame", "a block of samples per frame is read from a DBC file ('dbc')"));
    }
    let max_len = if fd { FD_MAX_LEN } else { CLASSIC_MAX_LEN };
    let signals = if s.table.contains_key("dbc") {
        let path = base.join(s.string("dbc")?);
        let sig = s.table("signals")?;
        let mut names = DbcNames::default();
        for (key, v) in sig.table {
            let toml::Value::String(signal) = v else { return Err(sig.invalid(key, "must be a DBC signal name")) };
            match (key.as_str(), Role::from_column(key)) {
                ("sequence", _) => names.sequence = Some(signal.clone()),
                (_, Some(role)) => names.roles.push((role, signal.clone())),
                _ => return Err(sig.invalid(key, "is not load_N, disp_m, acc_mps2 or sequence")),
            }
        }
        if names.roles.is_empty() {
            return Err(sig.invalid("load_N", "no role is mapped"));
        }
        CanSignals::Dbc { path, names }
    } else {
        let Some(toml::Value::Array(list)) = s.table.get("can_signals") else {
            return Err(s.missing("dbc"));
        };
        let mut roles = Vec::new();
        let mut sequence = None;
        for (i, v) in list.iter().enumerate() {
            let key = format!("can_signals[{}]", i + 1);
            let toml::Value::Table(t) = v else { return Err(s.invalid(&key, "must be a table")) };
            let c = Keys { origin: s.origin, prefix: s.path(&key), table: t };
            let id = integer(&c, "id")?.ok_or_else(|| c.missing("id"))?;
            let extended = boolean(&c, "extended", false)?;
            let frame = FrameId { id: u32::try_from(id).unwrap_or(u32::MAX), extended };
            if !frame.is_valid() {
                return Err(c.invalid(
                    "id",
                    format!("{id:#x} does not fit a {} identifier", if extended { "29-bit" } else { "11-bit" }),
                ));
            }
            let small = |key: &str| -> Result<u16, ConfigError> {
                let v = integer(&c, key)?.ok_or_else(|| c.missing(key))?;
                u16::try_from(v)
                    .ok()
                    .filter(|&b| (b as usize) < 8 * max_len || key == "length")
                    .ok_or_else(|| c.invalid(key, format!("{v} out of range")))
            };
            let byte_order = match c.string("byte_order")? {
                "intel" => ByteOrder::LittleEndian,
                "motorola" => ByteOrder::BigEndian,
                other => {
                    return Err(c.invalid("byte_order", format!("must be \"intel\" or \"motorola\", got \"{other}\"")));
                }
            };
            let layout = SignalLayout {
                frame,
                start_bit: small("start_bit")?,
                length: small("length")?,
                byte_order,
                signed: boolean(&c, "signed", false)?,
                factor: c.opt_number("factor")?.map(|_| c.finite("factor")).transpose()?.unwrap_or(1.0),
                offset: c.opt_number("offset")?.map(|_| c.finite("offset")).transpose()?.unwrap_or(0.0),
            };
            let role = c.string("role")?;
            layout.validate_within(role, max_len).map_err(|e| c.invalid("length", e.to_string()))?;
            match Role::from_column(role) {
                Some(r) => roles.push(CanSignalSpec { role: r, layout }),
                None if role == "sequence" => sequence = Some(layout),
                None => return Err(c.invalid("role", format!("'{role}' is not load_N, disp_m, acc_mps2 or sequence"))),
            }
        }
        let mapping =
            CanMapping::block(vec![roles], sequence, fd).map_err(|e| s.invalid("can_signals", e.to_string()))?;
        CanSignals::Explicit(mapping)
    };
    Ok(CanSourceSpec { name, input, sample_rate_hz, batch_s, fd, samples_per_frame, signals })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquire::can::forgemon_mapping;

    fn parse(text: &str) -> Result<CanSourceSpec, ConfigError> {
        let table: toml::Table = text.parse().expect("TOML");
        parse_can_source("svc.toml", "sources[1]", &table, Path::new("/etc/fm"))
    }

    const DBC_SOURCE: &str = r#"
name = "bus"
kind = "can"
interface = "can0"
sample_rate_hz = 5000
dbc = "hammer.dbc"
[signals]
load_N = "Load"
disp_m = "Disp"
acc_mps2 = "Acc"
sequence = "Seq"
"#;

    const EXPLICIT: &str = r#"
name = "bus"
kind = "can"
log = "cap.log"
sample_rate_hz = 5000
batch_s = 0.02
[[can_signals]]
role = "sequence"
id = 0x120
start_bit = 0
length = 8
byte_order = "intel"
[[can_signals]]
role = "load_N"
id = 0x120
start_bit = 8
length = 16
byte_order = "intel"
signed = true
factor = 100
[[can_signals]]
role = "acc_mps2"
id = 0x120
start_bit = 24
length = 16
byte_order = "intel"
signed = true
factor = 0.25
[[can_signals]]
role = "disp_m"
id = 0x120
start_bit = 40
length = 24
byte_order = "intel"
signed = true
factor = 1e-6
"#;

    #[test]
    fn a_dbc_source_names_its_file_and_signals() {
        let s = parse(DBC_SOURCE).unwrap();
        assert_eq!(s.input, CanInput::Interface("can0".into()));
        let CanSignals::Dbc { path, names } = &s.signals else { panic!("{s:?}") };
        assert_eq!(path, Path::new("/etc/fm/hammer.dbc"));
        assert_eq!(names.sequence.as_deref(), Some("Seq"));
        assert_eq!(names.roles.len(), 3);
        assert_eq!(s.batch_s, DEFAULT_BATCH_S);
    }

    #[test]
    fn explicit_signals_give_the_same_mapping_as_the_dbc() {
        let s = parse(EXPLICIT).unwrap();
        assert_eq!(s.input, CanInput::Log(PathBuf::from("/etc/fm/cap.log")));
        assert_eq!(s.signals, CanSignals::Explicit(forgemon_mapping()));
        let cfg = s.resolve().unwrap();
        assert_eq!(cfg.timing.batch_samples, 100);
    }

    #[test]
    fn errors_name_the_key() {
        let e = |text: String| parse(&text).unwrap_err().to_string();
        assert!(e(DBC_SOURCE.replace("sample_rate_hz = 5000\n", "")).contains("'sources[1].sample_rate_hz'"));
        assert!(e(DBC_SOURCE.replace("interface = \"can0\"", "")).contains("'sources[1].interface'"));
        assert!(e(DBC_SOURCE.replace("sequence = ", "speed = ")).contains("'sources[1].signals.speed'"));
        assert!(e(EXPLICIT.replacen("id = 0x120", "id = 0x800", 2)).contains("'sources[1].can_signals[1].id'"));
        assert!(e(EXPLICIT.replacen("\"intel\"", "\"vax\"", 1)).contains("can_signals[1].byte_order"));
        assert!(e(EXPLICIT.replace("start_bit = 40", "start_bit = 48")).contains("can_signals[4]"));
        assert!(e(EXPLICIT.replace("role = \"disp_m\"", "role = \"load_N\"")).contains("role mapped twice"));
    }

    #[test]
    fn the_canfd_example_reads_a_block_of_eight_fd_samples() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
        let text = DBC_SOURCE.replace("hammer.dbc", "hammer-canfd.dbc").replace("5000", "50000");
        let table: toml::Table =
            format!("{text}\n").replace("[signals]", "fd = true\nsamples_per_frame = 8\n[signals]").parse().unwrap();
        let spec = parse_can_source("svc.toml", "sources[1]", &table, &dir).unwrap();
        assert_eq!((spec.fd, spec.samples_per_frame), (true, 8));
        let cfg = spec.resolve().unwrap();
        assert_eq!(cfg.mapping, crate::acquire::can::forgemon_fd_mapping());
        assert_eq!(cfg.mapping.samples_per_frame(), 8);
        // A block needs a DBC; a count out of range is named.
        let e = parse(&EXPLICIT.replace("batch_s = 0.02", "batch_s = 0.02\nsamples_per_frame = 8")).unwrap_err();
        assert!(e.to_string().contains("'sources[1].samples_per_frame'"), "{e}");
        let e = parse(&DBC_SOURCE.replace("[signals]", "samples_per_frame = 0\n[signals]")).unwrap_err();
        assert!(e.to_string().contains("'sources[1].samples_per_frame'"), "{e}");
        // Explicit signals may sit past byte 8 only in an FD frame.
        let far = EXPLICIT.replace("start_bit = 40", "start_bit = 100");
        assert!(parse(&far).unwrap_err().to_string().contains("can_signals[4]"));
        let fd = parse(&far.replace("batch_s = 0.02", "batch_s = 0.02\nfd = true")).unwrap();
        let CanSignals::Explicit(m) = &fd.signals else { panic!("{fd:?}") };
        assert!(m.is_fd());
    }

    #[test]
    fn a_missing_dbc_file_is_named_when_resolved() {
        let e = parse(DBC_SOURCE).unwrap().resolve().unwrap_err().to_string();
        assert!(e.starts_with("/etc/fm/hammer.dbc:"), "{e}");
    }
}
