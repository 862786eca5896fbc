//! The service's faces, started one way: each from its own config section, with the same
//! context, and each subscribes to the bus (`live::Live`). `serve` starts every face in
//! its list (`daemon::FACES`) and stops them when the service stops; adding a face adds its
//! files and one line there, not edits across the service, the demo and the tests.
//!
//! Besides the bus, a face may ask for two things through its context: HTTP routes on the
//! service's listener (beside `/status`, behind its token: the dashboard), and the
//! recorder's messages as the file gets them, samples included (the Foxglove view).

use std::sync::Mutex;

use futures_util::future::BoxFuture;
use tokio::sync::mpsc;

use super::live::Live;
use super::status::SharedStatus;
use super::{AdviceHook, Control};
use crate::config::service::ServiceConfig;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::record::tap::Tap;

/// What every face is started with.
pub struct FaceContext<'a> {
    pub config: &'a ServiceConfig,
    pub machine: &'a Machine,
    /// The machine file's text (its effects).
    pub machine_text: &'a str,
    pub process: Option<&'a Process>,
    /// The bus: results, alerts, billets, acknowledgements, advice, the stop.
    pub bus: &'a Live,
    pub status: &'a SharedStatus,
    /// Commands back to the service (new billet, acknowledge).
    pub control: &'a mpsc::Sender<Control>,
    /// A front end's callback for the advisor's plans (the demo prints them).
    pub on_advice: &'a Mutex<Option<AdviceHook>>,
    /// Routes a face serves on the service's HTTP listener; `serve` merges them.
    pub routes: &'a Mutex<Vec<axum::Router>>,
    /// Consumers of every message the recorder writes (`record::tap`), samples included;
    /// `serve` hands each message to each of them.
    pub recorded: &'a Mutex<Vec<Tap>>,
}

impl FaceContext<'_> {
    /// Serve `routes` on the service's HTTP listener.
    pub fn serve_routes(&self, routes: axum::Router) {
        self.routes.lock().map(|mut r| r.push(routes)).ok();
    }

    /// Receive every message the recorder writes.
    pub fn tap_recording(&self, tap: Tap) {
        self.recorded.lock().map(|mut t| t.push(tap)).ok();
    }
}

/// A running face. Dropping it stops it; `finish` lets it send what it still holds first
/// (after the bus carried `Stopping`).
pub trait Face: Send {
    fn finish(self: Box<Self>) -> BoxFuture<'static, ()> {
        Box::pin(async {})
    }
}

/// A face's start: `None` when its section is not configured.
pub type Start = for<'a> fn(&'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn Face>>>>;

/// `face` as a running face, if it started.
pub fn boxed<F: Face + 'static>(face: Option<F>) -> Option<Box<dyn Face>> {
    face.map(|f| Box::new(f) as Box<dyn Face>)
}
