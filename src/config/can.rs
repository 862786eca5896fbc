//! A `[[sources]]` table of `kind = "can"`, read from its raw serde struct into
//! `acquire::can::CanSourceSpec`: every key named, unknown keys refused with a suggestion,
//! and every error placed at its line. Its DBC file is read later, by
//! `CanSourceSpec::resolve`. The keys are documented in `acquire::can::config`.

use std::path::Path;

use serde::Deserialize;

use super::ConfigError;
use super::document::Document;
use crate::acquire::can::dbc::DbcNames;
use crate::acquire::can::signal::{
    ByteOrder, CLASSIC_MAX_LEN, CanMapping, CanSignalSpec, FD_MAX_LEN, FrameId, SignalLayout,
};
use crate::acquire::can::{CanInput, CanSignals, CanSourceSpec, MAX_SAMPLES_PER_FRAME};
use crate::signal::capture::DEFAULT_BATCH_S;
use crate::signal::sample::Role;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCan {
    name: String,
    #[allow(dead_code)]
    kind: String,
    interface: Option<String>,
    log: Option<String>,
    sample_rate_hz: f64,
    batch_s: Option<f64>,
    fd: Option<bool>,
    samples_per_frame: Option<i64>,
    dbc: Option<String>,
    signals: Option<RawSignalNames>,
    can_signals: Option<Vec<RawCanSignal>>,
}

/// `[sources.signals]`: role = DBC signal name.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSignalNames {
    #[serde(rename = "load_N")]
    load_n: Option<String>,
    disp_m: Option<String>,
    acc_mps2: Option<String>,
    sequence: Option<String>,
}

/// `[[sources.can_signals]]`: one signal's place in its frame.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCanSignal {
    role: String,
    id: i64,
    extended: Option<bool>,
    start_bit: i64,
    length: i64,
    byte_order: RawByteOrder,
    signed: Option<bool>,
    factor: Option<f64>,
    offset: Option<f64>,
}

#[derive(Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawByteOrder {
    Intel,
    Motorola,
}

/// The CAN source `value` at the dotted key `prefix` of `doc`, whose directory is `base`.
pub(super) fn can_source(
    doc: &Document<'_>,
    prefix: &str,
    value: toml::Spanned<toml::de::DeValue<'_>>,
    base: &Path,
) -> Result<CanSourceSpec, ConfigError> {
    let raw: RawCan = doc.read_value(value, prefix)?;
    let key = |k: &str| format!("{prefix}.{k}");
    let input = match (raw.interface, raw.log) {
        (Some(i), None) => CanInput::Interface(i),
        (None, Some(l)) => CanInput::Log(base.join(l)),
        (Some(_), Some(_)) => return Err(doc.invalid(&key("log"), "give either 'interface' or 'log', not both")),
        (None, None) => return Err(doc.missing(&key("interface"))),
    };
    let positive = |k: &str, x: f64| {
        if x.is_finite() && x > 0.0 {
            Ok(x)
        } else {
            Err(doc.invalid(&key(k), format!("must be finite and > 0, got {x}")))
        }
    };
    let sample_rate_hz = positive("sample_rate_hz", raw.sample_rate_hz)?;
    let batch_s = raw.batch_s.map_or(Ok(DEFAULT_BATCH_S), |b| positive("batch_s", b))?;
    let fd = raw.fd.unwrap_or(false);
    let samples_per_frame = match raw.samples_per_frame {
        None => 1,
        Some(n) if (1..=MAX_SAMPLES_PER_FRAME).contains(&n) => n as usize,
        Some(n) => {
            return Err(doc.invalid(&key("samples_per_frame"), format!("{n} is not 1..={MAX_SAMPLES_PER_FRAME}")));
        }
    };
    if samples_per_frame > 1 && raw.dbc.is_none() {
        return Err(
            doc.invalid(&key("samples_per_frame"), "a block of samples per frame is read from a DBC file ('dbc')")
        );
    }
    let signals = match raw.dbc {
        Some(dbc) => {
            let Some(s) = raw.signals else { return Err(doc.missing(&key("signals"))) };
            let roles: Vec<(Role, String)> = [(Role::Load, s.load_n), (Role::Disp, s.disp_m), (Role::Acc, s.acc_mps2)]
                .into_iter()
                .filter_map(|(r, n)| Some((r, n?)))
                .collect();
            if roles.is_empty() {
                return Err(doc.invalid(&key("signals.load_N"), "no role is mapped"));
            }
            CanSignals::Dbc { path: base.join(dbc), names: DbcNames { roles, sequence: s.sequence } }
        }
        None => {
            let Some(list) = raw.can_signals else { return Err(doc.missing(&key("dbc"))) };
            CanSignals::Explicit(explicit(doc, prefix, list, fd)?)
        }
    };
    Ok(CanSourceSpec { name: raw.name, input, sample_rate_hz, batch_s, fd, samples_per_frame, signals })
}

