//! The address space of the OPC UA server: the machine modelled after OPC 40001-1
//! (Machinery: the `Machines` folder, a machine with its `Identification`) and OPC 40503-1
//! (Metal Forming: the forming working unit with its cycle counter and process values),
//! as far as they fit a hammer or a screw press. The nodes that follow them keep the
//! specifications' browse names in a namespace of forgemon's own ([`MODEL_NS`]); the values
//! the specifications have no place for (energies, efficiency, blow class, billet counter,
//! the per-blow event type) are in the forgemon namespace ([`FORGEMON_NS`]). docs/guide.md
//! "OPC UA server" lists which is which. When the companion NodeSet2 files are loaded
//! ([`Companion`], `[opcua] nodesets_dir`), the same nodes are instances of the companion
//! types: the machine a `MachineToolType` in Machinery's `Machines` folder, its working unit
//! a `FormingProcessWorkingUnitType`, the blow event a `CyclicEventType`, each with the
//! mandatory children its type declares (`instance.rs`). Pure construction: no IO, no clock.

use opcua::nodes::{
    AccessLevel, EventNotifier, MethodBuilder, NodeType, ObjectBuilder, ObjectTypeBuilder, TypeTree, VariableBuilder,
};
use opcua::server::address_space::AddressSpace;
use opcua::types::{
    Argument, DataTypeId, DateTime, EUInformation, ExtensionObject, LocalizedText, NodeId, ObjectId, ObjectTypeId,
    QualifiedName, ReferenceTypeId, VariableTypeId, Variant,
};

use super::events::BLOW_EVENT_FIELDS;
use super::instance;
use crate::estimate::result::AlertKind;
use crate::physics::machine::MachineKind;

/// Nodes named after OPC 40001-1 and OPC 40503-1 (the structure the specifications
/// describe, not their NodeSets).
pub const MODEL_NS: &str = "urn:forgemon:UA:MetalForming";
/// forgemon's own nodes, types and event fields.
pub const FORGEMON_NS: &str = "urn:forgemon:UA";

/// The alert conditions, one per kind of alert, with the browse name of their node and
/// their severity (OPC 10000-5 §6.4.2: 1–1000).
pub const CONDITIONS: [(AlertKind, &str, u16); 4] = [
    (AlertKind::ElasticBlow, "ElasticBlowAlarm", 700),
    (AlertKind::Nok, "NokAlarm", 600),
    (AlertKind::ModelHealth, "ModelHealthAlarm", 500),
    (AlertKind::Sensor, "SensorAlarm", 500),
];

/// A unit of UN/CEFACT Recommendation 20 as OPC 10000-8 §5.6.3 names it: the common code,
/// the symbol shown, the description.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unece {
    pub code: &'static str,
    pub symbol: &'static str,
    pub description: &'static str,
}

/// OPC 10000-8 §5.6.3: the namespace of the UNECE units.
pub const UNECE_NAMESPACE: &str = "http://www.opcfoundation.org/UA/units/un/cefact";

impl Unece {
    /// The unit's `UnitId`: its common code's characters as bytes of an Int32, the first the
    /// most significant (OPC 10000-8 §5.6.3).
    pub fn unit_id(&self) -> i32 {
        self.code.bytes().fold(0i32, |id, c| (id << 8) | i32::from(c))
    }

    /// The `EngineeringUnits` value.
    pub fn eu_information(&self) -> EUInformation {
        EUInformation {
            namespace_uri: UNECE_NAMESPACE.into(),
            unit_id: self.unit_id(),
            display_name: LocalizedText::new("en", self.symbol),
            description: LocalizedText::new("en", self.description),
        }
    }
}

const NEWTON: Unece = Unece { code: "NEW", symbol: "N", description: "newton" };
const METRE: Unece = Unece { code: "MTR", symbol: "m", description: "metre" };
const METRE_PER_SECOND: Unece = Unece { code: "MTS", symbol: "m/s", description: "metre per second" };
const JOULE: Unece = Unece { code: "JOU", symbol: "J", description: "joule" };
/// A count or a ratio: "one".
const ONE: Unece = Unece { code: "C62", symbol: "1", description: "one" };

