//! The simulated machine behind the simulated devices (DESIGN.md §4): a hammer or press
//! forging billet after billet (approach, blow, rebound, a pause, the next blow; a new
//! billet when one is finished), as one continuous stream of samples at the DAQ's rate,
//! with the sensor imperfections of `synth`. Transports (a pty with the serial framing, a
//! Modbus server, a candump log) encode what it yields. Pure: the caller paces it.

use std::collections::VecDeque;

use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;
use crate::physics::process::Process;
use crate::physics::sequence::SequenceError;
use crate::signal::capture::CaptureRow;
use crate::synth::{CaptureSpec, idle_rows, synth_blows};

/// One billet's worth of forging.
#[derive(Debug, Clone, PartialEq)]
pub struct BilletPlan {
    pub process: Process,
    /// Impact speed of each blow, m/s.
    pub v0s_mps: Vec<f64>,
}

/// `n` billets of `base`'s plan whose heights vary by up to `spread` (a fraction) around the
/// sheet's, drawn uniformly from `seed`; the first is the sheet's own height, since a
/// service learns the dies' position from the first billet it sees.
pub fn spread_plans(base: &BilletPlan, n: usize, spread: f64, seed: u64) -> Vec<BilletPlan> {
    use rand::SeedableRng;
    use rand_distr::Distribution;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let unit = rand_distr::Uniform::new_inclusive(-1.0, 1.0).expect("finite bounds");
    (0..n)
        .map(|i| {
            let mut plan = base.clone();
            if i > 0 && spread > 0.0 {
                plan.process.billet.height_m *= 1.0 + spread * unit.sample(&mut rng);
            }
            plan
        })
        .collect()
}

/// A machine forging a list of billets, blow after blow, with `interval_s` between blows.
pub struct SimMachine {
    machine: Machine,
    effects: EffectSet,
    plans: Vec<BilletPlan>,
    spec: CaptureSpec,
    interval_s: f64,
    next_billet: usize,
    queue: VecDeque<CaptureRow>,
    /// Samples emitted so far (the stream's clock is `t0 + n / rate`).
    emitted: u64,
    t0_s: f64,
    last_disp_m: f64,
    seed: u64,
    /// Stream sample index at which each billet started.
    billet_starts: Vec<u64>,
    /// Extra idle time before each billet after the first, s (a part being changed).
    billet_idle_s: f64,
    /// The simulated truth: each blow's billet height after it, m, in forging order.
    h_end_truth_m: Vec<f64>,
}

impl SimMachine {
    pub fn new(
        machine: Machine,
        effects: EffectSet,
        plans: Vec<BilletPlan>,
        spec: CaptureSpec,
        interval_s: f64,
    ) -> Self {
        let seed = spec.seed;
        SimMachine {
            machine,
            effects,
            plans,
            t0_s: spec.t_origin_s,
            spec,
            interval_s,
            next_billet: 0,
            queue: VecDeque::new(),
            emitted: 0,
            last_disp_m: 0.4375,
            seed,
            billet_starts: Vec::new(),
            billet_idle_s: 0.0,
            h_end_truth_m: Vec::new(),
        }
    }

    /// Stand idle this long more before each billet after the first, s.
    pub fn with_billet_idle(mut self, idle_s: f64) -> Self {
        self.billet_idle_s = idle_s.max(0.0);
        self
    }

    /// The simulated billet height after each blow forged so far, m (the truth a test
    /// compares the estimator's `h_end_m` with).
    pub fn h_end_truth_m(&self) -> &[f64] {
        &self.h_end_truth_m
    }

    pub fn sample_rate_hz(&self) -> f64 {
        self.spec.sample_rate_hz
    }

    /// Whether every billet has been forged and every sample handed out.
    pub fn finished(&self) -> bool {
        self.next_billet >= self.plans.len() && self.queue.is_empty()
    }

    /// How many billets the samples handed out so far reach into (1 from the first sample).
    pub fn billet_of_emitted(&self) -> usize {
        self.billet_starts.iter().filter(|&&s| s < self.emitted.max(1)).count()
    }

