//! The OPC Foundation's companion NodeSet2 files of `[opcua] nodesets_dir`: every `*.xml`
//! there is parsed (a file that does not parse is named with its line), ordered so that a
//! model comes after the models it requires, and imported into the server's address space
//! by async-opcua's `NodeSet2Import`. The machine's nodes are then instances of the
//! companion types (`model.rs`, `instance.rs`): Machinery's `Machines` folder (OPC 40001-1),
//! Machine Tools' `MachineToolType` (OPC 40501-1) and Metal Forming's
//! `FormingProcessWorkingUnitType` and `CyclicEventType` (OPC 40502... as the files name
//! them: `http://opcfoundation.org/UA/MetalForming/`).
//!
//! A model a file requires that no file there defines is an error naming both, and so is a
//! model defined twice: the server would otherwise serve types whose supertypes are
//! missing. The files are read when the service starts; a bad directory stops the start.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use opcua::nodes::{ImportedItem, NodeSet2Import, NodeSetImport, NodeSetNamespaceMapper};
use opcua::xml::schema::ua_node_set::{UANodeSet, load_nodeset2_file};

/// OPC UA's own namespace: built into the server, never in a file.
pub const CORE: &str = "http://opcfoundation.org/UA/";
/// OPC 40001-1 Machinery.
pub const MACHINERY: &str = "http://opcfoundation.org/UA/Machinery/";
/// OPC 40501-1 Machine Tools.
pub const MACHINE_TOOL: &str = "http://opcfoundation.org/UA/MachineTool/";
/// Metal Forming.
pub const METAL_FORMING: &str = "http://opcfoundation.org/UA/MetalForming/";
/// The models forgemon's nodes are instances of: a directory without one is refused.
pub const NEEDED: [&str; 3] = [MACHINERY, MACHINE_TOOL, METAL_FORMING];

/// One parsed NodeSet2 file.
pub struct NodeSetFile {
    pub path: PathBuf,
    /// The models the file defines (`<Models>`).
    pub models: Vec<String>,
    /// The models they require, OPC UA's own left out.
    pub requires: BTreeSet<String>,
    /// The namespace table of the file (`<NamespaceUris>`): `ns=1` is the first.
    uris: Vec<String>,
    nodes: UANodeSet,
}

/// At most this many unreadable values are left out of one file before it is refused.
const MAX_DROPPED_VALUES: usize = 1000;

/// The byte range of the `<Value>...</Value>` element around `span`, if `span` is inside one.
fn value_around(text: &str, span: std::ops::Range<usize>) -> Option<std::ops::Range<usize>> {
    let start = text.get(..span.start)?.rfind("<Value>")?;
    if text[start..span.start].contains("</Value>") {
        return None;
    }
    let end = span.end + text.get(span.end..)?.find("</Value>")? + "</Value>".len();
    Some(start..end)
}

/// The 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes().iter().take(offset).filter(|&&b| b == b'\n').count() + 1
}

impl NodeSetFile {
    /// Parse the NodeSet2 file `path`. A `<Value>` async-opcua cannot read (PADIM's
    /// `Matrix` values) is left out of its node, with a warning naming the line: the node
    /// stays, without its default value.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let mut text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
        let mut dropped = 0;
        let doc = loop {
            let e = match load_nodeset2_file(&text) {
                Ok(doc) => break doc,
                Err(e) => e,
            };
            let line = line_of(&text, e.span.start);
            match value_around(&text, e.span.clone()).filter(|_| dropped < MAX_DROPPED_VALUES) {
                Some(cut) => {
                    tracing::warn!("{}:{line}: a value async-opcua cannot read is left out: {e}", path.display());
                    text.replace_range(cut, "");
                    dropped += 1;
                }
                None => bail!("{}:{line}: not a NodeSet2 file: {e}", path.display()),
            }
        };
        let Some(nodes) = doc.node_set else {
            bail!("{}: not a NodeSet2 file: no <UANodeSet>", path.display());
        };
        let entries = nodes.models.as_ref().map(|m| m.models.as_slice()).unwrap_or_default();
        if entries.is_empty() {
            bail!("{}: the NodeSet2 file names no model (<Models>)", path.display());
        }
        let models: Vec<String> = entries.iter().map(|m| m.model_uri.clone()).collect();
        let requires = entries
            .iter()
            .flat_map(|m| m.required_model.iter().map(|r| r.model_uri.clone()))
            .filter(|uri| uri != CORE && !models.contains(uri))
            .collect();
        let uris = nodes.namespace_uris.as_ref().map(|u| u.uris.clone()).unwrap_or_default();
        Ok(NodeSetFile { path: path.to_path_buf(), models, requires, uris, nodes })
    }
}

