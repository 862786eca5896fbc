//! One MQTT connection after another to the broker, each a Sparkplug birth sequence:
//! connect with the NDEATH (this `bdSeq`) as the will, NBIRTH and DBIRTH on the broker's
//! CONNACK, then the queue in order at QoS 1, each blow removed from the queue on its PUBACK;
//! a rebirth on an NCMD `Node Control/Rebirth`. When the connection fails, what was in
//! flight goes back to the queue and the next attempt comes a second later with the next
//! `bdSeq`, which is kept on disk so a restarted service goes on counting.

use std::path::{Path, PathBuf};
use std::time::Duration;

use prost::Message;
use rumqttc::{AsyncClient, Event, LastWill, MqttOptions, Packet, QoS};

use super::payload::{self, MessageType, NodeIds};
use super::{SharedState, now_ms};
use crate::config::uplink::MqttUplink;

/// Wait between connection attempts.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(1);
/// MQTT keep-alive: a broker that went silent is noticed within 1.5 of these.
pub const KEEP_ALIVE: Duration = Duration::from_secs(5);
/// DDATA published and not yet acknowledged, at most.
pub const WINDOW: usize = 32;
/// Room in rumqttc's request channel: the window, two births and the subscription.
const REQUEST_CAPACITY: usize = WINDOW + 16;

/// The connected session's state, inside the shared state so the feeder can publish too.
pub(super) struct Live {
    client: AsyncClient,
    ids: NodeIds,
    bd_seq: u64,
    /// The last `seq` published.
    seq: u64,
    /// When the current birth was published: blows made before it are historical.
    birth_ms: u64,
}

/// Connect, publish, reconnect, for as long as the service runs.
pub(super) async fn run(cfg: MqttUplink, ids: NodeIds, dir: PathBuf, shared: SharedState) {
    let mut bd_seq = read_bd_seq(&dir).map_or(0, payload::next_seq);
    let mut reported = false;
    loop {
        if let Err(e) = write_bd_seq(&dir, bd_seq) {
            tracing::warn!("sparkplug: {e}: a restart may reuse this bdSeq");
        }
        let outcome = session(&cfg, &ids, bd_seq, &shared).await;
        if let Ok(mut s) = shared.lock() {
            if s.session.take().is_some() {
                reported = false;
            }
            s.store.rewind();
        }
        // One line per outage, not one per attempt.
        if !reported {
            tracing::warn!(url = %cfg.url, "sparkplug: broker unreachable ({outcome}); blows are queued on disk");
            reported = true;
        }
        bd_seq = payload::next_seq(bd_seq);
        tokio::time::sleep(RECONNECT_DELAY).await;
    }
}

/// One connection, until it fails; returns why.
async fn session(cfg: &MqttUplink, ids: &NodeIds, bd_seq: u64, shared: &SharedState) -> String {
    let client_id = format!("forgemon-{}-{}", ids.group_id, ids.edge_node_id);
    let mut opts = MqttOptions::new(client_id, cfg.host.clone(), cfg.port);
    opts.set_keep_alive(KEEP_ALIVE);
    opts.set_clean_session(true);
    let will = payload::ndeath(bd_seq).encode_to_vec();
    opts.set_last_will(LastWill::new(ids.topic(MessageType::NDeath), will, QoS::AtLeastOnce, false));
    let (client, mut events) = AsyncClient::new(opts, REQUEST_CAPACITY);
    let ncmd = ids.topic(MessageType::NCmd);
    loop {
        let event = match events.poll().await {
            Ok(e) => e,
            Err(e) => return e.to_string(),
        };
        let Ok(mut s) = shared.lock() else { return "the uplink's state is poisoned".into() };
        match event {
            Event::Incoming(Packet::ConnAck(_)) => {
                if let Err(e) = client.try_subscribe(ncmd.clone(), QoS::AtLeastOnce) {
                    return e.to_string();
                }
                let counters = s.counters();
                let mut live = Live { client: client.clone(), ids: ids.clone(), bd_seq, seq: 0, birth_ms: 0 };
                if let Err(e) = live.birth(counters) {
                    return e;
                }
                tracing::info!(url = %cfg.url, bd_seq, waiting = s.store.len(), "sparkplug: connected and born");
                s.session = Some(live);
            }
            Event::Incoming(Packet::PubAck(_)) => {
                if let Err(e) = s.store.ack_oldest() {
                    tracing::error!("sparkplug: {e}");
                }
                s.published += 1;
            }
            Event::Incoming(Packet::Publish(p)) if p.topic == ncmd && payload::is_rebirth_request(&p.payload) => {
                let counters = s.counters();
                if let Some(live) = s.session.as_mut() {
                    tracing::info!("sparkplug: rebirth asked for (NCMD)");
                    if let Err(e) = live.birth(counters) {
                        return e;
                    }
                }
            }
            _ => {}
        }
        pump(&mut s);
    }
}

/// Publish queued DDATA while there is room in the window (nothing without a session).
pub(super) fn pump(s: &mut super::Shared) {
    let Some(live) = s.session.as_mut() else { return };
    while s.store.in_flight() < WINDOW {
        let record = match s.store.take_next() {
            Ok(Some(r)) => r,
            Ok(None) => return,
            Err(e) => {
                tracing::error!("sparkplug: {e}");
                return;
            }
        };
        let Ok(data) = super::proto::Payload::decode(record.payload.as_slice()) else {
            // Unreadable (its CRC held, so written so): acknowledge it away rather than block.
            tracing::error!("sparkplug: a queued DDATA does not decode; dropped");
            s.store.discard_last();
            continue;
        };
        live.seq = payload::next_seq(live.seq);
        let data = payload::stamp_data(data, live.seq, record.t_ms < live.birth_ms);
        if live
            .client
            .try_publish(live.ids.topic(MessageType::DData), QoS::AtLeastOnce, false, data.encode_to_vec())
            .is_err()
        {
            // The request channel is full or closed: the session ends and rewinds.
            return;
        }
    }
}

impl Live {
    /// NBIRTH (`seq` 0) and DBIRTH (`seq` 1): a new birth sequence.
    fn birth(&mut self, counters: payload::NodeCounters) -> Result<(), String> {
        let t_ms = now_ms();
        let nbirth = payload::nbirth(self.bd_seq, counters, t_ms);
        let dbirth = payload::dbirth(1, t_ms);
        let publish = |t, p: super::proto::Payload| {
            self.client
                .try_publish(self.ids.topic(t), QoS::AtMostOnce, false, p.encode_to_vec())
                .map_err(|e| e.to_string())
        };
        publish(MessageType::NBirth, nbirth)?;
        publish(MessageType::DBirth, dbirth)?;
        self.seq = 1;
        self.birth_ms = t_ms;
        Ok(())
    }
}

/// The `bdSeq` of the last connection a previous run made, if it left one.
fn read_bd_seq(dir: &Path) -> Option<u64> {
    std::fs::read_to_string(dir.join("bdseq")).ok()?.trim().parse().ok()
}

fn write_bd_seq(dir: &Path, bd_seq: u64) -> std::io::Result<()> {
    std::fs::write(dir.join("bdseq"), format!("{bd_seq}\n"))
}