    /// Forge the next billet into the queue: for each blow, a pause, then the blow.
    fn forge_next_billet(&mut self) -> Result<(), SequenceError> {
        let plan = &self.plans[self.next_billet];
        self.next_billet += 1;
        self.billet_starts.push(self.emitted + self.queue.len() as u64);
        let mut spec = self.spec;
        spec.seed = self.seed.wrapping_add(self.next_billet as u64);
        let blows = synth_blows(&self.machine, &self.effects, &plan.process, &plan.v0s_mps, &spec)?;
        let idle_s = if self.next_billet > 1 { self.billet_idle_s } else { 0.0 };
        for (i, b) in blows.iter().enumerate() {
            self.h_end_truth_m.push(b.truth.forming.map_or(b.truth.h_start_m, |f| f.h_end_m));
            let interval_s = self.interval_s + if i == 0 { idle_s } else { 0.0 };
            let pause = ((interval_s * self.spec.sample_rate_hz) as usize).saturating_sub(b.rows.len());
            let disp0 = b.rows.first().map_or(self.last_disp_m, |r| r.disp_m);
            self.queue.extend(idle_rows(pause, 0.0, &spec, disp0, spec.seed.wrapping_mul(31).wrapping_add(i as u64)));
            self.queue.extend(b.rows.iter().copied());
            self.last_disp_m = b.rows.last().map_or(self.last_disp_m, |r| r.disp_m);
        }
        Ok(())
    }

    /// The next `n` samples (fewer once the last billet is done), on one continuous clock.
    pub fn next_rows(&mut self, n: usize) -> Result<Vec<CaptureRow>, SequenceError> {
        while self.queue.len() < n && self.next_billet < self.plans.len() {
            self.forge_next_billet()?;
        }
        let take = n.min(self.queue.len());
        let dt = 1.0 / self.spec.sample_rate_hz;
        let mut out: Vec<CaptureRow> = self.queue.drain(..take).collect();
        for r in &mut out {
            r.t_s = self.t0_s + self.emitted as f64 * dt;
            self.emitted += 1;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{parse_machine, parse_process};

    #[test]
    fn a_session_is_one_continuous_stream_holding_every_blow() {
        let m = parse_machine("m", include_str!("../config/hammer-lg1000.machine.toml")).unwrap().machine;
        let p = parse_process("p", include_str!("../config/steel-16NiCrMo13.process.toml")).unwrap();
        let plan = BilletPlan { process: p, v0s_mps: vec![3.9, 5.3] };
        let mut sim = SimMachine::new(m, EffectSet::NONE, vec![plan.clone(), plan], CaptureSpec::hammer(3), 0.5);
        let mut rows = Vec::new();
        while !sim.finished() {
            rows.extend(sim.next_rows(7919).unwrap());
        }
        // Four blows of 0.5 s each at 100 kHz.
        assert_eq!(rows.len(), 4 * 50_000);
        assert!(rows.windows(2).all(|w| ((w[1].t_s - w[0].t_s) - 1e-5).abs() < 1e-9));
        // Four distinct load peaks well above the noise.
        let peaks = rows.windows(2).filter(|w| w[0].load_n < 200e3 && w[1].load_n >= 200e3).count();
        assert!(peaks >= 4, "{peaks}");
    }
}

/// Quantise samples to a DAQ's counts, channel by channel (`count = (value - offset) /
/// gain`, saturating), interleaved as they go on the wire.
pub fn to_counts(rows: &[CaptureRow], channels: &[crate::acquire::ChannelSpec]) -> Vec<i32> {
    use crate::signal::sample::Role;
    let mut counts = Vec::with_capacity(rows.len() * channels.len());
    for r in rows {
        for c in channels {
            let v = match c.role {
                Role::Load => r.load_n,
                Role::Disp => r.disp_m,
                Role::Acc => r.acc_mps2,
            };
            counts.push(((v - c.offset) / c.gain).round().clamp(i32::MIN as f64, i32::MAX as f64) as i32);
        }
    }
    counts
}

/// Fault switches of a simulated serial device.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SerialFaults {
    /// Write this many garbage bytes before every `garbage_every`-th frame (0: never).
    pub garbage_every: u64,
    pub garbage_bytes: usize,
    /// Flip a byte inside every `corrupt_every`-th frame, so its CRC fails (0: never).
    pub corrupt_every: u64,
    /// Skip every `drop_every`-th frame (its sequence number is used up: a gap) (0: never).
    pub drop_every: u64,
    /// A channel that dies: from this many seconds into the stream it reads 0 counts (a
    /// broken cable, a charge amplifier gone; issue 43).
    pub dead: Option<(crate::signal::sample::Role, f64)>,
}

/// How a simulated serial device frames its samples.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialDeviceSpec {
    /// Channels in wire order, with the gain and offset the receiver will apply.
    pub channels: Vec<crate::acquire::ChannelSpec>,
    /// Samples per frame.
    pub frame_samples: usize,
    /// Pace frames at the sample rate (a live device) or write as fast as possible.
    pub realtime: bool,
    pub faults: SerialFaults,
}

