//! The OPC UA server (issue 21 §2): the machine modelled after OPC 40503-1 "OPC UA for
//! Metal Forming" (`model.rs`), fed blow by blow from the service's live feed (`feed.rs`)
//! with a cyclic event per blow and the alerts as acknowledgeable conditions
//! (`events.rs`), served by async-opcua on `[opcua] listen`. Anonymous sessions on a
//! loopback address only; elsewhere one user with a password, over a signed and encrypted
//! channel (Basic256Sha256) with a self-signed server certificate kept under `pki_dir`.
//! docs/guide.md "OPC UA server" documents the node layout for a plant's clients.
//!
//! Limits: at most `max_connections` connections, counted at accept, where one without an
//! activated session gives its place to a newcomer (`auth.rs`); a connection without HEL
//! is closed after `hello_timeout_s`; at most `max_sessions` sessions; a client
//! certificate the server does not know yet is refused and stored under `pki_dir/rejected`
//! (an operator trusts it by moving it to `pki_dir/trusted`); wrong passwords are throttled
//! per peer (`auth.rs`); the server's key is private (`pki.rs`), and the password file
//! must be (`daemon::secret`).

pub mod auth;
pub mod events;
pub mod feed;
pub mod instance;
pub mod model;
pub mod nodesets;
pub mod pki;

use std::net::SocketAddr;
use std::sync::Arc;

use anyhow::Context;
use opcua::nodes::{ImportedItem, NodeSetImport, NodeSetNamespaceMapper};
use opcua::server::node_manager::memory::{SimpleNodeManager, simple_node_manager_imports};
use opcua::server::{ANONYMOUS_USER_TOKEN_ID, ServerBuilder, ServerEndpoint, ServerHandle, ServerUserToken};
use opcua::types::{BuildInfo, DateTime, MessageSecurityMode};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::Control;
use super::live::Live;
use crate::config::opcua::{OpcuaAccess, OpcuaConfig};
use crate::physics::machine::MachineKind;

/// The user token id of the configured user.
const USER_TOKEN_ID: &str = "forgemon_user";
/// The endpoint path: the server serves the root (`opc.tcp://HOST:PORT/`).
const ENDPOINT_PATH: &str = "/";

/// The running server; dropping it stops the server and its feed.
pub struct OpcuaServer {
    pub addr: SocketAddr,
    handle: ServerHandle,
    tasks: [JoinHandle<()>; 2],
}

impl Drop for OpcuaServer {
    fn drop(&mut self) {
        self.handle.cancel();
        for t in &self.tasks {
            t.abort();
        }
    }
}

/// The two namespaces of forgemon's nodes, owned by one node manager (an import that adds
/// namespaces and no nodes: the nodes are built by `model.rs`).
struct Namespaces;

impl NodeSetImport for Namespaces {
    fn register_namespaces(&self, namespaces: &mut NodeSetNamespaceMapper) {
        namespaces.add_namespace(model::MODEL_NS, 1);
        namespaces.add_namespace(model::FORGEMON_NS, 2);
    }

    fn get_own_namespaces(&self) -> Vec<String> {
        vec![model::MODEL_NS.to_string(), model::FORGEMON_NS.to_string()]
    }

    fn load<'a>(&'a self, _: &'a NodeSetNamespaceMapper) -> Box<dyn Iterator<Item = ImportedItem> + 'a> {
        Box::new(std::iter::empty())
    }
}

