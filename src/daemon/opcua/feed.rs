//! The OPC UA server's feed from the service: each blow on the live feed (`live.rs`)
//! writes the working unit's process values and sends one `BlowCompletedEventType` event,
//! both from the same `BlowEstimate`; an alert raises its condition (active,
//! unacknowledged), and the service's `Acknowledged` (from any front end: `POST /ack`, the
//! PLC's coil 0, a condition's `Acknowledge` method here) acknowledges every raised
//! condition. The `Acknowledge` method only asks the service ([`Control::Acknowledge`]);
//! the condition changes when the service says it did, as every front end sees it.

use std::sync::{Arc, Mutex};

use opcua::server::SubscriptionCache;
use opcua::server::node_manager::memory::SimpleNodeManager;
use opcua::types::{DataValue, LocalizedText, NodeId, ObjectId, StatusCode, Variant};
use tokio::sync::{broadcast, mpsc};

use super::events::{BlowCompletedEvent, BlowEvent, ConditionPlace, ConditionState, as_dyn, condition_event, event_id};
use super::model::Nodes;
use crate::config::history::{TraceUpdate, check_id};
use crate::daemon::Control;
use crate::daemon::live::LiveEvent;
use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::Trace;
use crate::estimate::result::AlertKind;

/// The conditions' states, in the order of `Nodes::conditions`.
pub type Conditions = Arc<Mutex<Vec<ConditionState>>>;

/// Every condition inactive and acknowledged (nothing raised yet).
pub fn quiet_conditions(nodes: &Nodes) -> Conditions {
    let quiet = |severity| ConditionState {
        event_id: event_id(),
        active: false,
        acked: true,
        message: String::new(),
        severity,
    };
    Arc::new(Mutex::new(nodes.conditions.iter().map(|c| quiet(c.severity)).collect()))
}

/// What the feed writes to.
pub struct Feed {
    pub manager: Arc<SimpleNodeManager>,
    pub subscriptions: Arc<SubscriptionCache>,
    pub nodes: Nodes,
    pub conditions: Conditions,
    /// What the blows are forged as: the last status snapshot's (published just before each
    /// blow, after the billet's change).
    pub part: Trace,
}

