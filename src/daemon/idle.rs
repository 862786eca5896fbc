//! A connection's idle clock (issue 39): when a byte or a frame last moved on it, and a
//! wait that ends once nothing has moved for a given time. The HTTP server notes every
//! read and write (`http_server`), the Foxglove view every frame from its client; each
//! closes a connection that went idle, so a client that vanished (half-open) or stopped
//! reading does not hold a descriptor for ever.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::time::Instant;

/// When something last moved on one connection; shared between its IO and its watcher.
#[derive(Debug)]
pub struct IdleClock {
    opened: Instant,
    /// Since `opened`, ms.
    last_ms: AtomicU64,
}

impl Default for IdleClock {
    fn default() -> Self {
        IdleClock::new()
    }
}

impl IdleClock {
    /// A clock started now, as if something had just moved.
    pub fn new() -> Self {
        IdleClock { opened: Instant::now(), last_ms: AtomicU64::new(0) }
    }

    /// Something moved now.
    pub fn touch(&self) {
        self.last_ms.store(self.opened.elapsed().as_millis() as u64, Ordering::Relaxed);
    }

    /// Resolves once nothing moved for `limit`.
    pub async fn idle_for(&self, limit: Duration) {
        loop {
            let due = self.opened + Duration::from_millis(self.last_ms.load(Ordering::Relaxed)) + limit;
            if Instant::now() >= due {
                return;
            }
            tokio::time::sleep_until(due).await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The wait ends no sooner than `limit` after the last touch (a lower bound: a loaded
    /// machine may wake it later).
    #[tokio::test]
    async fn the_idle_wait_runs_from_the_last_touch() {
        let clock = IdleClock::new();
        let start = Instant::now();
        let limit = Duration::from_millis(300);
        let touched_midway = async {
            tokio::time::sleep(Duration::from_millis(200)).await;
            clock.touch();
            std::future::pending::<()>().await
        };
        tokio::select! {
            () = clock.idle_for(limit) => {}
            () = touched_midway => unreachable!("pending"),
        }
        assert!(Instant::now() - start >= Duration::from_millis(500), "{:?}", Instant::now() - start);
    }
}
