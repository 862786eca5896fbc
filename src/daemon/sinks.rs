//! Alert sinks beyond the log and the recording, as faces on the bus (`faces.rs`): an HTTP
//! webhook (the alert as JSON) and a Modbus coil on the PLC. Each follows the bus's
//! `Alert` events and sends each alert from its own task under a timeout, so a slow or
//! absent receiver never holds up the service or the other faces; failures are logged, not
//! fatal. At the stop each sends the alerts it has received, within `SINK_TIMEOUT`.

use std::time::Duration;

use futures_util::future::BoxFuture;
use tokio::sync::broadcast::{self, error::RecvError};
use tokio::task::JoinHandle;

use super::faces::{Face, FaceContext, boxed};
use super::live::LiveEvent;
use super::status::SharedStatus;
use crate::alert::Alert;
use crate::config::service::PlcCoil;

/// Longest a webhook call or a coil write may take.
pub const SINK_TIMEOUT: Duration = Duration::from_secs(2);

/// A sink's task on the bus.
struct Sink {
    task: JoinHandle<()>,
}

impl Face for Sink {
    /// Wait (at most `SINK_TIMEOUT`) for the sink to send what the bus gave it before
    /// `Stopping`.
    fn finish(self: Box<Self>) -> BoxFuture<'static, ()> {
        Box::pin(async move {
            let _ = tokio::time::timeout(SINK_TIMEOUT, self.task).await;
        })
    }
}

/// `[alerts] webhook`: each alert POSTed as JSON; `/status` shows how long after its
/// samples arrived the webhook answered.
pub fn webhook_face<'a>(ctx: &'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn Face>>>> {
    let sink = ctx.config.webhook.clone().map(|url| {
        let status = ctx.status.clone();
        Sink {
            task: tokio::spawn(follow(ctx.bus.subscribe(), move |alert, arrived_ns| {
                post(&url, alert, arrived_ns, &status)
            })),
        }
    });
    Box::pin(async move { Ok(boxed(sink)) })
}

/// `[alerts] plc_coil`: the coil set on each alert.
pub fn coil_face<'a>(ctx: &'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn Face>>>> {
    let sink =
        ctx.config.plc_coil.map(|c| Sink { task: tokio::spawn(follow(ctx.bus.subscribe(), move |_, _| set(c))) });
    Box::pin(async move { Ok(boxed(sink)) })
}

/// Hand each alert on the bus to `send`, until `Stopping`; then wait for the sends.
async fn follow(mut rx: broadcast::Receiver<LiveEvent>, send: impl Fn(&Alert, i64) -> JoinHandle<()>) {
    let mut sent = Vec::new();
    loop {
        match rx.recv().await {
            Ok(LiveEvent::Alert { alert, arrived_ns }) => {
                sent.retain(|t: &JoinHandle<()>| !t.is_finished());
                sent.push(send(&alert, arrived_ns));
            }
            Ok(LiveEvent::Stopping) | Err(RecvError::Closed) => break,
            Ok(_) => {}
            Err(RecvError::Lagged(n)) => tracing::error!(events = n, "an alert sink fell behind the bus: alerts lost"),
        }
    }
    for t in sent {
        let _ = t.await;
    }
}

fn post(url: &str, alert: &Alert, arrived_ns: i64, status: &SharedStatus) -> JoinHandle<()> {
    let (url, status) = (url.to_owned(), status.clone());
    let body = serde_json::to_string(alert).unwrap_or_default();
    tokio::task::spawn_blocking(move || {
        let agent: ureq::Agent = ureq::Agent::config_builder().timeout_global(Some(SINK_TIMEOUT)).build().into();
        match agent.post(&url).header("content-type", "application/json").send(body.as_bytes()) {
            Ok(_) => {
                let ms = (super::host_now_ns() - arrived_ns) as f64 * 1e-6;
                status.lock().map(|mut s| s.last_webhook_latency_ms = Some(ms)).ok();
            }
            Err(e) => tracing::error!("webhook {url}: {e}"),
        }
    })
}