impl Feed {
    /// Follow the live feed until the service stops.
    pub async fn run(mut self, mut live: broadcast::Receiver<LiveEvent>) {
        // Fell behind the bus: the next status snapshot has the last blow.
        let mut behind = false;
        loop {
            match live.recv().await {
                Ok(LiveEvent::Blow(b)) => self.on_blow(&b),
                Ok(LiveEvent::Acknowledged) => self.on_acknowledged(),
                Ok(LiveEvent::Billet(_) | LiveEvent::NewBillet | LiveEvent::Advice(_) | LiveEvent::Alert { .. }) => {}
                Ok(LiveEvent::Status(s)) => {
                    self.part = s.part.clone();
                    if let Some(b) = s.last_blow.as_ref().filter(|_| std::mem::take(&mut behind)) {
                        self.write_values(b);
                    }
                }
                Ok(LiveEvent::Stopping) => break,
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    // The events of the blows missed are lost; the values show the last blow
                    // from the next snapshot.
                    tracing::warn!(events = n, "OPC UA server fell behind the live feed");
                    behind = true;
                }
                Err(broadcast::error::RecvError::Closed) => break,
            }
        }
    }

    /// A blow: its values, its event, and its alert's condition.
    pub fn on_blow(&self, b: &BlowEstimate) {
        self.write_values(b);
        let (ns, unit, name) = (self.nodes.forgemon_ns, &self.nodes.working_unit, &self.nodes.machine_name);
        let event = BlowCompletedEvent::of(b, &self.part, ns, unit, name);
        let e = BlowEvent { event, cyclic: self.nodes.cyclic_event_type.clone() };
        self.notify(as_dyn(&e));
        if let Some(a) = &b.alert {
            self.raise(a.kind, &format!("blow {}: {}", a.blow, a.reason));
        }
    }

    /// The working unit's process values from blow `b`, with one timestamp.
    fn write_values(&self, b: &BlowEstimate) {
        let opt = |x: Option<f64>| x.map_or(Variant::Empty, Variant::from);
        let text = |x: &Option<String>| Variant::from(x.as_deref().unwrap_or_default());
        let values: [(&str, Variant); 13] = [
            ("CycleCounter", b.blow.into()),
            ("PeakLoad", b.peak_load_n.into()),
            ("BilletHeight", opt(b.h_end_m)),
            ("BilletCounter", b.billet.billet.into()),
            ("BlowClass", b.class.as_str().into()),
            ("ImpactVelocity", b.v_impact_mps.into()),
            ("ImpactEnergy", opt(b.kinetic_in_j)),
            ("PlasticEnergy", opt(b.plastic_j)),
            ("Efficiency", opt(b.efficiency)),
            ("LastAlert", b.alert.as_ref().map(|a| a.kind.as_str()).unwrap_or_default().into()),
            ("PartId", text(&self.part.part_id)),
            ("Lot", text(&self.part.lot)),
            ("DieSet", text(&self.part.die_set)),
        ];
        let mut writes: Vec<(&NodeId, Variant)> =
            values.into_iter().filter_map(|(name, v)| self.nodes.value(name).map(|id| (id, v))).collect();
        if b.alert.is_some()
            && let Some(id) = self.nodes.value("AlertLatched")
        {
            writes.push((id, true.into()));
        }
        self.set(writes);
    }

    /// Write `writes` with one source timestamp (a node that is not a value of ours is an
    /// error of this module, logged).
    fn set(&self, writes: Vec<(&NodeId, Variant)>) {
        let now = opcua::types::DateTime::now();
        let values = writes.into_iter().map(|(id, v)| {
            let dv = DataValue {
                value: Some(v),
                status: Some(StatusCode::Good),
                source_timestamp: Some(now),
                server_timestamp: Some(now),
                ..Default::default()
            };
            (id, None, dv)
        });
        if let Err(e) = self.manager.set_values(&self.subscriptions, values) {
            tracing::error!("OPC UA: writing the process values failed: {e}");
        }
    }

    /// An alert of `kind`: its condition active and unacknowledged, with a new EventId.
    fn raise(&self, kind: AlertKind, message: &str) {
        let Some(i) = self.nodes.conditions.iter().position(|c| c.kind == kind) else { return };
        let state = {
            let mut all = self.conditions.lock().unwrap_or_else(|p| p.into_inner());
            let s = &mut all[i];
            *s = ConditionState {
                event_id: event_id(),
                active: true,
                acked: false,
                message: message.to_string(),
                severity: s.severity,
            };
            s.clone()
        };
        self.publish_condition(i, &state);
    }

    /// The service acknowledged its latched alert: every raised condition acknowledged
    /// and inactive (each blow's alert is over when the operator has seen it).
    pub fn on_acknowledged(&self) {
        let changed: Vec<(usize, ConditionState)> = {
            let mut all = self.conditions.lock().unwrap_or_else(|p| p.into_inner());
            all.iter_mut()
                .enumerate()
                .filter(|(_, s)| !s.acked || s.active)
                .map(|(i, s)| {
                    *s = ConditionState {
                        event_id: event_id(),
                        active: false,
                        acked: true,
                        message: format!("{} acknowledged", s.message),
                        severity: s.severity,
                    };
                    (i, s.clone())
                })
                .collect()
        };
        for (i, s) in &changed {
            self.publish_condition(*i, s);
        }
        if let Some(id) = self.nodes.value("AlertLatched") {
            self.set(vec![(id, false.into())]);
        }
    }

    /// Condition `i`'s variables and its event.
    fn publish_condition(&self, i: usize, s: &ConditionState) {
        let c = &self.nodes.conditions[i];
        let active = if s.active { "Active" } else { "Inactive" };
        let acked = if s.acked { "Acknowledged" } else { "Unacknowledged" };
        self.set(vec![
            (&c.active_state, LocalizedText::from(active).into()),
            (&c.acked_state, LocalizedText::from(acked).into()),
            (&c.active_id, s.active.into()),
            (&c.acked_id, s.acked.into()),
            (&c.retain, (s.active || !s.acked).into()),
        ]);
        let place = ConditionPlace {
            node: c.node.clone(),
            name: c.name.to_string(),
            source: self.nodes.working_unit.clone(),
            source_name: self.nodes.machine_name.clone(),
            input_node: self.nodes.value("Efficiency").cloned().unwrap_or_default(),
        };
        let e = condition_event(&place, s);
        self.notify(as_dyn(&e));
    }

    /// `e` to the subscribers of the Server object, the machine and the working unit.
    fn notify(&self, e: &dyn opcua::nodes::Event) {
        let server: NodeId = ObjectId::Server.into();
        let to = [&server, &self.nodes.machine, &self.nodes.working_unit];
        self.subscriptions.notify_events(to.into_iter().map(|n| (e, n)));
    }
}

