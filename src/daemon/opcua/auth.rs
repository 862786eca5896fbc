//! Who may connect to the OPC UA server and open a session, and how fast wrong passwords
//! are answered.
//!
//! [`Gate`] is the server's accept gate (a patch of the vendored async-opcua-server,
//! `vendor/async-opcua-server/FORGEMON.md`): each connection takes a slot under
//! `max_connections` when it is accepted (`daemon::slots`), and is admitted once a session
//! on it is activated; at the cap a newcomer takes the slot of the oldest connection
//! without one, which is closed.
//!
//! [`Authenticator`] wraps async-opcua's `DefaultAuthenticator` (which checks the user and
//! password and offers the token policies) with a [`LoginThrottle`] per peer address: after
//! [`FREE_FAILURES`] wrong passwords in a row from one address, its logins are checked one
//! at a time, at most one every [`SPACING`] (2 a second); a try waits for its turn, and one
//! that would wait [`MAX_WAITING`] turns or more (4 s) is refused unchecked. A right
//! password ends the throttling. Other addresses' logins are not slowed.

use std::collections::{BTreeMap, HashMap};
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use opcua::server::authenticator::{AuthManager, DefaultAuthenticator, Password, UserToken};
use opcua::server::{AcceptGate, Admitted, ServerEndpoint, ServerUserToken};
use opcua::types::{Error, StatusCode, UserTokenPolicy};
use tokio::time::Instant;

use crate::daemon::slots::{Slot, Slots};

/// Wrong passwords in a row answered at once.
pub const FREE_FAILURES: u32 = 10;
/// Then one login checked per this time: 2 a second.
pub const SPACING: Duration = Duration::from_millis(500);
/// Turns a login may wait at most; one that would wait longer is refused unchecked.
pub const MAX_WAITING: u32 = 8;

/// When a login may be checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Turn {
    Now,
    At(Instant),
    /// Too many wait already.
    Refused,
}

/// The login throttle (module doc), fed the time of each login and its outcome.
#[derive(Debug, Default)]
pub struct LoginThrottle {
    failures: u32,
    /// The earliest time the next throttled login is checked.
    next: Option<Instant>,
}

impl LoginThrottle {
    /// The turn of a login arriving at `now`.
    pub fn turn(&mut self, now: Instant) -> Turn {
        if self.failures < FREE_FAILURES {
            return Turn::Now;
        }
        let at = self.next.map_or(now, |n| n.max(now));
        if at >= now + SPACING * MAX_WAITING {
            return Turn::Refused;
        }
        self.next = Some(at + SPACING);
        if at == now { Turn::Now } else { Turn::At(at) }
    }

    /// A checked login's outcome.
    pub fn outcome(&mut self, ok: bool) {
        if ok {
            *self = LoginThrottle::default();
        } else {
            self.failures = self.failures.saturating_add(1);
        }
    }
}

/// Peers whose failures are remembered; past this, those not throttled are forgotten, and
/// while it is still full, new peers share one throttle.
pub const MAX_PEERS: usize = 4096;

/// What a connection's task knows of its connection (the accept gate's context).
#[derive(Debug)]
pub struct Connection {
    pub peer: SocketAddr,
    slot: Slot,
}

/// The connection whose task calls this (an `AuthManager` method), if the gate admitted it.
pub fn connection() -> Option<Arc<Connection>> {
    opcua::server::connection_context()?.downcast::<Connection>().ok()
}

/// The server's accept gate (module doc).
pub struct Gate {
    pub slots: Slots,
}

impl AcceptGate for Gate {
    fn admit(&self, peer: SocketAddr) -> Option<Admitted> {
        let Some(slot) = self.slots.open() else {
            tracing::debug!(%peer, "OPC UA connection refused: every slot holds a session");
            return None;
        };
        let connection = Arc::new(Connection { peer, slot });
        let watched = connection.clone();
        let close = Box::pin(async move {
            watched.slot.shed().await;
            tracing::debug!(peer = %watched.peer, "OPC UA connection without a session closed for a newcomer");
        });
        Some(Admitted { context: connection, close })
    }
}

/// The throttles by peer address; `None` is a login with no known peer, or one past
/// [`MAX_PEERS`].
#[derive(Debug, Default)]
struct Throttles(HashMap<Option<IpAddr>, LoginThrottle>);

impl Throttles {
    fn of(&mut self, peer: Option<IpAddr>) -> &mut LoginThrottle {
        let full = self.0.len() >= MAX_PEERS && !self.0.contains_key(&peer);
        if full {
            self.0.retain(|_, t| t.failures >= FREE_FAILURES);
        }
        let key = if self.0.len() >= MAX_PEERS && !self.0.contains_key(&peer) { None } else { peer };
        self.0.entry(key).or_default()
    }

