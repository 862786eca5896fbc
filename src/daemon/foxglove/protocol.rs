//! The Foxglove WebSocket protocol's messages (`foxglove.websocket.v1`, the spec at
//! github.com/foxglove/ws-protocol, `docs/spec.md`), the part of it this server speaks:
//! `serverInfo`, `advertise`, `status` and binary message data out; `subscribe` and
//! `unsubscribe` in. Plain values to JSON text and bytes and back, no IO (sans-IO): the
//! connection in `mod.rs` moves them.

use base64::Engine;
use serde::{Deserialize, Serialize};

/// The WebSocket subprotocol a client must ask for (spec, "Subprotocol").
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Opcode of a binary "Message Data" frame (spec, "Binary messages").
pub const OPCODE_MESSAGE_DATA: u8 = 0x01;

/// Bytes of a message data frame before its payload: opcode, subscription id (u32 LE), log
/// time (u64 LE, ns).
pub const MESSAGE_DATA_HEADER_BYTES: usize = 1 + 4 + 8;

/// A channel as the server advertises it (spec, "Advertise": `channels[]`).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct AdvertisedChannel {
    pub id: u32,
    pub topic: String,
    /// The message encoding (`protobuf`).
    pub encoding: String,
    pub schema_name: String,
    /// For protobuf: the base64 of the encoded `google.protobuf.FileDescriptorSet`.
    pub schema: String,
    pub schema_encoding: String,
}

impl AdvertisedChannel {
    /// A protobuf channel whose schema is `descriptor_set`, base64-encoded as the spec asks.
    pub fn protobuf(id: u32, topic: &str, schema_name: &str, descriptor_set: &[u8]) -> Self {
        AdvertisedChannel {
            id,
            topic: topic.to_string(),
            encoding: "protobuf".into(),
            schema_name: schema_name.to_string(),
            schema: base64::engine::general_purpose::STANDARD.encode(descriptor_set),
            schema_encoding: "protobuf".into(),
        }
    }
}

/// Severity of a `status` message (spec, "Status": 0 info, 1 warning, 2 error).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Info = 0,
    Warning = 1,
    Error = 2,
}

/// A JSON message from the server.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub enum ServerMessage {
    #[serde(rename_all = "camelCase")]
    ServerInfo {
        name: String,
        /// Optional features offered: none (no client publishing, parameters, services).
        capabilities: Vec<String>,
        supported_encodings: Vec<String>,
        metadata: std::collections::BTreeMap<String, String>,
        /// Changes when the server restarts, so a client drops what it knew.
        session_id: String,
    },
    Advertise {
        channels: Vec<AdvertisedChannel>,
    },
    Status {
        level: u8,
        message: String,
    },
}

impl ServerMessage {
    pub fn status(level: Level, message: impl Into<String>) -> Self {
        ServerMessage::Status { level: level as u8, message: message.into() }
    }

    /// The message as the text frame's JSON.
    pub fn to_json(&self) -> String {
        // Plain strings, integers and maps: serialising cannot fail.
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// One subscription a client asks for (spec, "Subscribe": `subscriptions[]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Subscription {
    /// The client's id for it, which the server's message data frames carry.
    pub id: u32,
    pub channel_id: u32,
}

/// A JSON message from a client that this server acts on.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub enum ClientMessage {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        subscription_ids: Vec<u32>,
    },
}

/// Why a client's text frame was not acted on.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadClientMessage {
    #[error("not a JSON object with an \"op\": {reason}")]
    NotJson { reason: String },
    #[error("op \"{op}\" is not supported by this server (it offers subscribe and unsubscribe only)")]
    Unsupported { op: String },
    #[error("op \"{op}\": {reason}")]
    BadFields { op: String, reason: String },
}

/// Read a client's text frame.
pub fn parse_client(text: &str) -> Result<ClientMessage, BadClientMessage> {
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| BadClientMessage::NotJson { reason: e.to_string() })?;
    let op = match value.get("op").and_then(serde_json::Value::as_str) {
        Some(op) => op.to_string(),
        None => return Err(BadClientMessage::NotJson { reason: "no string \"op\" field".into() }),
    };
    if !matches!(op.as_str(), "subscribe" | "unsubscribe") {
        return Err(BadClientMessage::Unsupported { op });
    }
    serde_json::from_value(value).map_err(|e| BadClientMessage::BadFields { op, reason: e.to_string() })
}