/// The server's builder for `cfg`: its endpoint, who may use it, and the companion
/// NodeSet2 files of `nodesets_dir` (read here: a bad file fails the start).
fn builder(cfg: &OpcuaConfig) -> anyhow::Result<ServerBuilder> {
    let mut imports = vec![Box::new(Namespaces) as Box<dyn NodeSetImport>];
    if let Some(dir) = &cfg.nodesets_dir {
        imports.extend(nodesets::imports(nodesets::read_dir(dir)?));
    }
    let b = ServerBuilder::new()
        .application_name("forgemon")
        .application_uri("urn:forgemon")
        .product_uri("urn:forgemon")
        .build_info(BuildInfo {
            product_uri: "urn:forgemon".into(),
            manufacturer_name: "forgemon".into(),
            product_name: "forgemon".into(),
            software_version: env!("CARGO_PKG_VERSION").into(),
            build_number: "".into(),
            build_date: DateTime::now(),
        })
        .host(cfg.listen.ip().to_string())
        .port(cfg.listen.port())
        .discovery_urls(vec![ENDPOINT_PATH.to_string()])
        .hello_timeout(u32::try_from(cfg.hello_timeout_s).unwrap_or(u32::MAX))
        .max_sessions(usize::try_from(cfg.max_sessions).unwrap_or(usize::MAX))
        .with_node_manager(simple_node_manager_imports(imports, "forgemon"));
    Ok(match &cfg.access {
        OpcuaAccess::Anonymous => b
            // Ours, so that an activated session admits its connection (`auth::Gate`).
            .with_authenticator(Arc::new(auth::Authenticator::new(std::collections::BTreeMap::new())))
            .add_endpoint("none", ServerEndpoint::new_none(ENDPOINT_PATH, &[ANONYMOUS_USER_TOKEN_ID.to_string()]))
            .create_sample_keypair(false)
            // No certificate is used, but async-opcua makes its PKI folders all the same
            // (by default in the working directory): keep them out of the way.
            .pki_dir(std::env::temp_dir().join("forgemon-opcua-pki")),
        OpcuaAccess::User { name, password_file, pki_dir } => {
            let password = super::secret::read(password_file, "the OPC UA password ([opcua] password_file)")?;
            let token = ServerUserToken::user_pass(name.as_str(), password.as_str());
            let users = std::collections::BTreeMap::from([(USER_TOKEN_ID.to_string(), token.clone())]);
            b.add_user_token(USER_TOKEN_ID, token)
                .with_authenticator(Arc::new(auth::Authenticator::new(users)))
                .add_endpoint(
                    "basic256sha256_sign_encrypt",
                    ServerEndpoint::new(
                        ENDPOINT_PATH,
                        opcua::crypto::SecurityPolicy::Basic256Sha256,
                        MessageSecurityMode::SignAndEncrypt,
                        &[USER_TOKEN_ID.to_string()],
                    ),
                )
                .pki_dir(pki_dir.clone())
                .create_sample_keypair(true)
                .certificate_path("own/cert.der")
                .private_key_path(pki::PRIVATE_KEY)
                // A client's certificate is trusted only once an operator has moved it from
                // pki_dir/rejected to pki_dir/trusted; an unknown one is refused.
                .trust_client_certs(false)
        }
    })
}

/// The companion types in the server's namespaces, each checked to be there by its
/// browse name (the files of `dir` were imported by `builder`).
fn companion(
    handle: &ServerHandle,
    manager: &SimpleNodeManager,
    dir: &std::path::Path,
) -> anyhow::Result<model::Companion> {
    let ns = |uri: &str| {
        handle
            .get_namespace_index(uri)
            .with_context(|| format!("opcua.nodesets_dir {}: {uri} was not loaded", dir.display()))
    };
    let c = model::Companion::new(ns(nodesets::MACHINERY)?, ns(nodesets::MACHINE_TOOL)?, ns(nodesets::METAL_FORMING)?);
    let space = manager.address_space().read();
    for (id, name) in c.expected() {
        let found = space.find(id).map(|n| n.as_node().browse_name().name.to_string());
        if found.as_deref() != Some(name) {
            anyhow::bail!(
                "opcua.nodesets_dir {}: node {id} is {} where the specification has {name}",
                dir.display(),
                found.unwrap_or_else(|| "missing".into())
            );
        }
    }
    Ok(c)
}

impl crate::daemon::faces::Face for OpcuaServer {}

/// The server as a face (`faces::FACES`): `[opcua]`.
pub fn face<'a>(
    ctx: &'a crate::daemon::faces::FaceContext<'a>,
) -> futures_util::future::BoxFuture<'a, anyhow::Result<Option<Box<dyn crate::daemon::faces::Face>>>> {
    Box::pin(async move {
        let server = start(ctx.config.opcua.as_ref(), ctx.machine.kind(), ctx.bus, ctx.control.clone());
        Ok(crate::daemon::faces::boxed(server.await?))
    })
}

