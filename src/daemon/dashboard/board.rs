//! What the dashboard shows beyond `/status`, kept by the status snapshot as the service's
//! events come (no second computation): the last `RECENT_BLOWS` blows' results (docs/interfaces.md
//! §5) with the time of day each struck, the blows of the billet in the dies (the efficiency
//! bars), the last acknowledged alert, the last blow's curve (`estimate::curve`), and each
//! source's measured sample rate. A page that loads or reconnects reads it whole from
//! `GET /dashboard/state`.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use serde::Serialize;

use crate::estimate::BlowEstimate;
use crate::estimate::curve::BlowCurve;
use crate::estimate::result::Alert;
use crate::signal::align::ClockModel;
use crate::signal::sample::{Role, SampleBatch};

/// Rows of the dashboard's table of blows.
pub const RECENT_BLOWS: usize = 50;

/// Host time over which a source's rate is measured, ns: several batches of any source
/// (Modbus polls, CAN batches of 20 ms, serial frames), short enough to follow a stall.
pub const RATE_WINDOW_NS: i64 = 3_000_000_000;

/// A source silent for this long, host time, is measured at 0 Hz.
pub const RATE_SILENT_NS: i64 = 2_000_000_000;

/// A row of the table: a blow's result and when it struck.
#[derive(Debug, Clone, Serialize)]
pub struct BoardBlow {
    #[serde(flatten)]
    pub estimate: BlowEstimate,
    /// First contact on the host's wall clock, s since the Unix epoch: the device time
    /// mapped through the timeline source's clock (`Board::on_samples`); `None` before any
    /// batch of it. The page shows it as the time of day in its own zone.
    pub t_contact_unix_s: Option<f64>,
}

/// The dashboard's state.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Board {
    /// The last `RECENT_BLOWS` blows, newest first.
    pub recent_blows: VecDeque<BoardBlow>,
    /// The blows of the billet in the dies, in order (empty once it is finished).
    pub billet_blows: Vec<BlowEstimate>,
    /// The alert the operator acknowledged last; `None` once a new alert is latched.
    pub acknowledged_alert: Option<Alert>,
    /// The last blow's curve (served on its own, `GET /blow/last/curve`).
    #[serde(skip)]
    pub curve: Option<Arc<BlowCurve>>,
    /// Host minus device time of the timeline, ns: of the latest batch carrying the
    /// acceleration (the merge's timeline, `signal::merge`, and a single DAQ's batches).
    #[serde(skip)]
    timeline_offset_ns: Option<i64>,
    /// Per source, (host receive ns, samples received up to that batch), over the last
    /// `RATE_WINDOW_NS`.
    #[serde(skip)]
    arrivals: BTreeMap<String, VecDeque<(i64, u64)>>,
}

impl Board {
    /// A batch arrived: its source's rate, and the timeline's clock. `clock` maps its
    /// source's device time onto the host's (`signal::align`), once fitted.
    pub fn on_samples(&mut self, b: &SampleBatch, clock: Option<&ClockModel>) {
        let marks = self.arrivals.entry(b.source.clone()).or_default();
        let total = marks.back().map_or(0, |m| m.1) + b.len() as u64;
        marks.push_back((b.host_time_ns, total));
        while marks.len() > 2 && marks.front().is_some_and(|m| b.host_time_ns - m.0 > RATE_WINDOW_NS) {
            marks.pop_front();
        }
        if b.channel(Role::Acc).is_some() && !b.is_empty() {
            self.timeline_offset_ns = Some(match clock.filter(|c| c.len() >= 2) {
                Some(c) => c.map(b.device_time_ns) - b.device_time_ns,
                // Not fitted yet: the batch's last sample reached the host when it did.
                None => b.host_time_ns - (b.device_time_ns + ((b.len() - 1) as f64 * b.period_ns) as i64),
            });
        }
    }

    /// Each source's sample rate, Hz, as measured at host time `now_ns`: the samples of
    /// the batches after the window's first over the host time between them; 0 for a source
    /// silent for `RATE_SILENT_NS`, `None` before two batches.
    pub fn rates_hz(&self, now_ns: i64) -> BTreeMap<String, Option<f64>> {
        let rate = |m: &VecDeque<(i64, u64)>| match (m.front(), m.back()) {
            (Some(_), Some(last)) if now_ns - last.0 > RATE_SILENT_NS => Some(0.0),
            (Some(first), Some(last)) if last.0 > first.0 => {
                Some((last.1 - first.1) as f64 / ((last.0 - first.0) as f64 * 1e-9))
            }
            _ => None,
        };
        self.arrivals.iter().map(|(k, m)| (k.clone(), rate(m))).collect()
    }