/// A condition's `Acknowledge(EventId, Comment)` (OPC 10000-9 §5.7.3): the EventId must be
/// the condition's last event's, and the condition not yet acknowledged; then the service
/// is asked to acknowledge.
pub fn acknowledge(
    conditions: &Conditions,
    i: usize,
    control: &mpsc::Sender<Control>,
    args: &[Variant],
) -> Result<Vec<Variant>, StatusCode> {
    let Some(Variant::ByteString(id)) = args.first() else { return Err(StatusCode::BadArgumentsMissing) };
    {
        let all = conditions.lock().unwrap_or_else(|p| p.into_inner());
        let Some(s) = all.get(i) else { return Err(StatusCode::BadMethodInvalid) };
        if &s.event_id != id {
            return Err(StatusCode::BadEventIdUnknown);
        }
        if s.acked {
            return Err(StatusCode::BadConditionBranchAlreadyAcked);
        }
    }
    control.try_send(Control::Acknowledge).map_err(|_| StatusCode::BadResourceUnavailable)?;
    tracing::info!(condition = i, "OPC UA: Acknowledge");
    Ok(Vec::new())
}

/// A text argument of `SetPart`/`ChangeDies`: empty keeps the value in force; otherwise it
/// must be an id as `[part]`'s (1–32 characters, no leading or trailing space).
fn id_arg(args: &[Variant], i: usize) -> Result<Option<Option<String>>, StatusCode> {
    match args.get(i) {
        None => Err(StatusCode::BadArgumentsMissing),
        Some(Variant::String(s)) if s.is_empty() => Ok(None),
        Some(Variant::String(s)) => {
            let s = s.as_ref();
            check_id(s).map_err(|_| StatusCode::BadInvalidArgument)?;
            Ok(Some(Some(s.to_string())))
        }
        Some(Variant::Empty) => Ok(None),
        Some(_) => Err(StatusCode::BadTypeMismatch),
    }
}

/// A method of the working unit that sends the service a control.
pub type PartMethod = fn(&mpsc::Sender<Control>, &[Variant]) -> Result<Vec<Variant>, StatusCode>;

/// `FM:SetPart(PartId, Lot, DieSet)`: a new billet, forged as given (as `POST /billet` with
/// a body, the PLC's coil 2).
pub fn set_part(control: &mpsc::Sender<Control>, args: &[Variant]) -> Result<Vec<Variant>, StatusCode> {
    let change = TraceUpdate { part_id: id_arg(args, 0)?, lot: id_arg(args, 1)?, die_set: id_arg(args, 2)? };
    control
        .try_send(Control::NewBilletAs { at_device_ns: None, change: Box::new(change) })
        .map_err(|_| StatusCode::BadResourceUnavailable)?;
    tracing::info!("OPC UA: SetPart");
    Ok(Vec::new())
}

/// `FM:ChangeDies(DieSet)`: the dies were changed (as `POST /die`, the PLC's coil 3).
pub fn change_dies(control: &mpsc::Sender<Control>, args: &[Variant]) -> Result<Vec<Variant>, StatusCode> {
    let change = TraceUpdate { die_set: id_arg(args, 0)?, ..TraceUpdate::default() };
    control.try_send(Control::DieChange(Box::new(change))).map_err(|_| StatusCode::BadResourceUnavailable)?;
    tracing::info!("OPC UA: ChangeDies");
    Ok(Vec::new())
}