/// Serve the machine on `cfg` when it is set (`[opcua]`); `None` otherwise. Fails when
/// the password cannot be read or the address cannot be listened on.
pub async fn start(
    cfg: Option<&OpcuaConfig>,
    kind: MachineKind,
    live: &Live,
    control: mpsc::Sender<Control>,
) -> anyhow::Result<Option<OpcuaServer>> {
    let Some(cfg) = cfg else { return Ok(None) };
    if let OpcuaAccess::User { pki_dir, .. } = &cfg.access {
        pki::prepare(pki_dir)?;
    }
    let (mut server, handle) =
        builder(cfg)?.build().map_err(|e| anyhow::anyhow!("opcua: the server's configuration is not valid: {e}"))?;
    let slots = crate::daemon::slots::Slots::new(usize::try_from(cfg.max_connections).unwrap_or(usize::MAX));
    server.set_accept_gate(Arc::new(auth::Gate { slots }));
    if let OpcuaAccess::User { pki_dir, .. } = &cfg.access {
        // async-opcua logs a certificate it could not make and serves on without it.
        let cert = pki_dir.join("own/cert.der");
        if !cert.is_file() {
            anyhow::bail!(
                "opcua.pki_dir {}: cannot make the server's certificate {}",
                pki_dir.display(),
                cert.display()
            );
        }
        pki::secure_key(pki_dir)?;
    }
    let manager = handle
        .node_managers()
        .get_of_type::<SimpleNodeManager>()
        .context("opcua: the server has no node manager of forgemon's")?;
    let (Some(model_ns), Some(forgemon_ns)) =
        (handle.get_namespace_index(model::MODEL_NS), handle.get_namespace_index(model::FORGEMON_NS))
    else {
        anyhow::bail!("opcua: forgemon's namespaces were not registered");
    };
    let companion = cfg.nodesets_dir.as_ref().map(|dir| companion(&handle, &manager, dir)).transpose()?;
    let nodes = {
        let tt = handle.type_tree().read();
        let types = companion.as_ref().map(|c| (c, &*tt as &dyn opcua::nodes::TypeTree));
        model::build(&mut manager.address_space().write(), model_ns, forgemon_ns, kind, types)
    };
    let conditions = feed::quiet_conditions(&nodes);
    for (i, c) in nodes.conditions.iter().enumerate() {
        let (conditions, control) = (conditions.clone(), control.clone());
        manager
            .inner()
            .add_method_callback(c.acknowledge.clone(), move |args| feed::acknowledge(&conditions, i, &control, args));
    }
    let methods: [(_, feed::PartMethod); 2] =
        [(nodes.set_part.clone(), feed::set_part), (nodes.change_dies.clone(), feed::change_dies)];
    for (node, call) in methods {
        let control = control.clone();
        manager.inner().add_method_callback(node, move |args| call(&control, args));
    }
    let listener = tokio::net::TcpListener::bind(cfg.listen)
        .await
        .with_context(|| format!("opcua.listen {}: cannot listen", cfg.url))?;
    let addr = listener.local_addr().with_context(|| format!("opcua.listen {}", cfg.url))?;
    let feed = feed::Feed {
        manager,
        subscriptions: handle.subscriptions().clone(),
        nodes,
        conditions,
        part: crate::estimate::billet_book::Trace::default(),
    };
    let updater = tokio::spawn(feed.run(live.subscribe()));
    let run = tokio::spawn(async move {
        if let Err(e) = server.run_with(listener).await {
            tracing::error!("OPC UA server stopped: {e}");
        }
    });
    tracing::info!(%addr, "OPC UA server listening");
    Ok(Some(OpcuaServer { addr, handle, tasks: [updater, run] }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Users by token id, as async-opcua's authenticator takes them.
    fn users(b: &ServerBuilder) -> std::collections::BTreeMap<String, ServerUserToken> {
        b.config().user_tokens.clone()
    }

    #[test]
    fn anonymous_access_has_one_unsecured_endpoint_and_no_users() {
        let cfg = OpcuaConfig::anonymous("opc.tcp://127.0.0.1:4840").expect("loopback");
        let b = builder(&cfg).expect("builds");
        let eps = &b.config().endpoints;
        assert_eq!(eps.len(), 1);
        let ep = eps.values().next().expect("one endpoint");
        assert_eq!(ep.security_policy, "None");
        assert!(ep.user_token_ids.contains(ANONYMOUS_USER_TOKEN_ID));
        assert!(users(&b).is_empty());
    }

    #[test]
    fn a_user_gets_only_an_encrypted_endpoint_without_anonymous() {
        let dir = tempfile::tempdir().expect("temp dir");
        let pass = dir.path().join("pass");
        std::fs::write(&pass, "s3cret\n").expect("write");
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&pass, std::fs::Permissions::from_mode(0o600)).expect("chmod");
        let cfg = OpcuaConfig {
            url: "opc.tcp://0.0.0.0:4840".into(),
            listen: "0.0.0.0:4840".parse().expect("address"),
            access: OpcuaAccess::User {
                name: "mes".into(),
                password_file: pass.clone(),
                pki_dir: dir.path().join("pki"),
            },
            hello_timeout_s: 2,
            max_sessions: 3,
            max_connections: 6,
            nodesets_dir: None,
        };
        let b = builder(&cfg).expect("builds");
        let eps = &b.config().endpoints;
        assert_eq!(eps.len(), 1);
        let ep = eps.values().next().expect("one endpoint");
        assert_eq!((ep.security_policy.as_str(), ep.security_mode.as_str()), ("Basic256Sha256", "SignAndEncrypt"));
        assert!(!ep.user_token_ids.contains(ANONYMOUS_USER_TOKEN_ID));
        let u = users(&b);
        assert_eq!(u[USER_TOKEN_ID].user, "mes");
        assert_eq!(u[USER_TOKEN_ID].pass.as_deref(), Some("s3cret"), "the newline is not part of the password");
        let c = b.config();
        assert_eq!((c.tcp_config.hello_timeout, c.limits.max_sessions), (2, 3));
        assert!(!c.certificate_validation.trust_client_certs, "an unknown client certificate is refused");
        std::fs::write(&pass, "\n").expect("write");
        let e = builder(&cfg).err().expect("an empty password is refused").to_string();
        assert!(e.contains("password_file") && e.contains("empty"), "{e}");
        std::fs::write(&pass, "s3cret\n").expect("write");
        std::fs::set_permissions(&pass, std::fs::Permissions::from_mode(0o644)).expect("chmod");
        let e = builder(&cfg).err().expect("a password others can read is refused").to_string();
        assert!(e.contains("password_file") && e.contains("chmod 600"), "{e}");
    }
}
