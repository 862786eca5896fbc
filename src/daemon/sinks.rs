//! Alert sinks beyond the log and the recording: an HTTP webhook (the alert as JSON) and a
//! Modbus coil on the PLC. Each alert is sent from its own task under a timeout, so a slow
//! or absent receiver never holds up the service; failures are logged, not fatal.

use std::time::Duration;

use crate::alert::Alert;
use crate::config::service::PlcCoil;

/// Longest a webhook call or a coil write may take.
pub const SINK_TIMEOUT: Duration = Duration::from_secs(2);

/// Where alerts go besides the log and the recording.
#[derive(Debug, Clone)]
pub struct Sinks {
    webhook: Option<String>,
    coil: Option<PlcCoil>,
}

impl Sinks {
    pub fn new(webhook: Option<String>, coil: Option<PlcCoil>) -> Self {
        Sinks { webhook, coil }
    }

    /// Send `alert` to every sink, without waiting. `since_host_ns` is when the samples that
    /// ended the blow arrived: the status shows how long after that the webhook answered.
    pub fn fire(&self, alert: &Alert, since_host_ns: i64, status: &super::status::SharedStatus) {
        if let Some(url) = self.webhook.clone() {
            let body = serde_json::to_string(alert).unwrap_or_default();
            let status = status.clone();
            tokio::task::spawn_blocking(move || {
                let agent: ureq::Agent =
                    ureq::Agent::config_builder().timeout_global(Some(SINK_TIMEOUT)).build().into();
                match agent.post(&url).header("content-type", "application/json").send(body.as_bytes()) {
                    Ok(_) => {
                        let ms = (super::host_now_ns() - since_host_ns) as f64 * 1e-6;
                        status.lock().map(|mut s| s.last_webhook_latency_ms = Some(ms)).ok();
                    }
                    Err(e) => tracing::error!("webhook {url}: {e}"),
                }
            });
        }
        if let Some(c) = self.coil {
            tokio::spawn(async move {
                if let Err(e) = crate::acquire::modbus::write_coil(c.address, c.unit, c.coil, true, SINK_TIMEOUT).await
                {
                    tracing::error!("PLC coil {} at {}: {e}", c.coil, c.address);
                }
            });
        }
    }
}
