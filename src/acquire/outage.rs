//! What the log says about a source that cannot be opened (issue 40): the first failure at
//! warn level with the path and the cause, again only when the cause changes or every
//! `OUTAGE_REPEAT_S` while it stays down, so a missing port does not flood the journal, and
//! at info level when it opens again. Pure: the driver passes in the host clock and logs the
//! lines it is handed (`/status` shows every attempt; the log, the changes).

/// How often a source that stays down for the same cause is logged again, s.
pub const OUTAGE_REPEAT_S: i64 = 300;

const NS_PER_S: i64 = 1_000_000_000;

/// One source's outage, as logged so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OutageLog {
    /// When the source went down (a failed open or a lost link), host ns; `None`: it is up.
    since_ns: Option<i64>,
    /// The cause last logged and when.
    logged: Option<(String, i64)>,
    /// Failed opens since it went down.
    attempts: u64,
}

impl OutageLog {
    pub fn new() -> Self {
        Self::default()
    }

    /// The link was lost at `now_ns` (the driver logs that itself): a later open is a
    /// return.
    pub fn lost(&mut self, now_ns: i64) {
        self.since_ns.get_or_insert(now_ns);
    }

    /// An open failed at `now_ns` with `cause` (the path and the error): the warning to log,
    /// when the outage is new, the cause changed or `OUTAGE_REPEAT_S` passed since the last.
    pub fn failed(&mut self, cause: &str, now_ns: i64) -> Option<String> {
        let since = *self.since_ns.get_or_insert(now_ns);
        self.attempts += 1;
        let line = match &self.logged {
            None => format!("cannot open {cause}; retrying, logged again when the cause changes"),
            Some((last, _)) if last != cause => format!("cannot open {cause} (the cause changed); retrying"),
            Some((_, at)) if now_ns - at >= OUTAGE_REPEAT_S * NS_PER_S => format!(
                "still cannot open {cause}: {} failed attempts in {:.0} min",
                self.attempts,
                (now_ns - since) as f64 / (60 * NS_PER_S) as f64
            ),
            Some(_) => return None,
        };
        self.logged = Some((cause.to_string(), now_ns));
        Some(line)
    }

    /// The source opened at `now_ns`: the line to log at info when it was down (`None` at
    /// its first open).
    pub fn opened(&mut self, path: &str, now_ns: i64) -> Option<String> {
        let since = self.since_ns.take()?;
        let attempts = std::mem::take(&mut self.attempts);
        self.logged = None;
        Some(format!(
            "{path} is open again after {:.1} s down ({attempts} failed open attempt{})",
            (now_ns - since) as f64 / NS_PER_S as f64,
            if attempts == 1 { "" } else { "s" }
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = NS_PER_S;

    #[test]
    fn a_missing_port_is_logged_once_then_on_a_new_cause_or_every_five_minutes() {
        let mut log = OutageLog::new();
        let enoent = "/dev/ttyUSB0: No such file or directory (os error 2)";
        let first = log.failed(enoent, 10 * S).unwrap();
        assert!(first.starts_with("cannot open /dev/ttyUSB0: No such file"), "{first}");
        // A retry every second for a minute: nothing more.
        assert!((11..70).all(|t| log.failed(enoent, t * S).is_none()));
        // Another cause: logged at once.
        let eacces = "/dev/ttyUSB0: Permission denied (os error 13)";
        assert!(log.failed(eacces, 71 * S).unwrap().contains("the cause changed"));
        assert_eq!(log.failed(eacces, 72 * S), None);
        // The same cause five minutes after it was last logged: logged again, with the count.
        assert_eq!(log.failed(eacces, (71 + OUTAGE_REPEAT_S - 1) * S), None);
        let again = log.failed(eacces, (71 + OUTAGE_REPEAT_S) * S).unwrap();
        assert!(again.starts_with("still cannot open") && again.contains("failed attempts in 6 min"), "{again}");
        // Back: one info line, and a later outage is new.
        let back = log.opened("/dev/ttyUSB0", 400 * S).unwrap();
        assert!(back.starts_with("/dev/ttyUSB0 is open again after 390.0 s down"), "{back}");
        assert_eq!(log.opened("/dev/ttyUSB0", 401 * S), None);
        assert!(log.failed(enoent, 500 * S).unwrap().starts_with("cannot open"));
    }

    #[test]
    fn the_first_open_is_not_a_return_but_one_after_a_lost_link_is() {
        let mut log = OutageLog::new();
        assert_eq!(log.opened("p", 0), None);
        log.lost(5 * S);
        assert_eq!(
            log.opened("p", 7 * S).as_deref(),
            Some("p is open again after 2.0 s down (0 failed open attempts)")
        );
    }
}