/// A process value: browse name, namespace (true: forgemon's), data type, unit (the
/// `FM:Unit` text and the standard's `EngineeringUnits`).
struct ValueSpec {
    name: &'static str,
    forgemon: bool,
    data_type: DataTypeId,
    unit: &'static str,
    unece: Option<Unece>,
}

const fn value(
    name: &'static str,
    forgemon: bool,
    data_type: DataTypeId,
    unit: &'static str,
    unece: Option<Unece>,
) -> ValueSpec {
    ValueSpec { name, forgemon, data_type, unit, unece }
}

/// The working unit's per-blow values, written on every blow (`feed.rs`); the part, lot and
/// die set the blow was forged as (issue 44).
const VALUES: [ValueSpec; 14] = [
    value("CycleCounter", false, DataTypeId::UInt32, "blows", Some(ONE)),
    value("PeakLoad", false, DataTypeId::Double, "N", Some(NEWTON)),
    value("BilletHeight", false, DataTypeId::Double, "m", Some(METRE)),
    value("BilletCounter", true, DataTypeId::UInt32, "billets", Some(ONE)),
    value("BlowClass", true, DataTypeId::String, "", None),
    value("ImpactVelocity", true, DataTypeId::Double, "m/s", Some(METRE_PER_SECOND)),
    value("ImpactEnergy", true, DataTypeId::Double, "J", Some(JOULE)),
    value("PlasticEnergy", true, DataTypeId::Double, "J", Some(JOULE)),
    value("Efficiency", true, DataTypeId::Double, "1", Some(ONE)),
    value("LastAlert", true, DataTypeId::String, "", None),
    value("AlertLatched", true, DataTypeId::Boolean, "", None),
    value("PartId", true, DataTypeId::String, "", None),
    value("Lot", true, DataTypeId::String, "", None),
    value("DieSet", true, DataTypeId::String, "", None),
];

/// The companion specifications' namespaces in the server, when their NodeSet2 files are
/// loaded (`nodesets.rs`), and the types forgemon's nodes are instances of.
#[derive(Debug, Clone)]
pub struct Companion {
    /// Machinery's `Machines` folder (OPC 40001-1 §9.2, `i=1001`).
    pub machines: NodeId,
    /// `MachineToolType` (OPC 40501-1, `i=13`).
    pub machine_type: NodeId,
    /// `FormingProcessWorkingUnitType` (Metal Forming, `i=1008`).
    pub working_unit_type: NodeId,
    /// `CyclicEventType` (Metal Forming, `i=1016`): the blow event's supertype.
    pub cyclic_event_type: NodeId,
}

impl Companion {
    /// The nodes in the namespaces `machinery`, `machine_tool` and `metal_forming`.
    pub fn new(machinery: u16, machine_tool: u16, metal_forming: u16) -> Self {
        Companion {
            machines: NodeId::new(machinery, 1001u32),
            machine_type: NodeId::new(machine_tool, 13u32),
            working_unit_type: NodeId::new(metal_forming, 1008u32),
            cyclic_event_type: NodeId::new(metal_forming, 1016u32),
        }
    }

