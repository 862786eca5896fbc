//! The Foxglove view's shared state: the channels (one per recording topic, each with the
//! recording's protobuf schema), the connected clients with their subscriptions, and each
//! client's outbox, a bounded queue that drops its *oldest* message data when the client
//! falls behind and counts what it drops (DESIGN.md §4's rule for the real-time path).
//!
//! [`Hub::publish`] runs on the service's thread (the recorder's tap): it takes two short
//! locks, copies the message once for all the clients subscribed to its channel, and never
//! waits for a socket. Locks are always taken hub first, then an outbox.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use tokio::sync::{Notify, watch};

use crate::record::schema::FILE_DESCRIPTOR_SET;
use crate::record::{MessageKind, TappedMessage};

use super::protocol::{AdvertisedChannel, ClientMessage, Level, ServerMessage};

/// Bytes of message data a client's outbox holds before it drops the oldest: about 1.7 s
/// of one source's 3 × 100 kHz samples (8 bytes a value), many minutes of results.
pub const CLIENT_QUEUE_BYTES: usize = 4 << 20;
/// JSON messages (advertisements, status) queued for a client that does not read: past
/// this many the client is disconnected (they cannot be dropped without losing channels).
pub const CLIENT_CONTROL_MESSAGES: usize = 1024;
/// What a queued message costs beyond its payload, for the byte bound.
const QUEUED_OVERHEAD_BYTES: usize = 64;

/// One message for one client's subscription.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Data {
    pub subscription_id: u32,
    pub log_time_ns: u64,
    /// Shared by every client subscribed to the channel.
    pub payload: Arc<[u8]>,
}

/// What the connection sends next.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outgoing {
    /// A JSON message.
    Text(String),
    Data(Data),
}

#[derive(Debug, Default)]
struct Queued {
    control: VecDeque<String>,
    data: VecDeque<Data>,
    data_bytes: usize,
    /// Message data dropped, in all.
    dropped: u64,
    /// Of which the client was told about.
    dropped_told: u64,
    closed: bool,
}

/// A client's bounded queue: JSON messages first, then message data, oldest first.
#[derive(Debug)]
pub struct Outbox {
    queued: Mutex<Queued>,
    ready: Notify,
    capacity_bytes: usize,
}

impl Outbox {
    pub fn new(capacity_bytes: usize) -> Self {
        Outbox { queued: Mutex::new(Queued::default()), ready: Notify::new(), capacity_bytes }
    }

    /// Queue message data, dropping the oldest to stay within the byte bound; how many
    /// were dropped.
    pub fn push_data(&self, d: Data) -> u64 {
        let Ok(mut q) = self.queued.lock() else { return 0 };
        if q.closed {
            return 0;
        }
        let cost = d.payload.len() + QUEUED_OVERHEAD_BYTES;
        let mut dropped = 0;
        while q.data_bytes + cost > self.capacity_bytes {
            let Some(old) = q.data.pop_front() else { break };
            q.data_bytes -= old.payload.len() + QUEUED_OVERHEAD_BYTES;
            dropped += 1;
        }
        q.dropped += dropped;
        q.data_bytes += cost;
        q.data.push_back(d);
        drop(q);
        self.ready.notify_one();
        dropped
    }

    /// Queue a JSON message; false (and the outbox closed) when the client has left too
    /// many unread.
    pub fn push_text(&self, text: String) -> bool {
        let Ok(mut q) = self.queued.lock() else { return false };
        if q.control.len() >= CLIENT_CONTROL_MESSAGES {
            q.closed = true;
        } else if !q.closed {
            q.control.push_back(text);
        }
        let open = !q.closed;
        drop(q);
        self.ready.notify_one();
        open
    }

    /// Stop: `next` returns `None` from now on.
    pub fn close(&self) {
        if let Ok(mut q) = self.queued.lock() {
            q.closed = true;
        }
        self.ready.notify_one();
    }

    /// The next message to send, waiting for one; `None` once closed. A `status` warning
    /// comes first when message data was dropped since the last one.
    pub async fn next(&self) -> Option<Outgoing> {
        loop {
            if let Some(out) = self.try_next()? {
                return Some(out);
            }
            // `notify_one` leaves a permit when nobody waits: a push between the check
            // above and this wait is not missed.
            self.ready.notified().await;
        }
    }

