//! The `[opcua]` table of the service configuration: where the OPC UA Metal Forming server
//! (`daemon/opcua`) listens and who may open a session. Anonymous sessions are served on a
//! loopback address only; any other address needs `user` and `password_file`, and then
//! the server offers only a signed and encrypted endpoint (Basic256Sha256) whose self-signed
//! certificate it keeps under `pki_dir`. The password itself is read when the service
//! starts, not here (this module does no IO). `hello_timeout_s`, `max_connections` and
//! `max_sessions` bound what unauthenticated clients can hold.

use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::ConfigError;
use super::document::Document;
use super::limits::WholeLimits;

/// The URL scheme of OPC UA over TCP (OPC 10000-6 §7.2).
pub const OPC_TCP_SCHEME: &str = "opc.tcp://";
/// Default PKI directory (the server's own certificate and key, relative to the
/// configuration file's directory), used only when sessions need a user.
pub const DEFAULT_PKI_DIR: &str = "opcua-pki";
/// `hello_timeout_s`: a connection that has not sent its HEL message after this long is
/// closed (async-opcua's `tcp_config.hello_timeout`; it also bounds the time to open the
/// secure channel after HEL).
pub const DEFAULT_HELLO_TIMEOUT_S: u64 = 5;
/// `max_sessions`: sessions open at once (async-opcua's `limits.max_sessions`); a plant
/// has a few clients (an MES, a SCADA, an engineer's browser).
pub const DEFAULT_MAX_SESSIONS: u64 = 10;
/// `max_connections`: connections held at once, counted at accept (`daemon::slots`): at
/// the cap a newcomer takes the place of the oldest connection without an activated
/// session. Room for `max_sessions` clients and as many reconnecting.
pub const DEFAULT_MAX_CONNECTIONS: u64 = 2 * DEFAULT_MAX_SESSIONS;
/// `hello_timeout_s` from 1 s to 10 min.
pub const HELLO_TIMEOUT_S: WholeLimits = WholeLimits { min: 1, max: 600, unit: "s" };
/// `max_sessions` from 1 to 1000.
pub const MAX_SESSIONS: WholeLimits = WholeLimits { min: 1, max: 1000, unit: "sessions" };
/// `max_connections` from 1 to 1000.
pub const MAX_CONNECTIONS: WholeLimits = WholeLimits { min: 1, max: 1000, unit: "connections" };

/// `[opcua]` as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOpcua {
    listen: String,
    user: Option<String>,
    password_file: Option<String>,
    pki_dir: Option<String>,
    hello_timeout_s: Option<u64>,
    max_sessions: Option<u64>,
    max_connections: Option<u64>,
    nodesets_dir: Option<String>,
}

/// Who may open a session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OpcuaAccess {
    /// Anonymous sessions, on a loopback address only.
    Anonymous,
    /// One user with a password (read from `password_file` at start), over a signed and
    /// encrypted channel; anonymous sessions are refused.
    User { name: String, password_file: PathBuf, pki_dir: PathBuf },
}

/// The validated `[opcua]` table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpcuaConfig {
    /// The endpoint URL as configured (`opc.tcp://127.0.0.1:4840`).
    pub url: String,
    /// The address it names.
    pub listen: SocketAddr,
    pub access: OpcuaAccess,
    /// `hello_timeout_s`: a connection without HEL is closed after this long.
    pub hello_timeout_s: u64,
    /// `max_sessions`: sessions open at once.
    pub max_sessions: u64,
    /// `max_connections`: connections held at once, counted at accept.
    pub max_connections: u64,
    /// `nodesets_dir`: the OPC Foundation's companion NodeSet2 files (Machinery, Machine
    /// Tools, Metal Forming and what they require); when set, the machine's nodes are
    /// instances of the companion types (`daemon/opcua/nodesets.rs`). Read at start.
    pub nodesets_dir: Option<PathBuf>,
}

impl OpcuaConfig {
    /// Anonymous access on `url`, which must name a loopback address (the demo's `--opcua`).
    pub fn anonymous(url: &str) -> Result<Self, String> {
        let listen = parse_url(url)?;
        if !listen.ip().is_loopback() {
            return Err(format!("{url}: anonymous OPC UA sessions are served on loopback only"));
        }
        Ok(OpcuaConfig {
            url: url.to_string(),
            listen,
            access: OpcuaAccess::Anonymous,
            hello_timeout_s: DEFAULT_HELLO_TIMEOUT_S,
            max_sessions: DEFAULT_MAX_SESSIONS,
            max_connections: DEFAULT_MAX_CONNECTIONS,
            nodesets_dir: None,
        })
    }
}

