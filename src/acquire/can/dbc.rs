//! Signals from a DBC file (`can-dbc`): the config names a DBC signal for each role
//! (`load_N`, `disp_m`, `acc_mps2`) and optionally the sequence counter, and this turns
//! them into a [`CanMapping`]. Pure: the caller reads the file and passes its text.
//!
//! A CAN FD block of `n` samples per frame ([`block_mapping_from_dbc`]) names each role
//! by its stem: `Load` reads the signals `Load_0` … `Load_{n-1}`, sample 0 the oldest
//! (see `config/hammer-canfd.dbc`). Multiplexed signals (`M`, `m0` …) are refused with
//! an error rather than read from frames whose multiplexor selects something else.

use can_dbc::{Dbc, MessageId, MultiplexIndicator, ValueType};

use crate::signal::sample::Role;

use super::CanError;
use super::signal::{ByteOrder, CanMapping, CanSignalSpec, FrameId, SignalLayout};

/// Which DBC signal plays which role. A name is `Signal` or, when several messages have
/// a signal of that name, `Message.Signal`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DbcNames {
    pub roles: Vec<(Role, String)>,
    pub sequence: Option<String>,
}

impl DbcNames {
    /// The names `fixtures/can/hammer.dbc` uses.
    pub fn forgemon() -> DbcNames {
        DbcNames {
            roles: vec![(Role::Load, "Load".into()), (Role::Disp, "Disp".into()), (Role::Acc, "Acc".into())],
            sequence: Some("Seq".into()),
        }
    }
}

/// Build the mapping from the DBC text `text` (read from `origin`, named in errors).
pub fn mapping_from_dbc(origin: &str, text: &str, names: &DbcNames) -> Result<CanMapping, CanError> {
    block_mapping_from_dbc(origin, text, names, 1, false)
}

/// Build a mapping of `samples_per_frame` samples per sample frame (module docs), of CAN
/// FD frames when `fd`. With one sample per frame the names are the signals' own.
pub fn block_mapping_from_dbc(
    origin: &str,
    text: &str,
    names: &DbcNames,
    samples_per_frame: usize,
    fd: bool,
) -> Result<CanMapping, CanError> {
    let dbc = Dbc::try_from(text)
        .map_err(|e| CanError::Dbc { origin: origin.to_string(), message: e.to_string().trim().replace('\n', " ") })?;
    let mut slots = Vec::with_capacity(samples_per_frame);
    for k in 0..samples_per_frame.max(1) {
        let mut signals = Vec::new();
        for (role, name) in &names.roles {
            let name = if samples_per_frame > 1 { format!("{name}_{k}") } else { name.clone() };
            signals.push(CanSignalSpec { role: *role, layout: find(origin, &dbc, &name, fd)? });
        }
        slots.push(signals);
    }
    let sequence = names.sequence.as_deref().map(|n| find(origin, &dbc, n, fd)).transpose()?;
    CanMapping::block(slots, sequence, fd)
        .map_err(|e| CanError::DbcSignal { origin: origin.to_string(), why: e.to_string() })
}