    /// The next message if one is queued (`Some(None)` when empty), `None` once closed.
    pub fn try_next(&self) -> Option<Option<Outgoing>> {
        let Ok(mut q) = self.queued.lock() else { return None };
        if q.closed {
            return None;
        }
        if q.dropped > q.dropped_told {
            let n = q.dropped - q.dropped_told;
            q.dropped_told = q.dropped;
            let text = ServerMessage::status(
                Level::Warning,
                format!(
                    "forgemon dropped the oldest {n} messages queued for this client ({} in all): it reads slower than they come",
                    q.dropped
                ),
            );
            return Some(Some(Outgoing::Text(text.to_json())));
        }
        if let Some(text) = q.control.pop_front() {
            return Some(Some(Outgoing::Text(text)));
        }
        let Some(d) = q.data.pop_front() else { return Some(None) };
        q.data_bytes -= d.payload.len() + QUEUED_OVERHEAD_BYTES;
        Some(Some(Outgoing::Data(d)))
    }

    /// Message data dropped so far.
    pub fn dropped(&self) -> u64 {
        self.queued.lock().map_or(0, |q| q.dropped)
    }
}

/// A connected client's subscriptions, both ways.
struct Client {
    /// Channel id to the client's subscription id.
    by_channel: HashMap<u32, u32>,
    /// Subscription id to channel id.
    by_subscription: HashMap<u32, u32>,
    outbox: Arc<Outbox>,
}

struct State {
    channels: Vec<AdvertisedChannel>,
    by_topic: HashMap<String, u32>,
    clients: BTreeMap<u64, Client>,
    next_client: u64,
}

/// Counters over the server's life, for the log and the tests.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct HubStats {
    pub clients_now: u64,
    pub clients_served: u64,
    /// Message data queued for clients.
    pub queued: u64,
    /// Message data dropped because a client fell behind.
    pub dropped: u64,
    /// Client frames that were not protocol (bad JSON, unsupported op, binary).
    pub bad_frames: u64,
}

#[derive(Debug, Default)]
struct Counters {
    clients_served: AtomicU64,
    queued: AtomicU64,
    dropped: AtomicU64,
    bad_frames: AtomicU64,
}

/// The channels and the clients; cheap to clone (shared).
#[derive(Clone)]
pub struct Hub {
    state: Arc<Mutex<State>>,
    counters: Arc<Counters>,
    capacity_bytes: usize,
    /// Turns true when the service stops, so a connection stuck on its socket ends too.
    stopping: Arc<watch::Sender<bool>>,
}

impl Hub {
    /// A hub with every fixed topic of a recording advertised (`/results`, `/blows`, ...);
    /// `/samples/<source>` channels are added as their sources' first batches come.
    pub fn new(capacity_bytes: usize) -> Self {
        let state = State { channels: Vec::new(), by_topic: HashMap::new(), clients: BTreeMap::new(), next_client: 1 };
        let hub = Hub {
            state: Arc::new(Mutex::new(state)),
            counters: Arc::default(),
            capacity_bytes,
            stopping: Arc::new(watch::channel(false).0),
        };
        if let Ok(mut st) = hub.state.lock() {
            for kind in MessageKind::ALL {
                if let Some(topic) = kind.fixed_topic() {
                    add_channel(&mut st, topic, kind);
                }
            }
        }
        hub
    }

    /// The channels advertised now.
    pub fn channels(&self) -> Vec<AdvertisedChannel> {
        self.state.lock().map(|st| st.channels.clone()).unwrap_or_default()
    }

    /// Hand a message the recorder encoded to every client subscribed to its topic (the
    /// recorder's tap; never waits).
    pub fn publish(&self, m: &TappedMessage<'_>) {
        let Ok(mut st) = self.state.lock() else { return };
        let channel = match st.by_topic.get(m.topic) {
            Some(id) => *id,
            None => add_channel(&mut st, m.topic, m.kind),
        };
        let mut payload: Option<Arc<[u8]>> = None;
        let (mut queued, mut dropped) = (0, 0);
        for client in st.clients.values() {
            if let Some(&subscription_id) = client.by_channel.get(&channel) {
                let payload = payload.get_or_insert_with(|| Arc::from(m.data)).clone();
                dropped += client.outbox.push_data(Data { subscription_id, log_time_ns: m.log_time_ns, payload });
                queued += 1;
            }
        }
        drop(st);
        self.counters.queued.fetch_add(queued, Ordering::Relaxed);
        self.counters.dropped.fetch_add(dropped, Ordering::Relaxed);
    }

