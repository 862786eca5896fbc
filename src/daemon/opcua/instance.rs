//! Instances of the companion specifications' types (`nodesets.rs`): an object given a
//! companion type gets the children the type declares mandatory (OPC 10000-3 §6.4.4:
//! modelling rule `Mandatory`), with their browse names, type definitions, data types and
//! default values, and theirs in turn. A declaration of a subtype overrides its
//! supertype's of the same browse name. The declarations are read from the address space,
//! so only those the imported files hold are followed: OPC UA's own types (namespace 0)
//! are served by another node manager, and their children are not added. Methods are not
//! instantiated: a client calls a type's method on the object.
//!
//! An instance's node id is its parent's with `.BrowseName` appended, in forgemon's model
//! namespace, so `Hammer.Identification.Manufacturer` is found without browsing.

use opcua::nodes::{AccessLevel, NodeType, ObjectBuilder, TypeTree, VariableBuilder};
use opcua::server::address_space::AddressSpace;
use opcua::types::{
    BrowseDirection, DataEncoding, NodeId, NumericRange, ObjectId, QualifiedName, ReferenceTypeId, TimestampsToReturn,
    Variant,
};

/// How deep children of children are followed; the companion types nest four levels.
const DEPTH: usize = 8;

/// The references by which a type declares its children.
const AGGREGATES: [ReferenceTypeId; 4] = [
    ReferenceTypeId::HasComponent,
    ReferenceTypeId::HasProperty,
    ReferenceTypeId::HasAddIn,
    ReferenceTypeId::HasOrderedComponent,
];

/// The targets of `node`'s forward references of type `ty`.
fn targets(space: &AddressSpace, tt: &dyn TypeTree, node: &NodeId, ty: ReferenceTypeId) -> Vec<NodeId> {
    let ty: NodeId = ty.into();
    space
        .find_references(node, None::<(NodeId, bool)>, tt, BrowseDirection::Forward)
        .filter(|r| *r.reference_type == ty)
        .map(|r| r.target_node.clone())
        .collect()
}

/// `ty` and its supertypes, the most derived first, as far as the address space holds them,
/// each followed by the interfaces it has (OPC 10001-7: `HasInterface`) and theirs.
fn type_chain(space: &AddressSpace, tt: &dyn TypeTree, ty: &NodeId) -> Vec<NodeId> {
    let subtype: NodeId = ReferenceTypeId::HasSubtype.into();
    let supertype = |t: &NodeId| {
        space
            .find_references(t, None::<(NodeId, bool)>, tt, BrowseDirection::Inverse)
            .find(|r| *r.reference_type == subtype)
            .map(|r| r.target_node.clone())
            .filter(|up| space.node_exists(up))
    };
    let mut chain: Vec<NodeId> = Vec::new();
    let mut next = vec![ty.clone()];
    while let Some(t) = next.pop() {
        if chain.contains(&t) || chain.len() >= 64 {
            continue;
        }
        // Depth first: a type, its interfaces, then its supertype.
        next.extend(supertype(&t));
        let mut interfaces = targets(space, tt, &t, ReferenceTypeId::HasInterface);
        interfaces.reverse();
        next.extend(interfaces);
        chain.push(t);
    }
    chain
}

/// The mandatory declarations under `sources` (an instance declaration, then its type
/// and supertypes): each with the reference that holds it, the first of a browse name.
fn mandatory(space: &AddressSpace, tt: &dyn TypeTree, sources: &[NodeId]) -> Vec<(NodeId, ReferenceTypeId)> {
    let rule: NodeId = ObjectId::ModellingRule_Mandatory.into();
    let mut seen: Vec<QualifiedName> = Vec::new();
    let mut out = Vec::new();
    for source in sources {
        for ty in AGGREGATES {
            for decl in targets(space, tt, source, ty) {
                let Some(node) = space.find(&decl) else { continue };
                let name = node.as_node().browse_name().clone();
                if seen.contains(&name) {
                    continue;
                }
                seen.push(name);
                if targets(space, tt, &decl, ReferenceTypeId::HasModellingRule).contains(&rule) {
                    out.push((decl, ty));
                }
            }
        }
    }
    out
}

/// The type definition of `node`.
fn type_definition(space: &AddressSpace, tt: &dyn TypeTree, node: &NodeId) -> Option<NodeId> {
    targets(space, tt, node, ReferenceTypeId::HasTypeDefinition).into_iter().next()
}

