//! The events the OPC UA server sends: one `BlowCompletedEventType` per blow, a consistent
//! snapshot of that blow's result (every field from the one `BlowEstimate`, so a client
//! never sees the energy of one blow beside the load of the next), and the
//! `AlarmConditionType` (OPC 10000-9 §5.8) events of the alert conditions. The event
//! type's fields are forgemon's (namespace [`super::model::FORGEMON_NS`]); the condition
//! events use the standard type as async-opcua generates it.

use opcua::core_namespace::events::AlarmConditionType;
use opcua::nodes::{BaseEventType, Event};
use opcua::types::{
    AttributeId, ByteString, DateTime, EventField, LocalizedText, NamespaceMap, NodeId, NumericRange, ObjectTypeId,
    QualifiedName, UAString, Variant,
};

use crate::estimate::BlowEstimate;
use crate::estimate::billet_book::Trace;

/// `BlowCompletedEventType` (forgemon namespace, `s=BlowCompletedEventType`): one per
/// blow. Each field is a property of the type of the same browse name, in Pascal case
/// (`PlasticEnergy`); a value the blow does not have (an incomplete blow's energies, a
/// height without a process sheet) is left empty.
#[derive(Debug, opcua::Event)]
#[opcua(identifier = "s=BlowCompletedEventType", namespace = "urn:forgemon:UA")]
pub struct BlowCompletedEvent {
    pub base: BaseEventType,
    pub own_namespace_index: u16,
    /// The blow's number since the service started (the cycle counter's value).
    pub blow_number: u32,
    /// The billet's number and the blow's number on it.
    pub billet_number: u32,
    pub billet_blow: u32,
    /// `soft`, `intermediate`, `hard` or `incomplete` (docs/interfaces.md §5 `class`).
    pub blow_class: UAString,
    /// m/s.
    pub impact_velocity: f64,
    /// J: the kinetic energy brought into the blow.
    pub impact_energy: Option<f64>,
    /// J.
    pub plastic_energy: Option<f64>,
    /// Plastic over impact energy, 0–1.
    pub efficiency: Option<f64>,
    /// N.
    pub peak_load: f64,
    /// m, after the blow.
    pub billet_height: Option<f64>,
    /// The alert the blow raised (`elastic_blow`, ...), empty when none.
    pub alert: UAString,
    /// What the blow was forged as (OPC 40503's PartId; `[part]`, `POST /billet`, the PLC's
    /// part block, `SetPart`), empty when not given.
    pub part_id: UAString,
    pub lot: UAString,
    pub die_set: UAString,
    /// Metal Forming's `CyclicEventType` field: the blow number again.
    pub cycle_count: u32,
}

/// The fields of [`BlowCompletedEvent`] as browse names, in order (the type's properties).
pub const BLOW_EVENT_FIELDS: [&str; 14] = [
    "BlowNumber",
    "BilletNumber",
    "BilletBlow",
    "BlowClass",
    "ImpactVelocity",
    "ImpactEnergy",
    "PlasticEnergy",
    "Efficiency",
    "PeakLoad",
    "BilletHeight",
    "Alert",
    "PartId",
    "Lot",
    "DieSet",
];

impl BlowCompletedEvent {
    /// The event of blow `b` forged as `part`, from `source` (the working unit) named
    /// `source_name`, in the forgemon namespace `ns`.
    pub fn of(b: &BlowEstimate, part: &Trace, ns: u16, source: &NodeId, source_name: &str) -> Self {
        let message = format!("blow {} on billet {}: {}", b.blow, b.billet.billet, b.class.as_str());
        let base = BaseEventType::new(Self::event_type_id_from_index(ns), event_id(), message, DateTime::now())
            .set_source_node(source.clone())
            .set_source_name(source_name.into())
            .set_severity(if b.alert.is_some() { 500 } else { 100 });
        BlowCompletedEvent {
            base,
            own_namespace_index: ns,
            blow_number: b.blow,
            billet_number: b.billet.billet,
            billet_blow: b.billet.billet_blow,
            blow_class: b.class.as_str().into(),
            impact_velocity: b.v_impact_mps,
            impact_energy: b.kinetic_in_j,
            plastic_energy: b.plastic_j,
            efficiency: b.efficiency,
            peak_load: b.peak_load_n,
            billet_height: b.h_end_m,
            alert: b.alert.as_ref().map(|a| a.kind.as_str()).unwrap_or_default().into(),
            part_id: part.part_id.as_deref().unwrap_or_default().into(),
            lot: part.lot.as_deref().unwrap_or_default().into(),
            die_set: part.die_set.as_deref().unwrap_or_default().into(),
            cycle_count: b.blow,
        }
    }
}

