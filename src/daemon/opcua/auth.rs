//! Who may open an OPC UA session, and how fast wrong passwords are answered.
//!
//! [`Authenticator`] wraps async-opcua's `DefaultAuthenticator` (which checks the user and
//! password and offers the token policies) with a [`LoginThrottle`]: after
//! [`FREE_FAILURES`] wrong passwords in a row, logins are checked one at a time, at most one
//! every [`SPACING`] (2 a second); a try waits for its turn, and one that would wait
//! [`MAX_WAITING`] turns or more (4 s) is refused unchecked. A right password ends the
//! throttling.
//!
//! The throttle is the server's, not a peer's: async-opcua 0.19 tells an `AuthManager`
//! the endpoint, user and password of a login but not the client's address or certificate,
//! so wrong passwords from one peer slow every peer's logins, never beyond 2 a second.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::Duration;

use opcua::server::authenticator::{AuthManager, DefaultAuthenticator, Password, UserToken};
use opcua::server::{ServerEndpoint, ServerUserToken};
use opcua::types::{Error, StatusCode, UserTokenPolicy};
use tokio::time::Instant;

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

/// The server's authenticator: async-opcua's, behind the login throttle.
pub struct Authenticator {
    inner: DefaultAuthenticator,
    throttle: Mutex<LoginThrottle>,
}

impl Authenticator {
    pub fn new(users: BTreeMap<String, ServerUserToken>) -> Self {
        Authenticator { inner: DefaultAuthenticator::new(users), throttle: Mutex::default() }
    }

    fn throttle(&self) -> std::sync::MutexGuard<'_, LoginThrottle> {
        self.throttle.lock().unwrap_or_else(|p| p.into_inner())
    }
}

#[async_trait::async_trait]
impl AuthManager for Authenticator {
    async fn authenticate_anonymous_token(&self, endpoint: &ServerEndpoint) -> Result<(), Error> {
        self.inner.authenticate_anonymous_token(endpoint).await
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        let turn = self.throttle().turn(Instant::now());
        match turn {
            Turn::Now => {}
            Turn::At(at) => tokio::time::sleep_until(at).await,
            Turn::Refused => {
                tracing::warn!(user = username, "OPC UA login refused unchecked: too many wrong passwords");
                return Err(Error::new(StatusCode::BadUserAccessDenied, "too many failed logins; try again later"));
            }
        }
        let result = self.inner.authenticate_username_identity_token(endpoint, username, password).await;
        self.throttle().outcome(result.is_ok());
        if result.is_err() {
            tracing::warn!(user = username, "OPC UA login failed: wrong user or password");
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
}