    pub fn on_blow(&mut self, e: &BlowEstimate) {
        if self.recent_blows.len() == RECENT_BLOWS {
            self.recent_blows.pop_back();
        }
        let t_contact_unix_s = self.timeline_offset_ns.map(|off| e.t_contact_s + off as f64 * 1e-9);
        self.recent_blows.push_front(BoardBlow { estimate: e.clone(), t_contact_unix_s });
        if self.billet_blows.last().is_some_and(|b| b.billet.billet != e.billet.billet) {
            self.billet_blows.clear();
        }
        self.billet_blows.push(e.clone());
        if e.alert.is_some() {
            self.acknowledged_alert = None;
        }
    }

    /// The billet in the dies was finished (the next one started).
    pub fn on_billet_finished(&mut self) {
        self.billet_blows.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::{BilletTag, BlowClass};

    fn blow(n: u32, billet: u32) -> BlowEstimate {
        BlowEstimate {
            kinetic_in_j: Some(10_000.0),
            plastic_j: Some(8_000.0),
            efficiency: Some(0.8),
            class: BlowClass::Soft,
            peak_load_n: 1e6,
            billet: BilletTag { billet, billet_blow: n, billet_check: None, h_start_off_sheet_m: None },
            ..BlowEstimate::incomplete(n, f64::from(n), 5.3, f64::from(n) + 0.02)
        }
    }

    #[test]
    fn the_table_keeps_the_last_fifty_newest_first_and_the_bars_one_billet() {
        let mut b = Board::default();
        for n in 1..=60 {
            b.on_blow(&blow(n, 1 + u32::from(n > 55)));
        }
        let rows: Vec<u32> = b.recent_blows.iter().map(|e| e.estimate.blow).collect();
        assert_eq!(rows, (11..=60).rev().collect::<Vec<_>>());
        // Billet 2 began at blow 56: the bars show its five blows only.
        let bars: Vec<u32> = b.billet_blows.iter().map(|e| e.blow).collect();
        assert_eq!(bars, [56, 57, 58, 59, 60]);
        b.on_billet_finished();
        assert!(b.billet_blows.is_empty());
    }

    fn batch(source: &str, host_ns: i64, device_ns: i64, n: usize, roles: Vec<Role>) -> SampleBatch {
        SampleBatch {
            source: source.into(),
            seq: 0,
            device_time_ns: device_ns,
            host_time_ns: host_ns,
            period_ns: 10_000.0,
            values: vec![0.0; n * roles.len()],
            roles,
        }
    }

    #[test]
    fn rates_are_measured_on_the_host_clock_and_fall_to_zero_when_a_source_stops() {
        let mut b = Board::default();
        // 100 kHz in batches of 1000 every 10 ms, for 5 s.
        for k in 0..500 {
            b.on_samples(&batch("daq", 1_000_000_000 + k * 10_000_000, k * 10_000_000, 1000, vec![Role::Acc]), None);
        }
        let last = 1_000_000_000 + 499 * 10_000_000;
        let hz = b.rates_hz(last)["daq"].expect("measured");
        assert!((hz - 100e3).abs() < 1.0, "{hz}");
        assert_eq!(b.rates_hz(last + RATE_SILENT_NS + 1)["daq"], Some(0.0));
        // One batch: no rate yet.
        b.on_samples(&batch("can", last, 0, 10, vec![Role::Disp]), None);
        assert_eq!(b.rates_hz(last)["can"], None);
    }

    #[test]
    fn a_blow_gets_its_time_of_day_from_the_timeline_sources_clock() {
        let mut b = Board::default();
        b.on_blow(&blow(1, 1));
        assert_eq!(b.recent_blows[0].t_contact_unix_s, None, "no batch yet");
        // The device started 1.7e9 s after the epoch; its batch of 100 samples at 10 µs
        // reached the host as its last sample was taken. A source without the acceleration
        // is not the timeline.
        let t0_ns = 1_700_000_000_000_000_000;
        b.on_samples(&batch("daq", t0_ns + 990_000, 0, 100, vec![Role::Acc, Role::Load]), None);
        b.on_samples(&batch("enc", 5, 0, 100, vec![Role::Disp]), None);
        b.on_blow(&blow(2, 1));
        let t = b.recent_blows[0].t_contact_unix_s.expect("mapped");
        assert!((t - (1.7e9 + 2.0)).abs() < 1e-3, "{t}");
        let row = serde_json::to_value(&b.recent_blows[0]).expect("serialises");
        assert_eq!((row["blow"].as_u64(), row["class"].as_str()), (Some(2), Some("soft")), "{row}");
    }
}
