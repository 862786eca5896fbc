//! The service file's `[uplink.mqtt]` table (docs/interfaces.md §10): the MQTT broker the service
//! publishes Sparkplug B to, the node's Sparkplug identity, and the limits of the on-disk
//! store-and-forward queue kept while the broker is unreachable (`daemon/sparkplug`).
//! Raw serde struct that denies unknown keys, then validated once into [`MqttUplink`]; every
//! error names the file, line and dotted key.

use serde::Deserialize;

use super::ConfigError;
use super::document::Document;
use super::limits::WholeLimits;

/// MQTT's registered port for plain TCP.
pub const DEFAULT_MQTT_PORT: u16 = 1883;
/// Default Sparkplug group: one plant's forge shop.
pub const DEFAULT_GROUP_ID: &str = "forge";
/// Default edge node: the service.
pub const DEFAULT_EDGE_NODE_ID: &str = "forgemon";
/// Default device: the machine the service watches.
pub const DEFAULT_DEVICE_ID: &str = "machine";
/// Default queue size: 64 MiB, about 60 000 blows (a blow's DDATA is about 1 kB), two days of
/// a hammer striking every 3 s.
pub const DEFAULT_QUEUE_MAX_BYTES: u64 = 64 * 1024 * 1024;
/// Default queue age: 7 days, a long weekend's outage twice over.
pub const DEFAULT_QUEUE_MAX_AGE_S: u64 = 7 * 86_400;

/// `queue_max_bytes`: from 64 KiB (some 60 blows) to 1 TiB.
pub const QUEUE_MAX_BYTES: WholeLimits = WholeLimits { min: 64 * 1024, max: 1 << 40, unit: "bytes" };
/// `queue_max_age_s`: from a minute to a year.
pub const QUEUE_MAX_AGE_S: WholeLimits = WholeLimits { min: 60, max: 366 * 86_400, unit: "s" };

/// The validated `[uplink.mqtt]` table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttUplink {
    /// The URL as written (`mqtt://host:port`), for logs and `/status`.
    pub url: String,
    pub host: String,
    pub port: u16,
    /// Sparkplug ids (specification §4.1.1): no `/`, `+` or `#`.
    pub group_id: String,
    pub edge_node_id: String,
    pub device_id: String,
    /// The Sparkplug primary host application to wait for (`spBv1.0/STATE/<id>` online)
    /// before each birth, so that no blow is published while it cannot listen; `None`:
    /// publish as soon as the broker takes the connection.
    pub primary_host_id: Option<String>,
    pub queue_max_bytes: u64,
    pub queue_max_age_s: u64,
}