/// The layout of the signal called `name` (or `Message.Signal`), in a frame of the kind
/// `fd` says.
fn find(origin: &str, dbc: &Dbc, name: &str, fd: bool) -> Result<SignalLayout, CanError> {
    let err = |why: String| CanError::DbcSignal { origin: origin.to_string(), why };
    let (message, signal) = match name.split_once('.') {
        Some((m, s)) => (Some(m), s),
        None => (None, name),
    };
    let hits: Vec<_> = dbc
        .messages
        .iter()
        .filter(|m| message.is_none_or(|want| m.name == want))
        .flat_map(|m| m.signals.iter().filter(|s| s.name == signal).map(move |s| (m, s)))
        .collect();
    let (m, s) = match hits.as_slice() {
        [one] => *one,
        [] => return Err(err(format!("no signal named '{name}'"))),
        _ => return Err(err(format!("several messages have a signal '{name}'; write Message.Signal"))),
    };
    if s.multiplexer_indicator != MultiplexIndicator::Plain {
        return Err(err(format!(
            "signal '{name}' is multiplexed ({:?}); forgemon reads plain signals (a block of samples is Signal_0, Signal_1, ...)",
            s.multiplexer_indicator
        )));
    }
    if m.size > 8 && !fd {
        return Err(err(format!(
            "signal '{name}': message '{}' is {} bytes, a CAN FD frame; set fd = true",
            m.name, m.size
        )));
    }
    let frame = match m.id {
        MessageId::Standard(id) => FrameId::standard(id),
        MessageId::Extended(id) => FrameId::extended(id),
    };
    let narrow =
        |x: u64, what: &str| u16::try_from(x).map_err(|_| err(format!("signal '{name}': {what} {x} out of range")));
    let layout = SignalLayout {
        frame,
        start_bit: narrow(s.start_bit, "start bit")?,
        length: narrow(s.size, "size")?,
        byte_order: match s.byte_order {
            can_dbc::ByteOrder::LittleEndian => ByteOrder::LittleEndian,
            can_dbc::ByteOrder::BigEndian => ByteOrder::BigEndian,
        },
        signed: s.value_type == ValueType::Signed,
        factor: s.factor,
        offset: s.offset,
    };
    let max_len = if fd { super::signal::FD_MAX_LEN } else { super::signal::CLASSIC_MAX_LEN };
    layout.validate_within(name, max_len).map_err(|e| err(e.to_string()))?;
    Ok(layout)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DBC: &str = r#"VERSION ""

NS_ :

BS_:

BU_: DAQ

BO_ 288 ForgeSample: 8 DAQ
 SG_ Seq : 0|8@1+ (1,0) [0|255] "" Vector__XXX
 SG_ Load : 8|16@1- (100,0) [-3276800|3276700] "N" Vector__XXX
 SG_ Acc : 24|16@1- (0.25,0) [-8192|8191.75] "m/s2" Vector__XXX
 SG_ Disp : 40|24@1- (1E-006,0) [-8.388608|8.388607] "m" Vector__XXX

BO_ 2147487744 Other: 8 DAQ
 SG_ Load : 7|16@0- (0.5,-10) [0|0] "N" Vector__XXX

"#;

    #[test]
    fn the_forgemon_names_give_the_built_in_mapping() {
        let names = DbcNames {
            roles: vec![
                (Role::Load, "ForgeSample.Load".into()),
                (Role::Disp, "Disp".into()),
                (Role::Acc, "Acc".into()),
            ],
            sequence: Some("Seq".into()),
        };
        assert_eq!(mapping_from_dbc("t.dbc", DBC, &names).unwrap(), super::super::forgemon_mapping());
    }

    #[test]
    fn extended_ids_and_motorola_signals_are_read() {
        let names = DbcNames { roles: vec![(Role::Load, "Other.Load".into())], sequence: None };
        let m = mapping_from_dbc("t.dbc", DBC, &names).unwrap();
        let l = m.signals()[0].layout;
        assert_eq!(l.frame, FrameId::extended(0x1000)); // 2147487744 = 0x80001000
        assert_eq!((l.start_bit, l.length, l.byte_order, l.signed), (7, 16, ByteOrder::BigEndian, true));
        assert_eq!((l.factor, l.offset), (0.5, -10.0));
    }

    /// The committed CAN FD example describes the simulated DAQ's block (mod.rs docs).
    #[test]
    fn the_canfd_example_dbc_is_the_built_in_block() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/hammer-canfd.dbc");
        let text = std::fs::read_to_string(path).unwrap();
        let m = block_mapping_from_dbc(path, &text, &DbcNames::forgemon(), 8, true).unwrap();
        assert_eq!(m, super::super::forgemon_fd_mapping());
        // Without fd the 64-byte message is refused, naming the fix.
        let e = block_mapping_from_dbc(path, &text, &DbcNames::forgemon(), 8, false).unwrap_err().to_string();
        assert!(e.contains("set fd = true"), "{e}");
        // A block longer than the DBC's: the missing signal is named.
        let e = block_mapping_from_dbc(path, &text, &DbcNames::forgemon(), 9, true).unwrap_err().to_string();
        assert!(e.contains("no signal named 'Load_8'"), "{e}");
    }

    #[test]
    fn multiplexed_signals_are_refused() {
        let text = DBC.replace(" SG_ Seq : 0|8@1+", " SG_ Seq M : 0|8@1+").replace(" SG_ Acc : ", " SG_ Acc m1 : ");
        let names = DbcNames { roles: vec![(Role::Acc, "Acc".into())], sequence: None };
        let e = mapping_from_dbc("t.dbc", &text, &names).unwrap_err().to_string();
        assert!(e.contains("multiplexed"), "{e}");
    }

    #[test]
    fn bad_names_and_bad_files_name_the_file() {
        let one = |n: &str| DbcNames { roles: vec![(Role::Load, n.into())], sequence: None };
        let e = mapping_from_dbc("t.dbc", DBC, &one("Load")).unwrap_err().to_string();
        assert!(e.contains("t.dbc") && e.contains("Message.Signal"), "{e}");
        let e = mapping_from_dbc("t.dbc", DBC, &one("Nope")).unwrap_err().to_string();
        assert!(e.contains("no signal named 'Nope'"), "{e}");
        let e = mapping_from_dbc("bad.dbc", "BO_ x", &one("Load")).unwrap_err().to_string();
        assert!(e.starts_with("bad.dbc: not a valid DBC"), "{e}");
    }
}
