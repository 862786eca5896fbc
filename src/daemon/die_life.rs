//! Die life in the running service (issue 44): the die set in the hammer counted blow by
//! blow (`history::die::DieCount`, the same count the history database keeps), from where
//! the history database left each set at the start, a `die_life` alert when it reaches
//! `[die_life]`'s warning and again at its limit, and its state in `/status` `die_life`.

use std::collections::HashMap;
use std::path::PathBuf;

use serde::Serialize;

use crate::config::history::DieLifeConfig;
use crate::estimate::BlowEstimate;
use crate::estimate::result::{Alert, AlertKind};
use crate::history::die::{DieCount, DieLevel, all_latest};

/// `/status` `die_life`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DieLifeStatus {
    #[serde(flatten)]
    pub count: DieCount,
    pub level: DieLevel,
    pub warn_blows: Option<u64>,
    pub limit_blows: Option<u64>,
    #[serde(rename = "warn_energy_J")]
    pub warn_energy_j: Option<f64>,
    #[serde(rename = "limit_energy_J")]
    pub limit_energy_j: Option<f64>,
}

pub(super) struct DieLife {
    cfg: DieLifeConfig,
    /// The die set the blows are struck on now (`part`'s `die_set`).
    in_force: Option<String>,
    count: DieCount,
    level: DieLevel,
    /// Every other die set's count: as the history database held them at the start (read
    /// once: the history's writer counts this run's blows too, a moment later), and as this
    /// run left them.
    others: HashMap<Option<String>, DieCount>,
}

impl DieLife {
    /// The die set `name` as the history database last counted it (none there, or no
    /// database: from zero at `now_ns`).
    pub fn start(cfg: DieLifeConfig, history: Option<PathBuf>, name: Option<&str>, now_ns: i64) -> Self {
        let stored = history.as_deref().filter(|p| p.is_file()).map_or_else(Vec::new, |p| {
            crate::history::query::open_read(p)
                .map_err(|e| e.to_string())
                .and_then(|conn| all_latest(&conn).map_err(|e| format!("{}: {e}", p.display())))
                .unwrap_or_else(|e| {
                    tracing::warn!("die life: the counts so far cannot be read, counting from zero: {e}");
                    Vec::new()
                })
        });
        let others = stored.into_iter().map(|c| (c.die_set.clone(), c)).collect();
        let in_force = name.map(str::to_string);
        let mut d = DieLife { cfg, in_force, count: DieCount::default(), level: DieLevel::Ok, others };
        d.take_up(now_ns);
        d
    }

    /// Count on the die set in force from here: as last counted, or from zero.
    fn take_up(&mut self, now_ns: i64) {
        let name = self.in_force.clone();
        let count = self.others.remove(&name).unwrap_or_else(|| DieCount::new(name, now_ns));
        let left = std::mem::replace(&mut self.count, count);
        if left.blows > 0 {
            self.others.insert(left.die_set.clone(), left);
        }
        self.level = self.count.level(&self.cfg).0;
    }

    /// New dies, named `name`: from zero.
    pub fn change(&mut self, name: Option<&str>, now_ns: i64) {
        self.in_force = name.map(str::to_string);
        self.others.remove(&self.in_force);
        let left = std::mem::replace(&mut self.count, DieCount::new(self.in_force.clone(), now_ns));
        if left.blows > 0 && left.die_set != self.in_force {
            self.others.insert(left.die_set.clone(), left);
        }
        self.level = DieLevel::Ok;
    }

    /// The blows from here on are struck on die set `name` (counted from its first blow).
    pub fn struck_on(&mut self, name: Option<&str>) {
        self.in_force = name.map(str::to_string);
    }

    /// Count blow `e`; the alert when its die set reached a new level.
    pub fn on_blow(&mut self, e: &BlowEstimate, now_ns: i64) -> Option<Alert> {
        if self.count.die_set != self.in_force {
            self.take_up(now_ns);
        }
        self.count.add(e);
        let (level, quantity) = self.count.level(&self.cfg);
        if level <= self.level {
            return None;
        }
        self.level = level;
        let c = &self.count;
        let figures = [("blows", c.blows as f64), ("hard_blows", c.hard_blows as f64), ("energy_J", c.energy_j)];
        Some(Alert {
            kind: AlertKind::DieLife,
            blow: e.blow,
            reason: c.reason(level, quantity, &self.cfg),
            figures: figures.into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
        })
    }

    pub fn status(&self) -> DieLifeStatus {
        DieLifeStatus {
            count: self.count.clone(),
            level: self.level,
            warn_blows: self.cfg.warn_blows,
            limit_blows: self.cfg.limit_blows,
            warn_energy_j: self.cfg.warn_energy_j,
            limit_energy_j: self.cfg.limit_energy_j,
        }
    }
}