impl MqttUplink {
    /// The table's defaults for a broker at `url` (the demo's `--mqtt URL`).
    pub fn for_url(url: &str) -> Result<Self, String> {
        let (host, port) = parse_url(url)?;
        Ok(MqttUplink {
            url: url.to_string(),
            host,
            port,
            group_id: DEFAULT_GROUP_ID.into(),
            edge_node_id: DEFAULT_EDGE_NODE_ID.into(),
            device_id: DEFAULT_DEVICE_ID.into(),
            primary_host_id: None,
            queue_max_bytes: DEFAULT_QUEUE_MAX_BYTES,
            queue_max_age_s: DEFAULT_QUEUE_MAX_AGE_S,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawUplink {
    mqtt: Option<RawMqtt>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMqtt {
    url: String,
    group_id: Option<String>,
    edge_node_id: Option<String>,
    device_id: Option<String>,
    primary_host_id: Option<String>,
    queue_max_bytes: Option<u64>,
    queue_max_age_s: Option<u64>,
}

/// `[uplink]` of the service file, if present: `Some` when it has an `mqtt` table.
pub(crate) fn parse_uplink(doc: &Document<'_>) -> Result<Option<MqttUplink>, ConfigError> {
    let Some(value) = doc.get("uplink") else { return Ok(None) };
    let raw: RawUplink = doc.read_value(value.clone(), "uplink")?;
    let Some(m) = raw.mqtt else { return Ok(None) };
    let (host, port) = parse_url(&m.url).map_err(|why| doc.invalid("uplink.mqtt.url", why))?;
    let id = |key: &str, v: Option<String>, default: &str| -> Result<String, ConfigError> {
        let v = v.unwrap_or_else(|| default.to_string());
        sparkplug_id(&v).map_err(|why| doc.invalid(&format!("uplink.mqtt.{key}"), why))?;
        Ok(v)
    };
    let primary_host_id = match m.primary_host_id {
        Some(h) => Some(id("primary_host_id", Some(h), "")?),
        None => None,
    };
    Ok(Some(MqttUplink {
        url: m.url.clone(),
        host,
        port,
        group_id: id("group_id", m.group_id, DEFAULT_GROUP_ID)?,
        edge_node_id: id("edge_node_id", m.edge_node_id, DEFAULT_EDGE_NODE_ID)?,
        device_id: id("device_id", m.device_id, DEFAULT_DEVICE_ID)?,
        primary_host_id,
        queue_max_bytes: match m.queue_max_bytes {
            Some(b) => doc.in_whole_range("uplink.mqtt.queue_max_bytes", b, &QUEUE_MAX_BYTES)?,
            None => DEFAULT_QUEUE_MAX_BYTES,
        },
        queue_max_age_s: match m.queue_max_age_s {
            Some(s) => doc.in_whole_range("uplink.mqtt.queue_max_age_s", s, &QUEUE_MAX_AGE_S)?,
            None => DEFAULT_QUEUE_MAX_AGE_S,
        },
    }))
}

/// `mqtt://host[:port]` (or `tcp://`) as host and port; TLS (`mqtts://`) is not offered yet.
pub fn parse_url(url: &str) -> Result<(String, u16), String> {
    let rest = url
        .strip_prefix("mqtt://")
        .or_else(|| url.strip_prefix("tcp://"))
        .ok_or_else(|| format!("'{url}' is not an mqtt://host:port URL (plain TCP; mqtts:// is not supported)"))?;
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.is_empty() || rest.contains('/') || rest.contains('@') {
        return Err(format!("'{url}' must be mqtt://host or mqtt://host:port, without a path or credentials"));
    }
    // An IPv6 literal is bracketed: [::1]:1883.
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) if !p.contains(']') => {
            (h, p.parse::<u16>().map_err(|_| format!("'{url}': port '{p}' is not a number in 1..=65535"))?)
        }
        _ => (rest, DEFAULT_MQTT_PORT),
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() || port == 0 {
        return Err(format!("'{url}' must name a host and a port in 1..=65535"));
    }
    Ok((host.to_string(), port))
}

/// A Sparkplug group, edge node or device id: UTF-8, not empty, none of `/ + #`
/// (specification §4.1.1, they are topic levels).
fn sparkplug_id(s: &str) -> Result<(), String> {
    if s.is_empty() {
        return Err("must not be empty".into());
    }
    if let Some(c) = s.chars().find(|c| matches!(c, '/' | '+' | '#')) {
        return Err(format!("'{s}' must not contain '{c}' (it is an MQTT topic level)"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Option<MqttUplink>, ConfigError> {
        let doc = Document::parse("service.toml", text)?;
        parse_uplink(&doc)
    }

    #[test]
    fn full_table_is_read_with_defaults_filled_in() {
        let u = parse(
            "[uplink.mqtt]\nurl = \"mqtt://10.0.0.5:8883\"\nedge_node_id = \"hammer-3\"\nqueue_max_bytes = 1048576\n",
        )
        .expect("valid")
        .expect("present");
        assert_eq!((u.host.as_str(), u.port), ("10.0.0.5", 8883));
        assert_eq!(u.edge_node_id, "hammer-3");
        assert_eq!(u.group_id, DEFAULT_GROUP_ID);
        assert_eq!(u.queue_max_bytes, 1_048_576);
        assert_eq!(u.queue_max_age_s, DEFAULT_QUEUE_MAX_AGE_S);
    }

    /// The table through the whole service file: read into `ServiceConfig`, and a misspelt
    /// table under `[uplink]` refused there too.
    #[test]
    fn service_file_carries_the_uplink() {
        let service = |extra: &str| {
            let text = format!(
                "machine = \"m.toml\"\n[recording]\ndir = \"rec\"\n[[sources]]\nname = \"daq\"\nkind = \"serial\"\n\
                 path = \"/dev/ttyUSB0\"\n[[sources.channels]]\nrole = \"load_N\"\ngain = 1.0\n{extra}"
            );
            crate::config::service::parse_service("service.toml", std::path::Path::new("/"), &text)
        };
        let c = service("[uplink.mqtt]\nurl = \"mqtt://broker:1884\"\ndevice_id = \"press-2\"\n").expect("valid");
        let u = c.uplink_mqtt.expect("the uplink");
        assert_eq!((u.port, u.device_id.as_str()), (1884, "press-2"));
        assert_eq!(service("").expect("valid").uplink_mqtt, None);
        let e = service("[uplink.mqtt]\nurl = \"mqtt://b\"\n[uplink.mqqt]\nurl = \"x\"\n").expect_err("typo");
        assert!(e.to_string().contains("mqqt"), "{e}");
    }

    #[test]
    fn no_table_is_no_uplink() {
        assert_eq!(parse("x = 1\n").expect("valid"), None);
    }

    #[test]
    fn url_without_port_takes_1883_and_ipv6_is_bracketed() {
        assert_eq!(parse_url("mqtt://broker.plant"), Ok(("broker.plant".into(), 1883)));
        assert_eq!(parse_url("tcp://[::1]:1884"), Ok(("::1".into(), 1884)));
        assert!(parse_url("mqtts://broker:8883").is_err());
        assert!(parse_url("mqtt://broker:0").is_err());
        assert!(parse_url("mqtt://user@broker").is_err());
    }

    #[test]
    fn bad_id_names_the_key_and_line() {
        let e = parse("[uplink.mqtt]\nurl = \"mqtt://h\"\n\ngroup_id = \"a/b\"\n").expect_err("a '/' in an id");
        let m = e.to_string();
        assert!(m.contains("uplink.mqtt.group_id") && m.contains("service.toml:4"), "{m}");
    }

    #[test]
    fn misspelt_key_is_refused_with_a_suggestion() {
        let e = parse("[uplink.mqtt]\nurl = \"mqtt://h\"\nqueue_max_byte = 5\n").expect_err("unknown key");
        assert!(e.to_string().contains("queue_max_bytes"), "{e}");
    }

    #[test]
    fn queue_limits_are_range_checked() {
        let e = parse("[uplink.mqtt]\nurl = \"mqtt://h\"\nqueue_max_age_s = 5\n").expect_err("below a minute");
        assert!(e.to_string().contains("uplink.mqtt.queue_max_age_s"), "{e}");
    }
}