/// What a simulated serial device wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DeviceStats {
    pub frames: u64,
    pub samples: u64,
    pub dropped_frames: u64,
    pub corrupted_frames: u64,
    pub garbage_bursts: u64,
}

/// Run `sim` to the end through the binary framing of docs/interfaces.md §7 into `writer`.
/// Stops early when `stop` turns true or the reader goes away.
/// `on_billet(k, device_ns)` is called when the stream reaches billet k (k = 2, 3, ...),
/// with the device time of the frame that starts it, as a PLC would signal a new billet.
pub async fn drive_serial<W: tokio::io::AsyncWrite + Unpin>(
    mut sim: SimMachine,
    spec: &SerialDeviceSpec,
    mut writer: W,
    mut stop: tokio::sync::watch::Receiver<bool>,
    mut on_billet: impl FnMut(usize, u64),
) -> std::io::Result<DeviceStats> {
    use crate::acquire::serial::frame::{Frame, encode_frame};
    use tokio::io::AsyncWriteExt;

    let rate = sim.sample_rate_hz();
    let period_ns = (1e9 / rate).round() as u32;
    let frame_dt = std::time::Duration::from_secs_f64(spec.frame_samples as f64 / rate);
    let start = tokio::time::Instant::now();
    let mut stats = DeviceStats::default();
    let mut seq: u32 = 0;
    let mut device_ns: u64 = 1_000_000_000;
    while !sim.finished() && !*stop.borrow() {
        let billet_before = sim.billet_of_emitted();
        let rows = sim.next_rows(spec.frame_samples).map_err(std::io::Error::other)?;
        if rows.is_empty() {
            break;
        }
        let billet_now = sim.billet_of_emitted();
        if billet_now > billet_before && billet_before > 0 {
            on_billet(billet_now, device_ns);
        }
        let mut counts = to_counts(&rows, &spec.channels);
        if let Some((role, from_s)) = spec.faults.dead
            && let Some(c) = spec.channels.iter().position(|ch| ch.role == role)
        {
            let n_ch = spec.channels.len();
            for i in 0..rows.len() {
                let t_s = (device_ns - 1_000_000_000) as f64 * 1e-9 + i as f64 * f64::from(period_ns) * 1e-9;
                if t_s >= from_s {
                    counts[i * n_ch + c] = 0;
                }
            }
        }
        let frame = Frame {
            channel_count: spec.channels.len() as u8,
            sample_count: rows.len() as u16,
            sequence: seq,
            device_time_ns: device_ns,
            sample_period_ns: period_ns,
            counts,
        };
        seq = seq.wrapping_add(1);
        device_ns += u64::from(period_ns) * rows.len() as u64;
        stats.frames += 1;
        let f = spec.faults;
        let nth = |every: u64| every > 0 && stats.frames % every == 0;
        if nth(f.drop_every) {
            stats.dropped_frames += 1;
        } else {
            if nth(f.garbage_every) {
                stats.garbage_bursts += 1;
                // Bytes that are not a valid frame and hold no 0x00 (no delimiter).
                let junk: Vec<u8> = (0..f.garbage_bytes).map(|i| (i as u8).wrapping_mul(37) | 1).collect();
                if !write_unless_stopped(&mut writer, &junk, &mut stop).await? {
                    break;
                }
            }
            let mut bytes = encode_frame(&frame);
            if nth(f.corrupt_every) && bytes.len() > 8 {
                stats.corrupted_frames += 1;
                let i = bytes.len() / 2;
                bytes[i] = if bytes[i] == 0x55 { 0x56 } else { 0x55 };
            }
            if !write_unless_stopped(&mut writer, &bytes, &mut stop).await? {
                break;
            }
            stats.samples += rows.len() as u64;
        }
        if spec.realtime {
            tokio::time::sleep_until(start + frame_dt * stats.frames as u32).await;
        }
    }
    if !*stop.borrow() {
        writer.flush().await?;
    }
    Ok(stats)
}