    /// A client connected: its id and outbox, which already holds `serverInfo` and the
    /// advertisement of every channel.
    pub fn connect(&self, server_info: &ServerMessage) -> (u64, Arc<Outbox>) {
        let outbox = Arc::new(Outbox::new(self.capacity_bytes));
        outbox.push_text(server_info.to_json());
        let Ok(mut st) = self.state.lock() else { return (0, outbox) };
        outbox.push_text(ServerMessage::Advertise { channels: st.channels.clone() }.to_json());
        let id = st.next_client;
        st.next_client += 1;
        let client = Client { by_channel: HashMap::new(), by_subscription: HashMap::new(), outbox: outbox.clone() };
        st.clients.insert(id, client);
        self.counters.clients_served.fetch_add(1, Ordering::Relaxed);
        (id, outbox)
    }

    /// A client left (or was dropped); what it lost to falling behind.
    pub fn disconnect(&self, client: u64) -> u64 {
        let Ok(mut st) = self.state.lock() else { return 0 };
        st.clients.remove(&client).map_or(0, |c| {
            c.outbox.close();
            c.outbox.dropped()
        })
    }

    /// Close every client's outbox and tell the connections (the service stops).
    pub fn close_all(&self) {
        if let Ok(st) = self.state.lock() {
            st.clients.values().for_each(|c| c.outbox.close());
        }
        self.stopping.send_replace(true);
    }

    /// Resolves once [`Hub::close_all`] was called.
    pub async fn stopped(&self) {
        let mut rx = self.stopping.subscribe();
        let _ = rx.wait_for(|stopping| *stopping).await;
    }

    /// Act on a client's text frame; a frame that is not protocol is answered with an error
    /// `status` and counted.
    pub fn on_text(&self, client: u64, text: &str) {
        let answer = match super::protocol::parse_client(text) {
            Ok(m) => self.apply(client, m).err(),
            Err(e) => Some(e.to_string()),
        };
        if let Some(why) = answer {
            self.bad_frame(client, why);
        }
    }

    /// A frame this server never accepts (binary: client publishing is not offered).
    pub fn on_unexpected(&self, client: u64, what: &str) {
        self.bad_frame(client, format!("{what} frames are not accepted: this server only publishes"));
    }

    fn bad_frame(&self, client: u64, why: String) {
        self.counters.bad_frames.fetch_add(1, Ordering::Relaxed);
        tracing::debug!(client, %why, "foxglove: a client's frame was refused");
        if let Ok(st) = self.state.lock()
            && let Some(c) = st.clients.get(&client)
        {
            c.outbox.push_text(ServerMessage::status(Level::Error, why).to_json());
        }
    }

    fn apply(&self, client: u64, m: ClientMessage) -> Result<(), String> {
        let Ok(mut st) = self.state.lock() else { return Err("the server is stopping".into()) };
        let known: Vec<u32> = st.channels.iter().map(|c| c.id).collect();
        let Some(c) = st.clients.get_mut(&client) else { return Err("not connected".into()) };
        let mut refused = Vec::new();
        match m {
            ClientMessage::Subscribe { subscriptions } => {
                for s in subscriptions {
                    if !known.contains(&s.channel_id) {
                        refused.push(format!("subscription {}: no channel {}", s.id, s.channel_id));
                    } else if c.by_subscription.contains_key(&s.id) {
                        refused.push(format!("subscription {}: the id is in use", s.id));
                    } else if let Some(old) = c.by_channel.get(&s.channel_id) {
                        refused.push(format!("subscription {}: channel {} is subscribed as {old}", s.id, s.channel_id));
                    } else {
                        c.by_channel.insert(s.channel_id, s.id);
                        c.by_subscription.insert(s.id, s.channel_id);
                    }
                }
            }
            ClientMessage::Unsubscribe { subscription_ids } => {
                for id in subscription_ids {
                    match c.by_subscription.remove(&id) {
                        Some(channel) => {
                            c.by_channel.remove(&channel);
                        }
                        None => refused.push(format!("unsubscribe {id}: no such subscription")),
                    }
                }
            }
        }
        if refused.is_empty() { Ok(()) } else { Err(refused.join("; ")) }
    }

