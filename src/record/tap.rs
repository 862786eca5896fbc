//! A live copy of what the recorder writes: each message as it is encoded for the file, with
//! its topic, protobuf schema (name and FileDescriptorSet) and log time, handed to a
//! consumer that shows it live (the Foxglove view, `daemon/foxglove`). The file gets the very
//! same bytes; the tap changes nothing that is recorded, and a consumer that wants the
//! message must copy it before it returns (it runs on the writer's thread, so it must not
//! block either).

use super::schema::{FILE_DESCRIPTOR_SET, MESSAGE_ENCODING, MessageKind, SCHEMA_ENCODING};

/// One message as the recorder encoded it, borrowed for the duration of the tap's call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TappedMessage<'a> {
    /// The MCAP topic (`/results`, `/samples/<source>`, ...).
    pub topic: &'a str,
    pub kind: MessageKind,
    /// The protobuf-encoded message, exactly as written to the file.
    pub data: &'a [u8],
    /// The MCAP log time: host time, ns.
    pub log_time_ns: u64,
    /// The MCAP publish time: device time for samples, else the log time, ns.
    pub publish_time_ns: u64,
}

impl TappedMessage<'_> {
    /// The fully-qualified protobuf message name (the MCAP schema name).
    pub fn schema_name(&self) -> &'static str {
        self.kind.schema_name()
    }

    /// The encoded `google.protobuf.FileDescriptorSet` that defines the message (the MCAP
    /// schema record's data).
    pub fn schema(&self) -> &'static [u8] {
        FILE_DESCRIPTOR_SET
    }

    /// The schema's encoding: `protobuf`.
    pub fn schema_encoding(&self) -> &'static str {
        SCHEMA_ENCODING
    }

    /// The message's encoding: `protobuf`.
    pub fn message_encoding(&self) -> &'static str {
        MESSAGE_ENCODING
    }
}

/// A consumer of every message the writer encodes (set with
/// [`super::RecordWriter::set_tap`]).
pub type Tap = Box<dyn FnMut(&TappedMessage<'_>) + Send>;
