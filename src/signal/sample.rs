//! The one sample type (DESIGN.md §3): a batch of interleaved samples from one source, with
//! its device sequence number, device time and host receive time. Every source (serial,
//! CAN, Modbus, a capture file, a recording) produces these; everything after `acquire/`
//! consumes them and cannot tell where they came from.

use std::fmt;

/// What a channel measures (docs/interfaces.md §1, §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Role {
    /// Load at the machine's sensor, N, compressive positive.
    Load,
    /// Ram position from the encoder, m, down positive, arbitrary offset.
    Disp,
    /// Ram acceleration, m/s², down positive, gravity removed (free fall reads +9.81).
    Acc,
}

impl Role {
    /// The CSV column and config name of the role.
    pub fn column(&self) -> &'static str {
        match self {
            Role::Load => "load_N",
            Role::Disp => "disp_m",
            Role::Acc => "acc_mps2",
        }
    }

    pub fn from_column(name: &str) -> Option<Role> {
        match name {
            "load_N" => Some(Role::Load),
            "disp_m" => Some(Role::Disp),
            "acc_mps2" => Some(Role::Acc),
            _ => None,
        }
    }

    pub const ALL: [Role; 3] = [Role::Load, Role::Disp, Role::Acc];

    /// The channel's short name: in a blow's `channels` (docs/interfaces.md §5) and in
    /// `demo --without`.
    pub fn short(&self) -> &'static str {
        match self {
            Role::Load => "load",
            Role::Disp => "disp",
            Role::Acc => "acc",
        }
    }

    /// The role of a short name (`short`).
    pub fn from_short(name: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.short() == name)
    }
}

/// A set of the three channels: those a blow's estimate used (docs/interfaces.md §5
/// `channels`), those a source lacks. Serialised as the list of short names, in the order
/// load, acc, disp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Channels {
    load: bool,
    acc: bool,
    disp: bool,
}

impl Channels {
    pub const ALL: Channels = Channels { load: true, acc: true, disp: true };
    pub const NONE: Channels = Channels { load: false, acc: false, disp: false };

    pub fn has(&self, role: Role) -> bool {
        match role {
            Role::Load => self.load,
            Role::Acc => self.acc,
            Role::Disp => self.disp,
        }
    }

    /// The set with `role` in it (`on`) or out of it.
    pub fn with(mut self, role: Role, on: bool) -> Channels {
        match role {
            Role::Load => self.load = on,
            Role::Acc => self.acc = on,
            Role::Disp => self.disp = on,
        }
        self
    }

    pub fn without(self, role: Role) -> Channels {
        self.with(role, false)
    }

    /// The roles in the set, in the order load, acc, disp.
    pub fn roles(&self) -> impl Iterator<Item = Role> + '_ {
        [Role::Load, Role::Acc, Role::Disp].into_iter().filter(|r| self.has(*r))
    }

    /// The roles not in the set.
    pub fn missing(&self) -> impl Iterator<Item = Role> + '_ {
        [Role::Load, Role::Acc, Role::Disp].into_iter().filter(|r| !self.has(*r))
    }

    /// The roles of `self` that `other` lacks.
    pub fn missing_from(self, other: Channels) -> Channels {
        self.roles().fold(Channels::NONE, |c, r| c.with(r, !other.has(r)))
    }

    /// The short names of the roles in the set (`roles`).
    pub fn names(&self) -> Vec<&'static str> {
        self.roles().map(|r| r.short()).collect()
    }

    /// The set of the short names `names` (unknown names are `Err` with the name).
    pub fn parse<'a>(names: impl IntoIterator<Item = &'a str>) -> Result<Channels, &'a str> {
        names.into_iter().try_fold(Channels::NONE, |c, n| Role::from_short(n).map(|r| c.with(r, true)).ok_or(n))
    }

    /// The roles a batch of `roles` carries.
    pub fn of(roles: &[Role]) -> Channels {
        roles.iter().fold(Channels::NONE, |c, r| c.with(*r, true))
    }
}

impl Default for Channels {
    fn default() -> Self {
        Channels::ALL
    }
}

impl fmt::Display for Channels {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.names().join("+"))
    }
}

impl serde::Serialize for Channels {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.names())
    }
}

/// The column index of a role a batch does not carry (`Sample::from_row`): its value is NaN.
pub const ABSENT: usize = usize::MAX;

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.column())
    }
}