/// Where instances are made: the address space, the type tree to read it with, and the
/// namespace of the instances' node ids.
pub struct Instances<'a> {
    pub space: &'a mut AddressSpace,
    pub tt: &'a dyn TypeTree,
    pub ns: u16,
}

impl Instances<'_> {
    /// Add to `instance` (node id `path`) its type's child `name`, a declaration of any
    /// modelling rule (an optional property such as DI's `Model`), with its mandatory
    /// children: its node id, or `None` when the type declares no such child.
    pub fn add_declared(&mut self, instance: &NodeId, path: &str, name: &str) -> Option<NodeId> {
        let (space, tt) = (&*self.space, self.tt);
        let ty = type_definition(space, tt, instance)?;
        let sources = type_chain(space, tt, &ty);
        let (decl, reference) = sources.iter().find_map(|source| {
            AGGREGATES.iter().find_map(|&r| {
                targets(space, tt, source, r)
                    .into_iter()
                    .find(|d| space.find(d).is_some_and(|n| n.as_node().browse_name().name.as_ref() == name))
                    .map(|d| (d, r))
            })
        })?;
        self.add_one(instance, path, decl, reference, DEPTH);
        Some(NodeId::new(self.ns, format!("{path}.{name}")))
    }

    /// Add to `instance` (node id `path`) the mandatory children of its type `ty`; returns
    /// how many nodes were added.
    pub fn add_mandatory(&mut self, instance: &NodeId, path: &str, ty: &NodeId) -> usize {
        let sources = type_chain(self.space, self.tt, ty);
        self.add_children(instance, path, &sources, DEPTH)
    }

    /// The children of `instance` declared mandatory under `sources`.
    fn add_children(&mut self, instance: &NodeId, path: &str, sources: &[NodeId], depth: usize) -> usize {
        let mut added = 0;
        for (decl, reference) in mandatory(self.space, self.tt, sources) {
            added += self.add_one(instance, path, decl, reference, depth);
        }
        added
    }

    /// Add the declaration `decl` to `instance` by `reference`, with its mandatory
    /// children: how many nodes were added (none when a node of its id is there already).
    fn add_one(
        &mut self,
        instance: &NodeId,
        path: &str,
        decl: NodeId,
        reference: ReferenceTypeId,
        depth: usize,
    ) -> usize {
        let (tt, ns) = (self.tt, self.ns);
        let space = &mut *self.space;
        let Some(node) = space.find(&decl) else { return 0 };
        let name = node.as_node().browse_name().clone();
        let display = node.as_node().display_name().clone();
        let child_path = format!("{path}.{}", name.name);
        let id = NodeId::new(ns, child_path.clone());
        if space.node_exists(&id) {
            return 0;
        }
        // What the declaration is, read before the address space is written.
        let variable = match node {
            NodeType::Object(_) => None,
            NodeType::Variable(v) => Some((
                v.data_type(),
                v.value_rank(),
                v.value(TimestampsToReturn::Neither, &NumericRange::None, &DataEncoding::Binary, 0.0)
                    .value
                    .unwrap_or(Variant::Empty),
            )),
            _ => return 0,
        };
        let ty = type_definition(space, tt, &decl);
        let inserted = match variable {
            None => {
                let b = ObjectBuilder::new(&id, name, display);
                match &ty {
                    Some(t) => b.has_type_definition(t.clone()),
                    None => b,
                }
                .insert(space)
            }
            Some((data_type, value_rank, value)) => {
                let b = VariableBuilder::new(&id, name, display)
                    .data_type(data_type)
                    .value_rank(value_rank)
                    .value(value)
                    .access_level(AccessLevel::CURRENT_READ)
                    .user_access_level(AccessLevel::CURRENT_READ);
                match &ty {
                    Some(t) => b.has_type_definition(t.clone()),
                    None => b,
                }
                .insert(space)
            }
        };
        if !inserted {
            return 0;
        }
        space.insert_reference(instance, &id, reference);
        let mut added = 1;
        if depth > 0 {
            let mut sources = vec![decl];
            if let Some(t) = &ty {
                sources.extend(type_chain(space, tt, t));
            }
            added += self.add_children(&id, &child_path, &sources, depth - 1);
        }
        added
    }
}