/// A blow's event as the server sends it: when the blow event type is a subtype of Metal
/// Forming's `CyclicEventType` (`cyclic`), a select clause that names that type
/// (`CyclicEventType`/`PartId`, `CyclicEventType`/`CycleCount`) is answered too, where the
/// derived impl answers only its own type's and BaseEventType's.
pub struct BlowEvent {
    pub event: BlowCompletedEvent,
    pub cyclic: Option<NodeId>,
}

impl EventField for BlowEvent {
    fn get_value(
        &self,
        attribute_id: AttributeId,
        index_range: &NumericRange,
        browse_path: &[QualifiedName],
    ) -> Variant {
        self.event.get_value(attribute_id, index_range, browse_path)
    }
}

impl Event for BlowEvent {
    fn get_field(
        &self,
        type_definition_id: &NodeId,
        attribute_id: AttributeId,
        index_range: &NumericRange,
        browse_path: &[QualifiedName],
    ) -> Variant {
        if self.cyclic.as_ref() == Some(type_definition_id) {
            return self.event.get_value(attribute_id, index_range, browse_path);
        }
        self.event.get_field(type_definition_id, attribute_id, index_range, browse_path)
    }

    fn time(&self) -> &DateTime {
        self.event.time()
    }

    fn event_type_id(&self) -> &NodeId {
        self.event.event_type_id()
    }
}

/// A fresh EventId (OPC 10000-5 §6.4.2: unique per event), 16 random bytes.
pub fn event_id() -> ByteString {
    opcua::crypto::random::byte_string(16)
}

/// What a condition event says about its condition.
#[derive(Debug, Clone)]
pub struct ConditionState {
    pub event_id: ByteString,
    pub active: bool,
    pub acked: bool,
    pub message: String,
    pub severity: u16,
}

/// Where a condition is: its node, its name, the source it belongs to and the process value
/// it watches.
#[derive(Debug, Clone)]
pub struct ConditionPlace {
    pub node: NodeId,
    pub name: String,
    pub source: NodeId,
    pub source_name: String,
    pub input_node: NodeId,
}

/// The `AlarmConditionType` event that reports `state` of the condition at `place`
/// (OPC 10000-9 §5.5: `Retain` while active or unacknowledged).
pub fn condition_event(place: &ConditionPlace, state: &ConditionState) -> AlarmConditionType {
    let mut e = AlarmConditionType::new_event(
        NodeId::from(ObjectTypeId::AlarmConditionType),
        state.event_id.clone(),
        LocalizedText::from(state.message.as_str()),
        &NamespaceMap::new(),
        DateTime::now(),
    );
    let ack = &mut e.base;
    ack.acked_state.id = state.acked;
    ack.acked_state.base.value = if state.acked { "Acknowledged" } else { "Unacknowledged" }.into();
    let cond = &mut ack.base;
    cond.condition_name = place.name.as_str().into();
    cond.condition_class_id = ObjectTypeId::ProcessConditionClassType.into();
    cond.condition_class_name = "ProcessConditionClassType".into();
    cond.retain = state.active || !state.acked;
    cond.enabled_state.id = true;
    cond.enabled_state.base.value = "Enabled".into();
    cond.base.source_node = place.source.clone();
    cond.base.source_name = place.source_name.as_str().into();
    cond.base.severity = state.severity;
    e.active_state.id = state.active;
    e.active_state.base.value = if state.active { "Active" } else { "Inactive" }.into();
    e.input_node = place.input_node.clone();
    e
}