    pub fn stats(&self) -> HubStats {
        let load = |c: &AtomicU64| c.load(Ordering::Relaxed);
        HubStats {
            clients_now: self.state.lock().map_or(0, |st| st.clients.len() as u64),
            clients_served: load(&self.counters.clients_served),
            queued: load(&self.counters.queued),
            dropped: load(&self.counters.dropped),
            bad_frames: load(&self.counters.bad_frames),
        }
    }
}

/// Add a channel for `topic` and advertise it to the clients connected; its id.
fn add_channel(st: &mut State, topic: &str, kind: MessageKind) -> u32 {
    let id = st.channels.len() as u32 + 1;
    let channel = AdvertisedChannel::protobuf(id, topic, kind.schema_name(), FILE_DESCRIPTOR_SET);
    let advert = ServerMessage::Advertise { channels: vec![channel.clone()] }.to_json();
    for c in st.clients.values() {
        c.outbox.push_text(advert.clone());
    }
    st.channels.push(channel);
    st.by_topic.insert(topic.to_string(), id);
    id
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(n: u64, bytes: usize) -> Data {
        Data { subscription_id: 1, log_time_ns: n, payload: Arc::from(vec![n as u8; bytes]) }
    }

    fn drain(o: &Outbox) -> Vec<Outgoing> {
        std::iter::from_fn(|| o.try_next().flatten()).collect()
    }

    fn tapped<'a>(topic: &'a str, kind: MessageKind, data: &'a [u8], t: u64) -> TappedMessage<'a> {
        TappedMessage { topic, kind, data, log_time_ns: t, publish_time_ns: t }
    }

    /// A datum as (subscription, log time, payload).
    type Sent = (u32, u64, Vec<u8>);

    /// The JSON of each text message, and each datum.
    fn split(out: Vec<Outgoing>) -> (Vec<serde_json::Value>, Vec<Sent>) {
        let (mut texts, mut datas) = (Vec::new(), Vec::new());
        for o in out {
            match o {
                Outgoing::Text(t) => texts.push(serde_json::from_str(&t).expect("JSON")),
                Outgoing::Data(d) => datas.push((d.subscription_id, d.log_time_ns, d.payload.to_vec())),
            }
        }
        (texts, datas)
    }

    /// DESIGN.md §4: a full outbox loses its oldest data, counted; the client is told first.
    #[test]
    fn a_full_outbox_drops_the_oldest_data_counts_it_and_says_so_first() {
        // Room for three 100-byte messages (each costs its payload and the overhead).
        let o = Outbox::new(3 * (100 + QUEUED_OVERHEAD_BYTES));
        let dropped: u64 = (0..10).map(|n| o.push_data(data(n, 100))).sum();
        assert!(o.push_text("{\"op\":\"advertise\",\"channels\":[]}".into()));
        assert_eq!((dropped, o.dropped()), (7, 7));
        let (texts, datas) = split(drain(&o));
        assert_eq!(texts[0]["op"], "status");
        assert_eq!(texts[0]["level"], 1);
        let message = texts[0]["message"].as_str().unwrap_or_default();
        assert!(message.contains("oldest 7 messages"), "{message}");
        assert_eq!(texts[1]["op"], "advertise", "JSON before data, never dropped");
        assert_eq!(datas.iter().map(|d| d.1).collect::<Vec<_>>(), [7, 8, 9], "the newest kept, in order");
        // Once told, not again; a message larger than the bound still goes alone.
        assert_eq!(o.push_data(data(10, 10_000)), 0);
        assert_eq!(o.push_data(data(11, 1)), 1);
        assert_eq!(split(drain(&o)).1.iter().map(|d| d.1).collect::<Vec<_>>(), [11]);
        o.close();
        assert_eq!(o.try_next(), None);
    }

    #[test]
    fn a_client_that_leaves_its_json_unread_is_closed_not_grown() {
        let o = Outbox::new(1000);
        for _ in 0..CLIENT_CONTROL_MESSAGES {
            assert!(o.push_text("{}".into()));
        }
        assert!(!o.push_text("{}".into()));
        assert_eq!(o.try_next(), None, "closed");
    }

    #[test]
    fn data_goes_to_the_subscribed_clients_with_their_ids_and_new_topics_are_advertised() {
        let hub = Hub::new(CLIENT_QUEUE_BYTES);
        let info = ServerMessage::status(Level::Info, "hello");
        let ((a, out_a), (b, out_b)) = (hub.connect(&info), hub.connect(&info));
        let (texts, _) = split(drain(&out_a));
        assert_eq!(texts.len(), 2);
        let advertised = texts[1]["channels"].as_array().cloned().unwrap_or_default();
        let topics: Vec<&str> = advertised.iter().filter_map(|c| c["topic"].as_str()).collect();
        assert_eq!(topics, ["/blows", "/results", "/alerts", "/gaps", "/status", "/config", "/billets"]);
        let results = advertised[1]["id"].as_u64().unwrap_or_default();
        assert_eq!(advertised[1]["schemaName"], "forgemon.BlowResult");
        drain(&out_b);

        hub.on_text(a, &format!(r#"{{"op":"subscribe","subscriptions":[{{"id":40,"channelId":{results}}}]}}"#));
        hub.publish(&tapped("/results", MessageKind::Result, b"r1", 5));
        hub.publish(&tapped("/blows", MessageKind::Boundary, b"b1", 5));
        assert_eq!(split(drain(&out_a)).1, [(40, 5, b"r1".to_vec())], "A: its subscription only");
        assert!(drain(&out_b).is_empty(), "B subscribed to nothing");

        // A source's first batch adds its channel, advertised to everyone connected.
        hub.publish(&tapped("/samples/daq", MessageKind::Samples, b"s1", 6));
        for out in [&out_a, &out_b] {
            let (texts, datas) = split(drain(out));
            assert_eq!(texts.len(), 1);
            assert_eq!(texts[0]["channels"][0]["topic"], "/samples/daq");
            assert_eq!(texts[0]["channels"][0]["schemaName"], "forgemon.SampleBatch");
            assert!(datas.is_empty());
        }

        // Garbage and bad subscriptions are answered, counted, and change nothing.
        hub.on_text(b, "not json");
        hub.on_text(b, r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":99}]}"#);
        hub.on_text(a, &format!(r#"{{"op":"subscribe","subscriptions":[{{"id":40,"channelId":{results}}}]}}"#));
        hub.on_unexpected(b, "binary");
        let (texts, _) = split(drain(&out_b));
        assert_eq!(texts.iter().filter(|t| t["op"] == "status" && t["level"] == 2).count(), 3);
        assert!(texts[1]["message"].as_str().unwrap_or_default().contains("no channel 99"));
        let (texts, _) = split(drain(&out_a));
        assert!(texts[0]["message"].as_str().unwrap_or_default().contains("in use"));
        assert_eq!(hub.stats().bad_frames, 4);

        hub.on_text(a, r#"{"op":"unsubscribe","subscriptionIds":[40]}"#);
        hub.publish(&tapped("/results", MessageKind::Result, b"r2", 7));
        assert!(drain(&out_a).is_empty(), "unsubscribed");
        assert_eq!(hub.disconnect(a), 0);
        assert_eq!(out_a.try_next(), None, "closed on disconnect");
        let s = hub.stats();
        assert_eq!((s.clients_now, s.clients_served, s.queued, s.dropped), (1, 2, 1, 0));
    }

    /// A client that never reads: every publish returns, the outbox stays within its bound,
    /// and each message is either still queued or counted as dropped.
    #[test]
    fn a_client_that_never_reads_costs_the_publisher_only_drops() {
        let hub = Hub::new(CLIENT_QUEUE_BYTES);
        let (client, outbox) = hub.connect(&ServerMessage::status(Level::Info, "hi"));
        hub.on_text(client, r#"{"op":"subscribe","subscriptions":[{"id":3,"channelId":2}]}"#);
        // 10 ms of 3 × 100 kHz doubles per message, 20 s of them.
        let batch = vec![0u8; 3 * 1000 * 8];
        let n = 2000;
        for t in 0..n {
            hub.publish(&tapped("/results", MessageKind::Result, &batch, t));
        }
        let s = hub.stats();
        assert_eq!(s.queued, n);
        let (_, kept) = split(drain(&outbox));
        assert!(s.dropped > 0);
        assert_eq!(s.dropped + kept.len() as u64, n);
        assert!(kept.len() * (batch.len() + QUEUED_OVERHEAD_BYTES) <= CLIENT_QUEUE_BYTES);
        assert_eq!(kept.last().map(|d| d.1), Some(n - 1), "the newest kept");
    }
}