/// The mapping of `[[sources.can_signals]]`.
fn explicit(doc: &Document<'_>, prefix: &str, list: Vec<RawCanSignal>, fd: bool) -> Result<CanMapping, ConfigError> {
    let max_len = if fd { FD_MAX_LEN } else { CLASSIC_MAX_LEN };
    let mut roles = Vec::new();
    let mut sequence = None;
    for (i, c) in list.into_iter().enumerate() {
        let at = |k: &str| format!("{prefix}.can_signals[{}].{k}", i + 1);
        let extended = c.extended.unwrap_or(false);
        let frame = FrameId { id: u32::try_from(c.id).unwrap_or(u32::MAX), extended };
        if !frame.is_valid() {
            let bits = if extended { "29-bit" } else { "11-bit" };
            return Err(doc.invalid(&at("id"), format!("{:#x} does not fit a {bits} identifier", c.id)));
        }
        let bits = |k: &str, v: i64| {
            u16::try_from(v)
                .ok()
                .filter(|&b| (b as usize) < 8 * max_len || k == "length")
                .ok_or_else(|| doc.invalid(&at(k), format!("{v} out of range")))
        };
        let finite = |k: &str, x: Option<f64>, default: f64| match x {
            Some(x) if !x.is_finite() => Err(doc.invalid(&at(k), format!("must be finite, got {x}"))),
            x => Ok(x.unwrap_or(default)),
        };
        let layout = SignalLayout {
            frame,
            start_bit: bits("start_bit", c.start_bit)?,
            length: bits("length", c.length)?,
            byte_order: match c.byte_order {
                RawByteOrder::Intel => ByteOrder::LittleEndian,
                RawByteOrder::Motorola => ByteOrder::BigEndian,
            },
            signed: c.signed.unwrap_or(false),
            factor: finite("factor", c.factor, 1.0)?,
            offset: finite("offset", c.offset, 0.0)?,
        };
        layout.validate_within(&c.role, max_len).map_err(|e| doc.invalid(&at("length"), e.to_string()))?;
        match Role::from_column(&c.role) {
            Some(r) => roles.push(CanSignalSpec { role: r, layout }),
            None if c.role == "sequence" => sequence = Some(layout),
            None => {
                return Err(
                    doc.invalid(&at("role"), format!("'{}' is not load_N, disp_m, acc_mps2 or sequence", c.role))
                );
            }
        }
    }
    CanMapping::block(vec![roles], sequence, fd)
        .map_err(|e| doc.invalid(&format!("{prefix}.can_signals"), e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquire::can::{forgemon_fd_mapping, forgemon_mapping};
    use std::path::PathBuf;

    /// `text` as the first `[[sources]]` table of a file `svc.toml` in `base`.
    fn parse_in(text: &str, base: &Path) -> Result<CanSourceSpec, ConfigError> {
        let file = format!(
            "[[sources]]\n{}",
            text.replace("[signals]", "[sources.signals]").replace("[[can_signals]]", "[[sources.can_signals]]")
        );
        let doc = Document::parse("svc.toml", &file)?;
        let value = doc.get("sources[1]").expect("the table").clone();
        can_source(&doc, "sources[1]", value, base)
    }

    fn parse(text: &str) -> Result<CanSourceSpec, ConfigError> {
        parse_in(text, Path::new("/etc/fm"))
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
    fn errors_name_the_key_and_its_line() {
        let e = |text: String| parse(&text).unwrap_err().to_string();
        assert!(e(DBC_SOURCE.replace("sample_rate_hz = 5000\n", "")).contains("'sources[1].sample_rate_hz'"));
        assert!(e(DBC_SOURCE.replace("interface = \"can0\"", "")).contains("'sources[1].interface'"));
        let unknown = e(DBC_SOURCE.replace("sequence = ", "speed = "));
        assert!(unknown.contains("speed") && unknown.contains("sources[1].signals"), "{unknown}");
        assert!(e(EXPLICIT.replacen("id = 0x120", "id = 0x800", 2)).contains("'sources[1].can_signals[1].id'"));
        assert!(e(EXPLICIT.replacen("\"intel\"", "\"vax\"", 1)).contains("can_signals[1].byte_order"));
        assert!(e(EXPLICIT.replace("start_bit = 40", "start_bit = 48")).contains("can_signals[4]"));
        assert!(e(EXPLICIT.replace("role = \"disp_m\"", "role = \"load_N\"")).contains("role mapped twice"));
        let line = e(EXPLICIT.replace("sample_rate_hz = 5000", "sample_rate_hz = -1"));
        assert!(line.contains("svc.toml:6"), "{line}");
    }

    #[test]
    fn the_canfd_example_reads_a_block_of_eight_fd_samples() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
        let text = DBC_SOURCE.replace("hammer.dbc", "hammer-canfd.dbc").replace("5000", "50000");
        let spec = parse_in(&text.replace("[signals]", "fd = true\nsamples_per_frame = 8\n[signals]"), &dir).unwrap();
        assert_eq!((spec.fd, spec.samples_per_frame), (true, 8));
        let cfg = spec.resolve().unwrap();
        assert_eq!(cfg.mapping, forgemon_fd_mapping());
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
