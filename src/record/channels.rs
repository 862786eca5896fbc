//! The schemas and channels a reader has seen (from the summary, or from the chunks read so
//! far), and what each channel id holds: one of forgemon's message kinds, something foreign
//! to pass over, or a channel whose definition was never seen (it was in a corrupt chunk).

use std::collections::HashMap;

use super::schema::{MESSAGE_ENCODING, MessageKind, SCHEMA_ENCODING};

/// What a channel id resolves to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Lookup<'a> {
    Ours(MessageKind, &'a str),
    /// Another schema or encoding: not forgemon's.
    Foreign,
    /// No channel record with this id has been read.
    Unknown,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Channel {
    topic: String,
    schema_id: u16,
    message_encoding: String,
}

/// Schemas and channels by id. The first definition of an id wins.
#[derive(Debug, Default, Clone)]
pub(crate) struct Channels {
    /// Schema id: name and encoding.
    schemas: HashMap<u16, (String, String)>,
    channels: HashMap<u16, Channel>,
}

impl Channels {
    pub fn add_schema(&mut self, id: u16, name: String, encoding: String) {
        self.schemas.entry(id).or_insert((name, encoding));
    }

    pub fn add_channel(&mut self, id: u16, schema_id: u16, topic: String, message_encoding: String) {
        self.channels.entry(id).or_insert(Channel { topic, schema_id, message_encoding });
    }

    pub fn topic(&self, id: u16) -> Option<&str> {
        self.channels.get(&id).map(|c| c.topic.as_str())
    }

    /// The topic of a channel for a report: its name, or its id when it was never seen.
    pub fn topic_or_id(&self, id: u16) -> String {
        self.topic(id).map_or_else(|| format!("channel {id}"), str::to_string)
    }

    pub fn lookup(&self, id: u16) -> Lookup<'_> {
        let Some(channel) = self.channels.get(&id) else { return Lookup::Unknown };
        if channel.message_encoding != MESSAGE_ENCODING {
            return Lookup::Foreign;
        }
        match self.schemas.get(&channel.schema_id) {
            Some((name, encoding)) if encoding == SCHEMA_ENCODING => {
                MessageKind::from_schema_name(name).map_or(Lookup::Foreign, |k| Lookup::Ours(k, &channel.topic))
            }
            Some(_) => Lookup::Foreign,
            // The schema record came with the channel's chunk: treat like the channel.
            None => Lookup::Unknown,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_resolve_to_ours_foreign_or_unknown() {
        let mut c = Channels::default();
        c.add_schema(1, MessageKind::Gap.schema_name().into(), SCHEMA_ENCODING.into());
        c.add_schema(2, "other.Thing".into(), SCHEMA_ENCODING.into());
        c.add_channel(1, 1, "/gaps".into(), MESSAGE_ENCODING.into());
        c.add_channel(2, 2, "/other".into(), MESSAGE_ENCODING.into());
        c.add_channel(3, 1, "/json".into(), "json".into());
        c.add_channel(4, 9, "/lost".into(), MESSAGE_ENCODING.into());
        // A second definition of id 1 does not replace the first.
        c.add_channel(1, 2, "/changed".into(), MESSAGE_ENCODING.into());
        assert_eq!(c.lookup(1), Lookup::Ours(MessageKind::Gap, "/gaps"));
        assert_eq!(c.lookup(2), Lookup::Foreign);
        assert_eq!(c.lookup(3), Lookup::Foreign);
        assert_eq!(c.lookup(4), Lookup::Unknown);
        assert_eq!(c.lookup(5), Lookup::Unknown);
        assert_eq!(c.topic_or_id(5), "channel 5");
    }
}
