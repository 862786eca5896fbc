//! The limits of the service's network servers (issue 39): how many connections each holds
//! at once, counted when a connection is accepted, and how long a connection may take to
//! send its request head or handshake and may stay without a byte moving. A client that
//! opens connections and sends nothing, or trickles, can hold a server's descriptors for
//! these times at most, and never more of them than its cap; the sum of the caps sizes the
//! systemd unit's `LimitNOFILE` (`tests/systemd_unit.rs` checks it).

use std::time::Duration;

use super::ConfigError;
use super::document::Document;
use super::limits::{HANDSHAKE_TIMEOUT_S, IDLE_TIMEOUT_S, SERVER_CONNECTIONS};

/// `[http] max_connections`: below systemd's default of 1 024 descriptors with room for the
/// other servers, the recording and the sources.
pub const DEFAULT_HTTP_MAX_CONNECTIONS: u64 = 512;
/// `[http] header_timeout_s`: a request's head is a few hundred bytes.
pub const DEFAULT_HTTP_HEADER_TIMEOUT_S: f64 = 10.0;
/// `[http] idle_timeout_s`: four times the dashboard's event-stream keep-alive (15 s).
pub const DEFAULT_HTTP_IDLE_TIMEOUT_S: f64 = 60.0;
/// `[foxglove] max_clients`.
pub const DEFAULT_FOXGLOVE_MAX_CLIENTS: u64 = 16;
/// `[foxglove] handshake_timeout_s`.
pub const DEFAULT_FOXGLOVE_HANDSHAKE_TIMEOUT_S: f64 = 10.0;
/// `[foxglove] idle_timeout_s`: the server pings every third of it; Foxglove answers.
pub const DEFAULT_FOXGLOVE_IDLE_TIMEOUT_S: f64 = 60.0;

/// `[plc_server] idle_timeout_s`: a PLC polls every cycle (tens to hundreds of ms), so a
/// connection without a request for 30 s is gone or hostile.
pub const DEFAULT_PLC_IDLE_TIMEOUT_S: f64 = 30.0;
/// `[plc_server] max_connections`: a press has one PLC, a line a few HMIs beside it.
pub const DEFAULT_PLC_MAX_CONNECTIONS: u64 = 16;

/// Each server's connection cap at its default, by its key: what the descriptor limit of
/// the systemd unit must hold beside the service's own files.
pub const DEFAULT_CONNECTION_CAPS: [(&str, u64); 4] = [
    ("http.max_connections", DEFAULT_HTTP_MAX_CONNECTIONS),
    ("foxglove.max_clients", DEFAULT_FOXGLOVE_MAX_CLIENTS),
    ("plc_server.max_connections", DEFAULT_PLC_MAX_CONNECTIONS),
    ("opcua.max_connections", super::opcua::DEFAULT_MAX_CONNECTIONS),
];

/// The HTTP server's limits (`[http]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HttpLimits {
    /// Connections held at once, counted at accept. At the cap a newcomer sheds the oldest
    /// connection that has not yet passed the token; when every one has, it is refused.
    pub max_connections: usize,
    /// From a connection's opening, or the end of its previous response, to the end of its
    /// request head.
    pub header_timeout: Duration,
    /// A connection on which no byte moves either way this long is closed.
    pub idle_timeout: Duration,
}

impl Default for HttpLimits {
    fn default() -> Self {
        HttpLimits {
            max_connections: DEFAULT_HTTP_MAX_CONNECTIONS as usize,
            header_timeout: Duration::from_secs_f64(DEFAULT_HTTP_HEADER_TIMEOUT_S),
            idle_timeout: Duration::from_secs_f64(DEFAULT_HTTP_IDLE_TIMEOUT_S),
        }
    }
}

/// The Foxglove WebSocket server's limits (`[foxglove]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FoxgloveLimits {
    /// Connections held at once, handshaking or connected, counted at accept.
    pub max_clients: usize,
    /// From a connection's opening to the end of its WebSocket handshake.
    pub handshake_timeout: Duration,
    /// A client from which no frame (a pong included) comes this long is closed.
    pub idle_timeout: Duration,
}

impl Default for FoxgloveLimits {
    fn default() -> Self {
        FoxgloveLimits {
            max_clients: DEFAULT_FOXGLOVE_MAX_CLIENTS as usize,
            handshake_timeout: Duration::from_secs_f64(DEFAULT_FOXGLOVE_HANDSHAKE_TIMEOUT_S),
            idle_timeout: Duration::from_secs_f64(DEFAULT_FOXGLOVE_IDLE_TIMEOUT_S),
        }
    }
}

/// A cap, a first timeout and an idle timeout as a table gives them (each optional).
pub(super) struct RawLimits {
    pub cap: Option<u64>,
    pub first_s: Option<f64>,
    pub idle_s: Option<f64>,
}

/// `[http]`'s limits over the defaults, each within its range.
pub(super) fn http_limits(doc: &Document<'_>, raw: &RawLimits) -> Result<HttpLimits, ConfigError> {
    let c = checked(doc, "http", ["max_connections", "header_timeout_s", "idle_timeout_s"], raw)?;
    let d = HttpLimits::default();
    Ok(HttpLimits {
        max_connections: c.cap.unwrap_or(d.max_connections),
        header_timeout: c.first.unwrap_or(d.header_timeout),
        idle_timeout: c.idle.unwrap_or(d.idle_timeout),
    })
}

/// `[foxglove]`'s limits over the defaults, each within its range.
pub(super) fn foxglove_limits(doc: &Document<'_>, raw: &RawLimits) -> Result<FoxgloveLimits, ConfigError> {
    let keys = ["max_clients", "handshake_timeout_s", "idle_timeout_s"];
    let c = checked(doc, "foxglove", keys, raw)?;
    let d = FoxgloveLimits::default();
    Ok(FoxgloveLimits {
        max_clients: c.cap.unwrap_or(d.max_clients),
        handshake_timeout: c.first.unwrap_or(d.handshake_timeout),
        idle_timeout: c.idle.unwrap_or(d.idle_timeout),
    })
}

/// The values a table gives, checked.
struct Checked {
    cap: Option<usize>,
    first: Option<Duration>,
    idle: Option<Duration>,
}

/// The values given, checked against their ranges; errors name `table.key`.
fn checked(doc: &Document<'_>, table: &str, keys: [&str; 3], raw: &RawLimits) -> Result<Checked, ConfigError> {
    let key = |k: &str| format!("{table}.{k}");
    let cap = raw.cap.map(|c| doc.in_whole_range(&key(keys[0]), c, &SERVER_CONNECTIONS)).transpose()?;
    let first = raw.first_s.map(|s| doc.in_range(&key(keys[1]), s, &HANDSHAKE_TIMEOUT_S)).transpose()?;
    let idle = raw.idle_s.map(|s| doc.in_range(&key(keys[2]), s, &IDLE_TIMEOUT_S)).transpose()?;
    Ok(Checked {
        cap: cap.map(|c| c as usize),
        first: first.map(Duration::from_secs_f64),
        idle: idle.map(Duration::from_secs_f64),
    })
}