    /// A checked login's outcome; a peer with a right password is forgotten.
    fn outcome(&mut self, peer: Option<IpAddr>, ok: bool) {
        let key = if self.0.contains_key(&peer) { peer } else { None };
        self.of(key).outcome(ok);
        if ok {
            self.0.remove(&key);
        }
    }
}

/// The server's authenticator: async-opcua's, behind the login throttles.
pub struct Authenticator {
    inner: DefaultAuthenticator,
    throttles: Mutex<Throttles>,
}

impl Authenticator {
    pub fn new(users: BTreeMap<String, ServerUserToken>) -> Self {
        Authenticator { inner: DefaultAuthenticator::new(users), throttles: Mutex::default() }
    }

    fn throttles(&self) -> std::sync::MutexGuard<'_, Throttles> {
        self.throttles.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// A session on the calling connection was activated: it keeps its slot.
fn admitted() {
    if let Some(c) = connection() {
        c.slot.admit();
    }
}

#[async_trait::async_trait]
impl AuthManager for Authenticator {
    async fn authenticate_anonymous_token(&self, endpoint: &ServerEndpoint) -> Result<(), Error> {
        let result = self.inner.authenticate_anonymous_token(endpoint).await;
        if result.is_ok() {
            admitted();
        }
        result
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let peer = connection().map(|c| c.peer.ip());
        let turn = self.throttles().of(peer).turn(Instant::now());
        match turn {
            Turn::Now => {}
            Turn::At(at) => tokio::time::sleep_until(at).await,
            Turn::Refused => {
                tracing::warn!(user = username, ?peer, "OPC UA login refused unchecked: too many wrong passwords");
                return Err(Error::new(StatusCode::BadUserAccessDenied, "too many failed logins; try again later"));
            }
        }
        let result = self.inner.authenticate_username_identity_token(endpoint, username, password).await;
        self.throttles().outcome(peer, result.is_ok());
        match result {
            Ok(_) => admitted(),
            Err(_) => tracing::warn!(user = username, ?peer, "OPC UA login failed: wrong user or password"),
        }
        result
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        self.inner.user_token_policies(endpoint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn after_ten_failures_logins_are_spaced_and_a_queue_is_refused() {
        let mut t = LoginThrottle::default();
        let t0 = Instant::now();
        for _ in 0..FREE_FAILURES {
            assert_eq!(t.turn(t0), Turn::Now);
            t.outcome(false);
        }
        // Ten tries arriving together: the first now, then one every 0.5 s, and past eight
        // waiting turns refused.
        let turns: Vec<Turn> = (0..10).map(|_| t.turn(t0)).collect();
        assert_eq!(turns[0], Turn::Now);
        for (k, turn) in turns.iter().enumerate().take(MAX_WAITING as usize).skip(1) {
            assert_eq!(*turn, Turn::At(t0 + SPACING * k as u32), "try {k}");
        }
        assert_eq!(turns[8..], [Turn::Refused, Turn::Refused]);
        // Later, the queue has drained: a try is checked at once.
        let later = t0 + SPACING * 20;
        assert_eq!(t.turn(later), Turn::Now);
        assert_eq!(t.turn(later), Turn::At(later + SPACING));
        // The right password ends it.
        t.outcome(true);
        assert_eq!(t.turn(later), Turn::Now);
        assert_eq!(t.turn(later), Turn::Now);
    }

    #[test]
    fn each_peer_has_its_own_throttle_and_a_full_table_shares_one() {
        let mut t = Throttles::default();
        let (a, b) = (Some(IpAddr::from([10, 0, 0, 1])), Some(IpAddr::from([10, 0, 0, 2])));
        let t0 = Instant::now();
        for _ in 0..FREE_FAILURES {
            assert_eq!(t.of(a).turn(t0), Turn::Now);
            t.outcome(a, false);
        }
        assert_eq!(t.of(a).turn(t0), Turn::Now);
        assert_eq!(t.of(a).turn(t0), Turn::At(t0 + SPACING), "a is throttled");
        assert_eq!(t.of(b).turn(t0), Turn::Now, "b is not");
        assert_eq!(t.of(b).turn(t0), Turn::Now);
        t.outcome(b, true);
        assert!(!t.0.contains_key(&b), "a peer with a right password is forgotten");
        // A full table forgets the peers not throttled, and past that new peers share one.
        for k in 0..MAX_PEERS as u32 {
            let p = Some(IpAddr::from(((k + 1) << 8).to_be_bytes()));
            t.of(p).turn(t0);
            t.outcome(p, false);
        }
        assert!(t.0.len() <= MAX_PEERS);
        assert_eq!(t.of(a).turn(t0), Turn::At(t0 + SPACING * 2), "the throttled peer is remembered");
    }
}