/// The `*.xml` files of `dir`, parsed, in an order where each comes after the files whose
/// models it requires.
pub fn read_dir(dir: &Path) -> anyhow::Result<Vec<NodeSetFile>> {
    let what = || format!("opcua.nodesets_dir {}", dir.display());
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list it", what()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml")))
        .collect();
    paths.sort();
    let mut files = paths.iter().map(|p| NodeSetFile::read(p)).collect::<anyhow::Result<Vec<_>>>()?;
    for (i, f) in files.iter().enumerate() {
        for g in &files[i + 1..] {
            if let Some(m) = f.models.iter().find(|m| g.models.contains(m)) {
                bail!("{}: model {m} is defined twice, by {} and {}", what(), f.path.display(), g.path.display());
            }
        }
    }
    let defined: BTreeSet<&String> = files.iter().flat_map(|f| &f.models).collect();
    for f in &files {
        if let Some(m) = f.requires.iter().find(|m| !defined.contains(m)) {
            bail!("{}: {} requires model {m}, which no file there defines", what(), f.path.display());
        }
    }
    for m in NEEDED {
        if !defined.iter().any(|d| d.as_str() == m) {
            bail!("{}: no file defines model {m}, which forgemon's nodes are instances of", what());
        }
    }
    // Each pass takes the files whose required models are all in; every required model
    // is defined (above), so a pass that takes none means a cycle.
    let mut ordered = Vec::with_capacity(files.len());
    let mut loaded: BTreeSet<String> = BTreeSet::new();
    while !files.is_empty() {
        let (ready, rest): (Vec<_>, Vec<_>) = files.into_iter().partition(|f| f.requires.is_subset(&loaded));
        if ready.is_empty() {
            let names: Vec<String> = rest.iter().map(|f| f.path.display().to_string()).collect();
            bail!("{}: the models of {} require one another", what(), names.join(", "));
        }
        loaded.extend(ready.iter().flat_map(|f| f.models.iter().cloned()));
        ordered.extend(ready);
        files = rest;
    }
    Ok(ordered)
}

/// A file as async-opcua imports it. The namespaces are registered here (`ns=i` of the
/// file is its table's i-th URI) rather than by `NodeSet2Import`, which prints each one
/// on stdout.
struct Import {
    uris: Vec<String>,
    import: NodeSet2Import,
}

impl NodeSetImport for Import {
    fn register_namespaces(&self, namespaces: &mut NodeSetNamespaceMapper) {
        for (i, uri) in self.uris.iter().enumerate() {
            if uri != CORE {
                namespaces.add_namespace(uri, u16::try_from(i + 1).unwrap_or(u16::MAX));
            }
        }
    }

    fn get_own_namespaces(&self) -> Vec<String> {
        self.uris.iter().filter(|u| *u != CORE).cloned().collect()
    }

    fn load<'a>(&'a self, namespaces: &'a NodeSetNamespaceMapper) -> Box<dyn Iterator<Item = ImportedItem> + 'a> {
        self.import.load(namespaces)
    }
}

/// The imports of `files`, in their order.
pub fn imports(files: Vec<NodeSetFile>) -> Vec<Box<dyn NodeSetImport>> {
    files
        .into_iter()
        .map(|f| {
            let import = NodeSet2Import::new_nodeset("en", f.nodes, Vec::new());
            Box::new(Import { uris: f.uris, import }) as Box<dyn NodeSetImport>
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The files of fixtures/opcua-nodesets (node-opcua-nodesets 2.179.0, MIT).
    fn fixtures() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/opcua-nodesets")
    }

    #[test]
    fn the_companion_files_are_ordered_after_what_they_require() {
        let files = read_dir(&fixtures()).expect("the fixtures load");
        let at = |m: &str| files.iter().position(|f| f.models.iter().any(|x| x == m)).expect(m);
        assert!(at("http://opcfoundation.org/UA/DI/") < at(MACHINERY));
        assert!(at(MACHINERY) < at(MACHINE_TOOL));
        assert!(at(MACHINE_TOOL) < at(METAL_FORMING));
        for (i, f) in files.iter().enumerate() {
            for r in &f.requires {
                let j = files.iter().position(|g| g.models.contains(r)).expect("required model present");
                assert!(j < i, "{} before what it requires ({r})", f.path.display());
            }
        }
    }

    #[test]
    fn a_missing_model_or_a_broken_file_is_named() {
        let dir = tempfile::tempdir().expect("temp dir");
        for name in ["Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.MetalForming.NodeSet2.xml"] {
            std::fs::copy(fixtures().join(name), dir.path().join(name)).expect("copy");
        }
        let e = format!("{:#}", read_dir(dir.path()).err().expect("MetalForming needs more"));
        // The first missing model in URI order.
        assert!(
            e.contains("Opc.Ua.MetalForming.NodeSet2.xml requires model http://opcfoundation.org/UA/Dictionary/IRDI"),
            "{e}"
        );
        std::fs::write(
            dir.path().join("broken.xml"),
            "<?xml version=\"1.0\"?>\n<UANodeSet>\n  <Models>\n</UANodeSet>\n",
        )
        .expect("write");
        let e = format!("{:#}", read_dir(dir.path()).err().expect("a broken file is refused"));
        assert!(e.contains("broken.xml:"), "{e}");
        let e = format!("{:#}", read_dir(&dir.path().join("absent")).err().expect("no directory"));
        assert!(e.contains("opcua.nodesets_dir") && e.contains("absent"), "{e}");
    }
}