/// The event as the subscription cache takes it.
pub fn as_dyn(e: &impl Event) -> &dyn Event {
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(e: &dyn Event, path: &[(u16, &str)]) -> Variant {
        let path: Vec<QualifiedName> = path.iter().map(|(ns, n)| QualifiedName::new(*ns, *n)).collect();
        e.get_field(&ObjectTypeId::BaseEventType.into(), AttributeId::Value, &NumericRange::None, &path)
    }

    fn complete_blow() -> BlowEstimate {
        crate::estimate::result::examples::intermediate()
    }

    /// Every property the event type declares (`model.rs` builds them from
    /// `BLOW_EVENT_FIELDS`) is a field the event answers; a name it does not declare is empty.
    #[test]
    fn the_blow_event_answers_every_declared_field() {
        let b = complete_blow();
        let part = Trace { part_id: Some("P-1".into()), lot: Some("4711".into()), die_set: Some("17".into()) };
        let e = BlowCompletedEvent::of(&b, &part, 3, &NodeId::new(2, "unit"), "Hammer");
        for name in BLOW_EVENT_FIELDS {
            assert_ne!(field(&e, &[(3, name)]), Variant::Empty, "{name}");
        }
        assert_eq!(field(&e, &[(3, "PlasticEnergy")]), Variant::from(7_195.6));
        assert_eq!(field(&e, &[(3, "BlowNumber")]), Variant::from(7u32));
        assert_eq!(field(&e, &[(3, "PartId")]), Variant::from("P-1"));
        assert_eq!(field(&e, &[(0, "EventType")]), Variant::from(NodeId::new(3, "BlowCompletedEventType")));
        assert_eq!(field(&e, &[(3, "NoSuchField")]), Variant::Empty);
        // An incomplete blow has no energies: empty, not zero.
        let e = BlowCompletedEvent::of(&BlowEstimate { plastic_j: None, ..b }, &part, 3, &NodeId::null(), "Hammer");
        assert_eq!(field(&e, &[(3, "PlasticEnergy")]), Variant::Empty);
    }

    /// With Metal Forming loaded, a select clause naming `CyclicEventType` is answered: its
    /// `PartId` and `CycleCount`; naming another type still gives nothing.
    #[test]
    fn the_blow_event_answers_as_a_cyclic_event() {
        let part = Trace { part_id: Some("P-1".into()), ..Trace::default() };
        let cyclic = NodeId::new(7, 1016u32);
        let event = BlowCompletedEvent::of(&complete_blow(), &part, 3, &NodeId::new(2, "unit"), "Hammer");
        let e = BlowEvent { event, cyclic: Some(cyclic.clone()) };
        let at = |ty: &NodeId, name: &str| {
            e.get_field(ty, AttributeId::Value, &NumericRange::None, &[QualifiedName::new(7, name)])
        };
        assert_eq!(at(&cyclic, "PartId"), Variant::from("P-1"));
        assert_eq!(at(&cyclic, "CycleCount"), Variant::from(7u32));
        assert_eq!(at(&NodeId::new(7, 1099u32), "PartId"), Variant::Empty);
        let e = BlowEvent { cyclic: None, ..e };
        assert_eq!(
            e.get_field(&cyclic, AttributeId::Value, &NumericRange::None, &[QualifiedName::new(7, "PartId")]),
            Variant::Empty
        );
    }

    /// OPC 10000-9 §5.5: a condition is retained while active or unacknowledged.
    #[test]
    fn condition_events_carry_their_states_and_retain() {
        let place = ConditionPlace {
            node: NodeId::new(3, "ElasticBlowAlarm"),
            name: "ElasticBlowAlarm".into(),
            source: NodeId::new(2, "unit"),
            source_name: "Hammer".into(),
            input_node: NodeId::new(3, "Efficiency"),
        };
        for (active, acked, retain) in [(true, false, true), (false, true, false), (false, false, true)] {
            let s = ConditionState { event_id: event_id(), active, acked, message: "m".into(), severity: 700 };
            let e = condition_event(&place, &s);
            assert_eq!(field(&e, &[(0, "ActiveState"), (0, "Id")]), Variant::from(active));
            assert_eq!(field(&e, &[(0, "AckedState"), (0, "Id")]), Variant::from(acked));
            assert_eq!(field(&e, &[(0, "Retain")]), Variant::from(retain));
            assert_eq!(field(&e, &[(0, "EventId")]), Variant::from(s.event_id.clone()));
            assert_eq!(field(&e, &[(0, "ConditionName")]), Variant::from("ElasticBlowAlarm"));
        }
    }
}