/// `opc.tcp://HOST:PORT[/]` with HOST an IP address (`[::1]` for IPv6) or `localhost`, as
/// the address to listen on.
pub fn parse_url(url: &str) -> Result<SocketAddr, String> {
    let bad = |why: &str| format!("'{url}' is not an opc.tcp://ADDRESS:PORT URL: {why}");
    let rest = url.strip_prefix(OPC_TCP_SCHEME).ok_or_else(|| bad("it must start with opc.tcp://"))?;
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.contains('/') {
        return Err(bad("the server serves the root path only"));
    }
    let (host, port) = rest.rsplit_once(':').ok_or_else(|| bad("no port"))?;
    let port: u16 = port.parse().map_err(|_| bad("the port must be 0..=65535"))?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let ip: IpAddr = if host.eq_ignore_ascii_case("localhost") {
        IpAddr::from([127, 0, 0, 1])
    } else {
        host.parse().map_err(|_| bad("the host must be an IP address or localhost"))?
    };
    Ok(SocketAddr::new(ip, port))
}

/// `[opcua]` checked: the URL, and a user with a password file wherever the address is not
/// loopback. Paths are taken from `base`, the configuration file's directory.
pub(super) fn parse_opcua(
    doc: &Document<'_>,
    raw: Option<&RawOpcua>,
    base: &Path,
) -> Result<Option<OpcuaConfig>, ConfigError> {
    let Some(raw) = raw else { return Ok(None) };
    let listen = parse_url(&raw.listen).map_err(|why| doc.invalid("opcua.listen", why))?;
    let path = |s: &str| {
        let p = PathBuf::from(s);
        if p.is_absolute() { p } else { base.join(p) }
    };
    let access = match (&raw.user, &raw.password_file) {
        (None, None) if listen.ip().is_loopback() => OpcuaAccess::Anonymous,
        (None, None) => {
            return Err(doc.invalid(
                "opcua.user",
                format!(
                    "is required when opcua.listen ({listen}) is not loopback: anonymous sessions are served on \
                     loopback only (set user and password_file)"
                ),
            ));
        }
        (Some(_), None) => return Err(doc.missing("opcua.password_file")),
        (None, Some(_)) => return Err(doc.missing("opcua.user")),
        (Some(name), Some(_)) if name.trim().is_empty() => {
            return Err(doc.invalid("opcua.user", "must not be empty"));
        }
        (Some(name), Some(file)) => OpcuaAccess::User {
            name: name.clone(),
            password_file: path(file),
            pki_dir: path(raw.pki_dir.as_deref().unwrap_or(DEFAULT_PKI_DIR)),
        },
    };
    if raw.pki_dir.is_some() && access == OpcuaAccess::Anonymous {
        return Err(doc.invalid("opcua.pki_dir", "is used only with user and password_file"));
    }
    let hello_timeout_s = match raw.hello_timeout_s {
        Some(s) => doc.in_whole_range("opcua.hello_timeout_s", s, &HELLO_TIMEOUT_S)?,
        None => DEFAULT_HELLO_TIMEOUT_S,
    };
    let max_sessions = match raw.max_sessions {
        Some(n) => doc.in_whole_range("opcua.max_sessions", n, &MAX_SESSIONS)?,
        None => DEFAULT_MAX_SESSIONS,
    };
    let max_connections = match raw.max_connections {
        Some(n) => doc.in_whole_range("opcua.max_connections", n, &MAX_CONNECTIONS)?,
        None => DEFAULT_MAX_CONNECTIONS,
    };
    if raw.nodesets_dir.as_deref().is_some_and(|d| d.trim().is_empty()) {
        return Err(doc.invalid("opcua.nodesets_dir", "must not be empty (leave it out to serve without them)"));
    }
    let nodesets_dir = raw.nodesets_dir.as_deref().map(path);
    Ok(Some(OpcuaConfig {
        url: raw.listen.clone(),
        listen,
        access,
        hello_timeout_s,
        max_sessions,
        max_connections,
        nodesets_dir,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `[opcua]` alone parsed as the service file would parse it.
    fn parse(table: &str) -> Result<Option<OpcuaConfig>, ConfigError> {
        #[derive(Deserialize)]
        struct Wrapper {
            opcua: Option<RawOpcua>,
        }
        let doc = Document::parse("service.toml", table)?;
        let w: Wrapper = doc.read()?;
        parse_opcua(&doc, w.opcua.as_ref(), Path::new("/etc/forgemon"))
    }

    fn err(table: &str) -> String {
        parse(table).err().map(|e| e.to_string()).unwrap_or_else(|| panic!("accepted: {table}"))
    }

    #[test]
    fn urls_name_an_address_and_a_port() {
        assert_eq!(parse_url("opc.tcp://127.0.0.1:4840"), Ok("127.0.0.1:4840".parse().unwrap()));
        assert_eq!(parse_url("opc.tcp://localhost:4840/"), Ok("127.0.0.1:4840".parse().unwrap()));
        assert_eq!(parse_url("opc.tcp://[::1]:4841"), Ok("[::1]:4841".parse().unwrap()));
        for bad in [
            "http://127.0.0.1:4840",
            "opc.tcp://127.0.0.1",
            "opc.tcp://plant-a:4840",
            "opc.tcp://127.0.0.1:99999",
            "opc.tcp://127.0.0.1:4840/x",
        ] {
            assert!(parse_url(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn anonymous_is_served_on_loopback_only() {
        let c = parse("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\n").unwrap().unwrap();
        assert_eq!(c.access, OpcuaAccess::Anonymous);
        assert_eq!(c.listen.port(), 4840);
        let e = err("[opcua]\nlisten = \"opc.tcp://0.0.0.0:4840\"\n");
        assert!(e.contains("service.toml:1:") && e.contains("'opcua.user'") && e.contains("not loopback"), "{e}");
        assert!(OpcuaConfig::anonymous("opc.tcp://192.0.2.1:4840").is_err());
        assert!(OpcuaConfig::anonymous("opc.tcp://127.0.0.1:0").is_ok());
    }

    #[test]
    fn a_user_needs_a_password_file_and_gets_a_pki_dir() {
        let c = parse("[opcua]\nlisten = \"opc.tcp://0.0.0.0:4840\"\nuser = \"mes\"\npassword_file = \"opcua.pass\"\n")
            .unwrap()
            .unwrap();
        assert_eq!(
            c.access,
            OpcuaAccess::User {
                name: "mes".into(),
                password_file: PathBuf::from("/etc/forgemon/opcua.pass"),
                pki_dir: PathBuf::from("/etc/forgemon/opcua-pki"),
            }
        );
        let e = err("[opcua]\nlisten = \"opc.tcp://0.0.0.0:4840\"\nuser = \"mes\"\n");
        assert!(e.contains("missing key 'opcua.password_file'"), "{e}");
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\npassword_file = \"p\"\n");
        assert!(e.contains("missing key 'opcua.user'"), "{e}");
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\npki_dir = \"p\"\n");
        assert!(e.contains("'opcua.pki_dir'"), "{e}");
    }

    #[test]
    fn the_limits_have_defaults_and_ranges() {
        let c = parse("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\n").unwrap().unwrap();
        assert_eq!((c.hello_timeout_s, c.max_sessions), (5, 10));
        let c = parse("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nhello_timeout_s = 2\nmax_sessions = 3\n")
            .unwrap()
            .unwrap();
        assert_eq!((c.hello_timeout_s, c.max_sessions), (2, 3));
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nhello_timeout_s = 0\n");
        assert!(e.contains("'opcua.hello_timeout_s'"), "{e}");
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nmax_sessions = 0\n");
        assert!(e.contains("'opcua.max_sessions'"), "{e}");
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nmax_connections = 1001\n");
        assert!(e.contains("'opcua.max_connections'"), "{e}");
    }

    #[test]
    fn bad_keys_and_urls_name_their_key() {
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nusr = \"x\"\n");
        assert!(e.contains("unknown key 'usr'") && e.contains("did you mean 'user'"), "{e}");
        let e = err("[opcua]\nlisten = \"tcp://127.0.0.1:4840\"\n");
        assert!(e.contains("key 'opcua.listen'") && e.contains("opc.tcp://"), "{e}");
    }

    #[test]
    fn a_nodesets_dir_is_taken_from_the_configuration_files_directory() {
        let c = parse("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\n").unwrap().unwrap();
        assert_eq!(c.nodesets_dir, None);
        let c =
            parse("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nnodesets_dir = \"ua-nodesets\"\n").unwrap().unwrap();
        assert_eq!(c.nodesets_dir.as_deref(), Some(Path::new("/etc/forgemon/ua-nodesets")));
        let e = err("[opcua]\nlisten = \"opc.tcp://127.0.0.1:4840\"\nnodesets_dir = \" \"\n");
        assert!(e.contains("'opcua.nodesets_dir'") && e.contains("empty"), "{e}");
    }
}