/// A message data frame: opcode 0x01, the subscription id, the log time, the payload.
pub fn message_data(subscription_id: u32, log_time_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut frame = Vec::with_capacity(MESSAGE_DATA_HEADER_BYTES + payload.len());
    frame.push(OPCODE_MESSAGE_DATA);
    frame.extend_from_slice(&subscription_id.to_le_bytes());
    frame.extend_from_slice(&log_time_ns.to_le_bytes());
    frame.extend_from_slice(payload);
    frame
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_data_frame_is_opcode_subscription_time_payload() {
        let frame = message_data(0x0403_0201, 0x0c0b_0a09_0807_0605, b"pb");
        assert_eq!(
            frame,
            [
                0x01, // opcode: message data
                0x01, 0x02, 0x03, 0x04, // subscription id, u32 LE
                0x05, 0x06, 0x07, 0x08, 0x09, 0x0a, 0x0b, 0x0c, // log time ns, u64 LE
                b'p', b'b', // payload
            ]
        );
        assert_eq!(message_data(7, 0, &[]).len(), MESSAGE_DATA_HEADER_BYTES);
    }

    #[test]
    fn server_messages_have_the_spec_field_names() {
        let ch = AdvertisedChannel::protobuf(3, "/results", "forgemon.BlowResult", b"\x0a\x01x");
        let json: serde_json::Value =
            serde_json::from_str(&ServerMessage::Advertise { channels: vec![ch] }.to_json()).expect("JSON");
        assert_eq!(
            json,
            serde_json::json!({"op": "advertise", "channels": [{
                "id": 3, "topic": "/results", "encoding": "protobuf",
                "schemaName": "forgemon.BlowResult", "schema": "CgF4", "schemaEncoding": "protobuf"
            }]})
        );
        let info = ServerMessage::ServerInfo {
            name: "forgemon".into(),
            capabilities: vec![],
            supported_encodings: vec![],
            metadata: Default::default(),
            session_id: "s1".into(),
        };
        let json: serde_json::Value = serde_json::from_str(&info.to_json()).expect("JSON");
        assert_eq!(json["op"], "serverInfo");
        assert_eq!(json["sessionId"], "s1");
        assert!(json["supportedEncodings"].is_array() && json["capabilities"].is_array());
        let status: serde_json::Value =
            serde_json::from_str(&ServerMessage::status(Level::Warning, "slow").to_json()).expect("JSON");
        assert_eq!(status, serde_json::json!({"op": "status", "level": 1, "message": "slow"}));
    }

    #[test]
    fn client_messages_parse_and_garbage_says_why() {
        assert_eq!(
            parse_client(r#"{"op":"subscribe","subscriptions":[{"id":0,"channelId":2},{"id":9,"channelId":5}]}"#),
            Ok(ClientMessage::Subscribe {
                subscriptions: vec![Subscription { id: 0, channel_id: 2 }, Subscription { id: 9, channel_id: 5 }]
            })
        );
        assert_eq!(
            parse_client(r#"{"op":"unsubscribe","subscriptionIds":[9]}"#),
            Ok(ClientMessage::Unsubscribe { subscription_ids: vec![9] })
        );
        let e = |t: &str| parse_client(t).expect_err(t).to_string();
        assert!(e("").contains("not a JSON object"));
        assert!(e("\u{0}\u{ff}garbage").contains("not a JSON object"));
        assert!(e(r#"{"subscriptions":[]}"#).contains("no string \"op\""));
        assert!(e(r#"{"op":"advertise","channels":[]}"#).contains("\"advertise\" is not supported"));
        let why = e(r#"{"op":"subscribe","subscriptions":[{"id":-1,"channelId":2}]}"#);
        assert!(why.starts_with("op \"subscribe\""), "{why}");
        assert!(e(r#"{"op":"unsubscribe"}"#).contains("subscriptionIds"));
    }
}