/// One serial line of a machine whose channels are spread over several DAQs (the load and
/// accelerometer on one, the ram encoder on another), each on its own crystal.
#[derive(Debug)]
pub struct SplitLine<W> {
    /// The channels this DAQ sends, with the gain and offset the receiver will apply.
    pub channels: Vec<crate::acquire::ChannelSpec>,
    /// Send every `decimate`-th sample (a slower DAQ), ≥ 1.
    pub decimate: usize,
    /// Device time of the stream's first sample, ns.
    pub clock_offset_ns: u64,
    /// How fast the DAQ's crystal runs against true time, ppm (its time stamps and its
    /// stated sample period both carry it).
    pub clock_ppm: f64,
    pub writer: W,
}

/// Write `bytes` unless `stop` turns true first; whether they were written. A reader that
/// went away (a killed service) leaves the pty's buffer full, and a plain write would block
/// the device for ever; a dropped `stop` sender never stops it.
async fn write_unless_stopped<W: tokio::io::AsyncWrite + Unpin>(
    writer: &mut W,
    bytes: &[u8],
    stop: &mut tokio::sync::watch::Receiver<bool>,
) -> std::io::Result<bool> {
    use tokio::io::AsyncWriteExt;
    let stopped = async {
        if stop.wait_for(|s| *s).await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    tokio::select! {
        r = writer.write_all(bytes) => r.map(|()| true),
        () = stopped => Ok(false),
    }
}

/// Run `sim` to the end, in real time, framing each line's channels (docs/interfaces.md §7) into
/// its own writer, frames of `frame_samples` samples of the simulated machine.
/// `on_billet(k, device_ns)` gets the first line's device time where billet k starts.
pub async fn drive_serial_split<W: tokio::io::AsyncWrite + Unpin>(
    mut sim: SimMachine,
    frame_samples: usize,
    mut lines: Vec<SplitLine<W>>,
    mut stop: tokio::sync::watch::Receiver<bool>,
    mut on_billet: impl FnMut(usize, u64),
) -> std::io::Result<u64> {
    use crate::acquire::serial::frame::{Frame, encode_frame};
    use tokio::io::AsyncWriteExt;

    let rate = sim.sample_rate_hz();
    let true_period_ns = 1e9 / rate;
    let frame_dt = std::time::Duration::from_secs_f64(frame_samples as f64 / rate);
    let start = tokio::time::Instant::now();
    let (mut frames, mut emitted) = (0u64, 0u64);
    while !sim.finished() && !*stop.borrow() {
        let billet_before = sim.billet_of_emitted();
        let rows = sim.next_rows(frame_samples).map_err(std::io::Error::other)?;
        if rows.is_empty() {
            break;
        }
        let billet_now = sim.billet_of_emitted();
        for (k, line) in lines.iter_mut().enumerate() {
            let d = line.decimate.max(1) as u64;
            let scale = 1.0 + line.clock_ppm * 1e-6;
            // The first sample of this frame the line keeps.
            let first = emitted.div_ceil(d) * d;
            let kept: Vec<CaptureRow> = rows
                .iter()
                .enumerate()
                .filter(|(i, _)| (emitted + *i as u64).is_multiple_of(d))
                .map(|(_, r)| *r)
                .collect();
            let device_ns = line.clock_offset_ns + (first as f64 * true_period_ns * scale).round() as u64;
            if k == 0 && billet_now > billet_before && billet_before > 0 {
                on_billet(billet_now, device_ns);
            }
            if kept.is_empty() {
                continue;
            }
            let frame = Frame {
                channel_count: line.channels.len() as u8,
                sample_count: kept.len() as u16,
                sequence: frames as u32,
                device_time_ns: device_ns,
                sample_period_ns: (true_period_ns * d as f64 * scale).round() as u32,
                counts: to_counts(&kept, &line.channels),
            };
            if !write_unless_stopped(&mut line.writer, &encode_frame(&frame), &mut stop).await? {
                return Ok(frames);
            }
        }
        emitted += rows.len() as u64;
        frames += 1;
        tokio::time::sleep_until(start + frame_dt * frames as u32).await;
    }
    for line in lines.iter_mut().filter(|_| !*stop.borrow()) {
        line.writer.flush().await?;
    }
    Ok(frames)
}
