//! The history face (issue 44): the recorder's messages into the history database
//! (`history::writer`), its counters in `/status` `history` every second. On by default
//! (`[history]`); a database that cannot be opened stops the start, naming it.

use std::sync::Arc;

use futures_util::future::BoxFuture;

use super::faces::{Face, FaceContext, boxed};
use super::status::SharedStatus;
use crate::history::writer::{HistoryCounters, LiveHistory};

struct HistoryFace {
    live: Option<LiveHistory>,
    status_task: tokio::task::JoinHandle<()>,
}

impl Face for HistoryFace {
    fn finish(mut self: Box<Self>) -> BoxFuture<'static, ()> {
        self.status_task.abort();
        let live = self.live.take();
        Box::pin(async move {
            if let Some(live) = live {
                let _ = tokio::task::spawn_blocking(move || live.finish()).await;
            }
        })
    }
}

pub fn face<'a>(ctx: &'a FaceContext<'a>) -> BoxFuture<'a, anyhow::Result<Option<Box<dyn Face>>>> {
    Box::pin(async move {
        let Some(cfg) = &ctx.config.history else { return Ok(None) };
        let live = LiveHistory::start(cfg.path.clone(), cfg.keep_days)?;
        ctx.tap_recording(live.tap());
        let status_task = tokio::spawn(show(ctx.status.clone(), live.counters(), cfg.path.clone()));
        Ok(boxed(Some(HistoryFace { live: Some(live), status_task })))
    })
}

/// Copy the writer's counters into `/status` every second.
async fn show(status: SharedStatus, counters: Arc<HistoryCounters>, path: std::path::PathBuf) {
    let mut tick = tokio::time::interval(std::time::Duration::from_secs(1));
    loop {
        tick.tick().await;
        let now = counters.status(&path);
        status.lock().map(|mut s| s.history = Some(now)).ok();
    }
}