fn set(c: PlcCoil) -> JoinHandle<()> {
    tokio::spawn(async move {
        if let Err(e) = crate::acquire::modbus::write_coil(c.address, c.unit, c.coil, true, SINK_TIMEOUT).await {
            tracing::error!("PLC coil {} at {}: {e}", c.coil, c.address);
        }
    })
}

#[cfg(test)]
mod tests {
    use std::io::{BufRead, BufReader, Read, Write};
    use std::path::PathBuf;
    use std::sync::{Arc, Mutex};

    use super::*;
    use crate::alert::AlertKind;
    use crate::config::service::ServiceConfig;
    use crate::daemon::live::Live;
    use crate::daemon::status::StatusSnapshot;

    /// A loopback HTTP server that hands each request's body on.
    fn server() -> (String, std::sync::mpsc::Receiver<String>) {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}/hook", listener.local_addr().unwrap());
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let mut r = BufReader::new(stream.try_clone().unwrap());
                let (mut len, mut line) = (0usize, String::new());
                while r.read_line(&mut line).unwrap_or(0) > 2 {
                    if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                        len = v.trim().parse().unwrap_or(0);
                    }
                    line.clear();
                }
                let mut body = vec![0; len];
                let _ = r.read_exact(&mut body);
                // The body is handed over before the reply: once the client has its 200, the
                // test may read the bodies (replying first lost the last one to that race once).
                let _ = tx.send(String::from_utf8_lossy(&body).into_owned());
                let _ = (&stream).write_all(b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\nconnection: close\r\n\r\n");
            }
        });
        (url, rx)
    }

    /// The webhook is a face like any other: started from its section with the common
    /// context, it posts each alert the bus carries, and at the stop it has sent them all
    /// before `finish` returns. Without its section it does not start.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_webhook_face_posts_every_alert_on_the_bus_before_it_finishes() {
        let (url, bodies) = server();
        let bare = ServiceConfig::minimal(PathBuf::from("m.toml"), PathBuf::from("/nonexistent"));
        let config = ServiceConfig { webhook: Some(url), ..bare.clone() };
        let text = include_str!("../../config/hammer-lg1000.machine.toml");
        let machine = crate::config::parse_machine("lg1000", text).unwrap().machine;
        let bus = Live::default();
        let status = Arc::new(Mutex::new(StatusSnapshot::new("hammer")));
        let (control, _rx) = tokio::sync::mpsc::channel(1);
        let on_advice = Mutex::new(None);
        let (routes, recorded) = (Default::default(), Default::default());
        let ctx = |config| FaceContext {
            config,
            machine: &machine,
            machine_text: "",
            process: None,
            bus: &bus,
            status: &status,
            control: &control,
            on_advice: &on_advice,
            routes: &routes,
            recorded: &recorded,
        };
        assert!(webhook_face(&ctx(&bare)).await.unwrap().is_none(), "no [alerts] webhook, no face");
        let face = webhook_face(&ctx(&config)).await.unwrap().expect("a face");
        for blow in 1..=3 {
            let alert = Alert {
                kind: AlertKind::ElasticBlow,
                blow,
                reason: format!("blow {blow}"),
                figures: Default::default(),
            };
            bus.publish(LiveEvent::Alert { alert: Arc::new(alert), arrived_ns: crate::daemon::host_now_ns() });
        }
        bus.publish(LiveEvent::Stopping);
        face.finish().await;
        let mut got: Vec<u32> = bodies
            .try_iter()
            .map(|b| serde_json::from_str::<serde_json::Value>(&b).unwrap()["blow"].as_u64().unwrap() as u32)
            .collect();
        got.sort();
        assert_eq!(got, [1, 2, 3]);
        assert!(status.lock().unwrap().last_webhook_latency_ms.is_some());
    }
}