    /// Each node with the browse name the specifications give it.
    pub fn expected(&self) -> [(&NodeId, &'static str); 4] {
        [
            (&self.machines, "Machines"),
            (&self.machine_type, "MachineToolType"),
            (&self.working_unit_type, "FormingProcessWorkingUnitType"),
            (&self.cyclic_event_type, "CyclicEventType"),
        ]
    }
}

/// The ids of the nodes the feed writes and the events name.
#[derive(Debug, Clone)]
pub struct Nodes {
    pub model_ns: u16,
    pub forgemon_ns: u16,
    pub machine: NodeId,
    pub machine_name: String,
    pub working_unit: NodeId,
    /// Metal Forming's `CyclicEventType`, the blow event's supertype, when loaded.
    pub cyclic_event_type: Option<NodeId>,
    /// A process value's node by its browse name.
    values: Vec<(&'static str, NodeId)>,
    /// Each condition: kind, node, browse name, severity, its `Acknowledge` method and its
    /// state variables' `Id` (`ActiveState/Id`, `AckedState/Id`) and `Retain`.
    pub conditions: Vec<ConditionNodes>,
    /// The working unit's `SetPart` and `ChangeDies` methods.
    pub set_part: NodeId,
    pub change_dies: NodeId,
}

/// A condition's nodes.
#[derive(Debug, Clone)]
pub struct ConditionNodes {
    pub kind: AlertKind,
    pub node: NodeId,
    pub name: &'static str,
    pub severity: u16,
    pub acknowledge: NodeId,
    pub active_state: NodeId,
    pub acked_state: NodeId,
    pub active_id: NodeId,
    pub acked_id: NodeId,
    pub retain: NodeId,
}

impl Nodes {
    /// The node of the process value `name` (one of [`VALUES`]).
    pub fn value(&self, name: &str) -> Option<&NodeId> {
        self.values.iter().find(|(n, _)| *n == name).map(|(_, id)| id)
    }
}

/// The machine's browse name: what it is.
fn machine_name(kind: MachineKind) -> &'static str {
    match kind {
        MachineKind::Hammer => "Hammer",
        MachineKind::ScrewPress => "ScrewPress",
    }
}

/// Where a variable hangs: a property of its parent, or a component of a variable type
/// (BaseDataVariableType or a subtype).
#[derive(Debug, Clone, Copy)]
enum Place {
    Property,
    Component(VariableTypeId),
}

const PROPERTY: Place = Place::Property;
const COMPONENT: Place = Place::Component(VariableTypeId::BaseDataVariableType);

/// A read-only variable `name` (`ns`) with `value`, placed under `parent` as `place` says.
fn variable(
    space: &mut AddressSpace,
    id: &NodeId,
    name: QualifiedName,
    value: impl Into<Variant>,
    data_type: DataTypeId,
    parent: &NodeId,
    place: Place,
) {
    let display = LocalizedText::from(name.name.as_ref());
    let b = VariableBuilder::new(id, name, display)
        .value(value)
        .data_type(data_type)
        .access_level(AccessLevel::CURRENT_READ)
        .user_access_level(AccessLevel::CURRENT_READ);
    match place {
        Place::Property => b.property_of(parent.clone()).has_type_definition(VariableTypeId::PropertyType),
        Place::Component(ty) => b.component_of(parent.clone()).has_type_definition(ty),
    }
    .insert(space);
}

/// The value a process value holds before the first blow.
fn initial(data_type: DataTypeId) -> Variant {
    match data_type {
        DataTypeId::UInt32 => Variant::from(0u32),
        DataTypeId::Boolean => Variant::from(false),
        DataTypeId::String => Variant::from(""),
        _ => Variant::Empty,
    }
}

/// The companion types and the type tree to read them with, when the NodeSet2 files are
/// loaded.
pub type Types<'a> = Option<(&'a Companion, &'a dyn TypeTree)>;

/// The object `path` (node id; its last `.`-part is its browse name) under `parent` (by
/// `reference`): a BaseObjectType, or with the companion types an instance of
/// `companion_ty` with its mandatory children.
fn object(
    space: &mut AddressSpace,
    types: Types<'_>,
    ns: u16,
    path: &str,
    parent: &NodeId,
    reference: ReferenceTypeId,
    companion_ty: impl Fn(&Companion) -> &NodeId,
) -> NodeId {
    let id = NodeId::new(ns, path.to_string());
    let name = path.rsplit('.').next().unwrap_or(path);
    let ty = types.map_or_else(|| ObjectTypeId::BaseObjectType.into(), |(c, _)| companion_ty(c).clone());
    ObjectBuilder::new(&id, QualifiedName::new(ns, name), name)
        .has_type_definition(ty.clone())
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .insert(space);
    space.insert_reference(parent, &id, reference);
    if let Some((_, tt)) = types {
        instance::Instances { space, tt, ns }.add_mandatory(&id, path, &ty);
    }
    id
}

/// Build the machine's nodes into `space` (whose namespaces `model_ns` and `forgemon_ns`
/// are this server's), for a machine of `kind`; as instances of the companion types when
/// `types` is given.
pub fn build(space: &mut AddressSpace, model_ns: u16, forgemon_ns: u16, kind: MachineKind, types: Types<'_>) -> Nodes {
    let m = |s: &str| NodeId::new(model_ns, s.to_string());
    let f = |s: &str| NodeId::new(forgemon_ns, s.to_string());
    let name = machine_name(kind);

    blow_event_type(space, forgemon_ns, types.map(|(c, _)| &c.cyclic_event_type));
    let machines = match types {
        Some((c, _)) => c.machines.clone(),
        None => {
            let machines = m("Machines");
            let (browse, objects) = (QualifiedName::new(model_ns, "Machines"), ObjectId::ObjectsFolder.into());
            space.add_folder(&machines, browse, "Machines", &objects);
            machines
        }
    };
    let machine = object(space, types, model_ns, name, &machines, ReferenceTypeId::Organizes, |c| &c.machine_type);
    // The Server object is the root notifier: a machine's events reach it too.
    space.insert_reference(&ObjectId::Server.into(), &machine, ReferenceTypeId::HasNotifier);
    identification(space, types, model_ns, &machine, name, kind);

    let path = format!("{name}.FormingWorkingUnit");
    let component = ReferenceTypeId::HasComponent;
    let unit = object(space, types, model_ns, &path, &machine, component, |c| &c.working_unit_type);
    space.insert_reference(&machine, &unit, ReferenceTypeId::HasEventSource);
    // MachineTool's ElementMonitoringType names its element (mandatory `Name`).
    set_text(space, &NodeId::new(model_ns, format!("{path}.Name")), "FormingWorkingUnit");
    let mut values = Vec::new();
    for v in &VALUES {
        let (ns, id) = if v.forgemon { (forgemon_ns, f(v.name)) } else { (model_ns, m(v.name)) };
        // A Double with units is an AnalogUnitType (OPC 10000-8 §5.3.2), whose mandatory
        // property `engineering_units` adds.
        let analog = v.unece.is_some() && v.data_type == DataTypeId::Double;
        let ty = if analog { VariableTypeId::AnalogUnitType } else { VariableTypeId::BaseDataVariableType };
        let name = QualifiedName::new(ns, v.name);
        variable(space, &id, name, initial(v.data_type), v.data_type, &unit, Place::Component(ty));
        if !v.unit.is_empty() {
            let eu = NodeId::new(ns, format!("{}.Unit", v.name));
            variable(space, &eu, QualifiedName::new(forgemon_ns, "Unit"), v.unit, DataTypeId::String, &id, PROPERTY);
        }
        if let Some(u) = v.unece {
            engineering_units(space, &id, ns, v.name, u);
        }
        values.push((v.name, id));
    }
    let methods = part_methods(space, forgemon_ns, &unit);
    let input = f("Efficiency");
    let conditions = CONDITIONS
        .iter()
        .map(|&(kind, cname, severity)| condition(space, forgemon_ns, &unit, &input, kind, cname, severity))
        .collect();
    Nodes {
        model_ns,
        forgemon_ns,
        machine,
        machine_name: name.to_string(),
        working_unit: unit,
        cyclic_event_type: types.map(|(c, _)| c.cyclic_event_type.clone()),
        values,
        conditions,
        set_part: methods.0,
        change_dies: methods.1,
    }
}

/// `EngineeringUnits` (OPC 10000-8 §5.3.2: an `EUInformation`) of the value `id`.
fn engineering_units(space: &mut AddressSpace, id: &NodeId, ns: u16, name: &str, u: Unece) {
    let eu = NodeId::new(ns, format!("{name}.EngineeringUnits"));
    let value = Variant::from(ExtensionObject::from_message(u.eu_information()));
    variable(space, &eu, QualifiedName::new(0, "EngineeringUnits"), value, DataTypeId::EUInformation, id, PROPERTY);
}

/// The text arguments of a method: name and description.
fn string_args(names: &[(&str, &str)]) -> Vec<Argument> {
    names
        .iter()
        .map(|(name, description)| Argument {
            name: (*name).into(),
            data_type: DataTypeId::String.into(),
            value_rank: -1,
            array_dimensions: None,
            description: (*description).into(),
        })
        .collect()
}

/// The working unit's methods `FM:SetPart(PartId, Lot, DieSet)` (a new billet, forged as
/// given) and `FM:ChangeDies(DieSet)` (a die change): their node ids.
fn part_methods(space: &mut AddressSpace, ns: u16, unit: &NodeId) -> (NodeId, NodeId) {
    let id = |s: &str| NodeId::new(ns, s.to_string());
    let keeps = "empty: the value in force is kept";
    let set_part = id("SetPart");
    MethodBuilder::new(&set_part, QualifiedName::new(ns, "SetPart"), "SetPart")
        .component_of(unit.clone())
        .executable(true)
        .user_executable(true)
        .input_args(
            space,
            &id("SetPart.InputArguments"),
            &string_args(&[("PartId", keeps), ("Lot", keeps), ("DieSet", keeps)]),
        )
        .insert(space);
    let change_dies = id("ChangeDies");
    MethodBuilder::new(&change_dies, QualifiedName::new(ns, "ChangeDies"), "ChangeDies")
        .component_of(unit.clone())
        .executable(true)
        .user_executable(true)
        .input_args(
            space,
            &id("ChangeDies.InputArguments"),
            &string_args(&[("DieSet", "the die set put in; empty: the one in force, counted from zero")]),
        )
        .insert(space);
    (set_part, change_dies)
}

/// `Identification` (OPC 40001-1 §8, MachineryItemIdentificationType's properties that
/// forgemon knows).
fn identification(
    space: &mut AddressSpace,
    types: Types<'_>,
    ns: u16,
    machine: &NodeId,
    name: &str,
    kind: MachineKind,
) {
    let path = format!("{name}.Identification");
    let id = NodeId::new(ns, path.clone());
    // A MachineToolType has its Identification already (`instance.rs`).
    if !space.node_exists(&id) {
        ObjectBuilder::new(&id, QualifiedName::new(ns, "Identification"), "Identification")
            .component_of(machine.clone())
            .has_type_definition(ObjectTypeId::BaseObjectType)
            .insert(space);
    }
    let props: [(&str, String); 4] = [
        ("ProductInstanceUri", format!("urn:forgemon:machine:{}", kind.as_str())),
        ("Model", kind.as_str().to_string()),
        ("SoftwareRevision", env!("CARGO_PKG_VERSION").to_string()),
        ("Manufacturer", "unknown (forgemon monitors it)".to_string()),
    ];
    for (p, value) in props {
        let pid = NodeId::new(ns, format!("{path}.{p}"));
        // An optional property of the companion type (DI's `Model`) in its namespace.
        if let Some((_, tt)) = types {
            instance::Instances { space: &mut *space, tt, ns }.add_declared(&id, &path, p);
        }
        if !set_text(space, &pid, &value) {
            let browse = QualifiedName::new(ns, p);
            variable(space, &pid, browse, value.as_str(), DataTypeId::String, &id, PROPERTY);
        }
    }
}

/// Set the text variable `id`, made from a companion type's declaration, to `value` in its
/// declared data type (DI's `Manufacturer` and `Model` are LocalizedText): false when there
/// is no such variable.
fn set_text(space: &mut AddressSpace, id: &NodeId, value: &str) -> bool {
    let Some(NodeType::Variable(v)) = space.find_mut(id) else { return false };
    let text = v.data_type() == DataTypeId::LocalizedText;
    let value = if text { Variant::from(LocalizedText::new("", value)) } else { Variant::from(value) };
    let now = DateTime::now();
    v.set_value_direct(value, opcua::types::StatusCode::Good, &now, &now)
        .unwrap_or_else(|e| tracing::warn!("opcua: {id}: {e}"));
    true
}

/// `BlowCompletedEventType` (forgemon), a subtype of `supertype` (Metal Forming's
/// `CyclicEventType`) or else of BaseEventType, with one property per field.
fn blow_event_type(space: &mut AddressSpace, ns: u16, supertype: Option<&NodeId>) {
    let ty = super::events::BlowCompletedEvent::event_type_id_from_index(ns);
    ObjectTypeBuilder::new(&ty, QualifiedName::new(ns, "BlowCompletedEventType"), "BlowCompletedEventType")
        .is_abstract(false)
        .subtype_of(supertype.cloned().unwrap_or_else(|| ObjectTypeId::BaseEventType.into()))
        .insert(space);
    for field in BLOW_EVENT_FIELDS {
        let id = NodeId::new(ns, format!("BlowCompletedEventType.{field}"));
        VariableBuilder::new(&id, QualifiedName::new(ns, field), field)
            .data_type(DataTypeId::BaseDataType)
            .property_of(ty.clone())
            .has_type_definition(VariableTypeId::PropertyType)
            .has_modelling_rule(ObjectId::ModellingRule_Mandatory)
            .insert(space);
    }
}

/// The condition's `Acknowledge(EventId, Comment)` method, `method` under `condition`.
fn acknowledge_method(space: &mut AddressSpace, condition: &NodeId, method: &NodeId, args: &NodeId) {
    let arg = |name: &str, data_type: DataTypeId, description: &str| Argument {
        name: name.into(),
        data_type: data_type.into(),
        value_rank: -1,
        array_dimensions: None,
        description: description.into(),
    };
    MethodBuilder::new(method, QualifiedName::new(0, "Acknowledge"), "Acknowledge")
        .component_of(condition.clone())
        .executable(true)
        .user_executable(true)
        .input_args(
            space,
            args,
            &[
                arg("EventId", DataTypeId::ByteString, "the event being acknowledged"),
                arg("Comment", DataTypeId::LocalizedText, "the operator's comment"),
            ],
        )
        .insert(space);
}

/// One alert condition: an `AlarmConditionType` instance under the working unit
/// (`HasCondition`), with the state an operator reads and the `Acknowledge` method.
fn condition(
    space: &mut AddressSpace,
    ns: u16,
    unit: &NodeId,
    input: &NodeId,
    kind: AlertKind,
    name: &'static str,
    severity: u16,
) -> ConditionNodes {
    let id = NodeId::new(ns, name.to_string());
    let sub = |s: &str| NodeId::new(ns, format!("{name}.{s}"));
    ObjectBuilder::new(&id, QualifiedName::new(ns, name), name)
        .component_of(unit.clone())
        .has_type_definition(ObjectTypeId::AlarmConditionType)
        .insert(space);
    space.insert_reference(unit, &id, ReferenceTypeId::HasCondition);
    let base = |s: &str| QualifiedName::new(0, s);
    let (active, acked) = (sub("ActiveState"), sub("AckedState"));
    variable(
        space,
        &active,
        base("ActiveState"),
        LocalizedText::from("Inactive"),
        DataTypeId::LocalizedText,
        &id,
        COMPONENT,
    );
    variable(
        space,
        &acked,
        base("AckedState"),
        LocalizedText::from("Acknowledged"),
        DataTypeId::LocalizedText,
        &id,
        COMPONENT,
    );
    let (active_id, acked_id, retain) = (sub("ActiveState.Id"), sub("AckedState.Id"), sub("Retain"));
    variable(space, &active_id, base("Id"), false, DataTypeId::Boolean, &active, PROPERTY);
    variable(space, &acked_id, base("Id"), true, DataTypeId::Boolean, &acked, PROPERTY);
    variable(space, &retain, base("Retain"), false, DataTypeId::Boolean, &id, PROPERTY);
    variable(space, &sub("ConditionName"), base("ConditionName"), name, DataTypeId::String, &id, PROPERTY);
    variable(space, &sub("InputNode"), base("InputNode"), input.clone(), DataTypeId::NodeId, &id, PROPERTY);
    let acknowledge = sub("Acknowledge");
    acknowledge_method(space, &id, &acknowledge, &sub("Acknowledge.InputArguments"));
    ConditionNodes {
        kind,
        node: id,
        name,
        severity,
        acknowledge,
        active_state: active,
        acked_state: acked,
        active_id,
        acked_id,
        retain,
    }
}
