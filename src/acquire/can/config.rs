//! A CAN source's configuration, from the service config's `[[sources]]` table with
//! `kind = "can"` in two steps: `config` reads and validates the keys into a
//! [`CanSourceSpec`] (every error names the key), and [`CanSourceSpec::resolve`] reads the
//! DBC file, if any, into the mapping. Both run before anything is opened.
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

use std::path::PathBuf;

use super::CanError;
use super::dbc::{DbcNames, block_mapping_from_dbc};
use super::decoder::CanTiming;
use super::live::CanSourceConfig;
use super::signal::CanMapping;

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