/// One sample with the three roles, in device time: what the segmenter cuts blows from.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    pub t_s: f64,
    pub load_n: f64,
    pub disp_m: f64,
    pub acc_mps2: f64,
    /// Not measured: interpolated across a hole in the stream (`Segmenter::hole`), so that
    /// a blow keeps one uniform time grid. The estimator decides whether a blow with such
    /// samples can still be trusted.
    pub filled: bool,
}

/// Two readings of one channel the same to rounding (1e-9 relative, at least 1e-9 absolute):
/// a stuck or dead channel repeats one value, where a live one shows at least its noise.
pub fn same_reading(a: f64, b: f64) -> bool {
    (b - a).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

impl Sample {
    /// A measured sample at `t_s` from one interleaved row of a batch whose load,
    /// displacement and acceleration are the channels `cols`; a channel the batch does not
    /// carry (`ABSENT`) reads NaN.
    pub fn from_row(t_s: f64, row: &[f64], cols: [usize; 3]) -> Sample {
        let at = |c: usize| row.get(c).copied().unwrap_or(f64::NAN);
        Sample { t_s, load_n: at(cols[0]), disp_m: at(cols[1]), acc_mps2: at(cols[2]), filled: false }
    }
}

/// Device time, s, of sample `i` of a batch starting at `device_time_ns`, `period_ns` apart
/// (`SampleBatch::time_s`, and a copy of the batch's values that keeps both).
pub fn sample_time_s(device_time_ns: i64, period_ns: f64, i: usize) -> f64 {
    (device_time_ns as f64 + period_ns * i as f64) * 1e-9
}

/// A block of samples from one source: `values` holds `len()` samples of `roles.len()`
/// channels, interleaved (sample 0 of every channel, then sample 1, ...), in physical units.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleBatch {
    /// Which source produced it (a config name, or the file it was read from).
    pub source: String,
    /// Device sequence number of the batch (frame counter), +1 per batch.
    pub seq: u64,
    /// Device time of the first sample, ns, device clock (arbitrary origin).
    pub device_time_ns: i64,
    /// Host time at which the batch was received, ns (for files: the device time mapped).
    pub host_time_ns: i64,
    /// Sample period, ns.
    pub period_ns: f64,
    /// The channels, in the order they are interleaved.
    pub roles: Vec<Role>,
    pub values: Vec<f64>,
}

impl SampleBatch {
    /// Number of samples per channel.
    pub fn len(&self) -> usize {
        if self.roles.is_empty() { 0 } else { self.values.len() / self.roles.len() }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Device time of sample `i`, s.
    pub fn time_s(&self, i: usize) -> f64 {
        sample_time_s(self.device_time_ns, self.period_ns, i)
    }

    /// Index of a role's channel.
    pub fn channel(&self, role: Role) -> Option<usize> {
        self.roles.iter().position(|r| *r == role)
    }
}

/// Samples lost or dropped (topic `/gaps`).
#[derive(Debug, Clone, PartialEq)]
pub struct Gap {
    pub source: String,
    /// Device time of the gap, s.
    pub t_s: f64,
    pub samples_lost: u64,
    /// Why: "sequence_jump", "crc", "overflow", "backpressure", ...
    pub reason: String,
}

/// Counters every transport keeps (they go into `Status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    pub samples: u64,
    pub frames: u64,
    /// Events dropped because the pipeline's channel was full.
    pub drops: u64,
    /// Sequence gaps (or missing frames) seen.
    pub gaps: u64,
    pub crc_errors: u64,
    /// Frames or lines that did not decode (garbage, bad lengths, malformed text).
    pub decode_errors: u64,
    pub reconnects: u64,
}

impl Counters {
    /// The status message of source `source` in state `state`.
    pub fn status(&self, source: &str, state: &str, detail: impl Into<String>) -> Status {
        Status {
            source: source.to_string(),
            state: state.to_string(),
            samples: self.samples,
            frames: self.frames,
            drops: self.drops,
            gaps: self.gaps,
            crc_errors: self.crc_errors,
            decode_errors: self.decode_errors,
            reconnects: self.reconnects,
            detail: detail.into(),
        }
    }
}

/// A source's state and counters since it started (topic `/status`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Status {
    pub source: String,
    /// "connected", "reconnecting", "stopped", ...
    pub state: String,
    pub samples: u64,
    pub frames: u64,
    pub drops: u64,
    pub gaps: u64,
    pub crc_errors: u64,
    pub decode_errors: u64,
    pub reconnects: u64,
    /// Free text: last error, port name, ...
    pub detail: String,
}
