//! Block mode: forgemon's own convention for a DAQ that buffers samples in a ring of
//! holding registers (the layout is documented in the module docs of `acquire::modbus`).
//! Pure code: [`BlockTracker`] is fed the header words and plans which ring slots to read,
//! notices lost samples (a counter jump larger than the ring) and decodes the slots;
//! [`RingWriter`] is the device's side, used by the simulated server. Neither does IO.

use super::registers::MAX_READ_REGISTERS;
use crate::acquire::ChannelSpec;

/// Registers before the ring.
pub const HEADER_REGISTERS: u16 = 8;
/// Slots the reader keeps away from the writer's overwrite edge: a slot that old may be
/// rewritten between reading the header and reading the slot, so it counts as lost.
pub const RING_MARGIN_DIVISOR: u32 = 8;

/// The block header (registers `base..base + 8`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockHeader {
    /// Samples written since the device started, wrapping (registers 0..1, high word first).
    pub counter: u32,
    /// Sample period, ns (registers 2..3, high word first).
    pub period_ns: u32,
    /// Slots in the ring, N (register 4).
    pub ring_len: u16,
    /// Channels per sample, C (register 5).
    pub channels: u16,
    /// Registers per value, W: 1 = i16 counts, 2 = i32 counts high word first (register 6).
    pub width: u16,
}

/// A header that breaks the convention or does not match the config.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BlockError {
    #[error("block header: {got} registers, need {HEADER_REGISTERS}")]
    ShortHeader { got: usize },
    #[error("block header: ring length 0, period 0 or width {width} (1 or 2)")]
    BadHeader { width: u16 },
    #[error("block header: {device} channels, config names {config}")]
    ChannelCount { device: u16, config: usize },
    #[error("block ring of {registers} registers at {base} exceeds the address space")]
    TooLarge { base: u16, registers: u64 },
    #[error("block read: {got} registers, expected {expected}")]
    ShortRead { got: usize, expected: usize },
}

impl BlockHeader {
    pub fn parse(words: &[u16]) -> Result<BlockHeader, BlockError> {
        if words.len() < HEADER_REGISTERS as usize {
            return Err(BlockError::ShortHeader { got: words.len() });
        }
        let h = BlockHeader {
            counter: ((words[0] as u32) << 16) | words[1] as u32,
            period_ns: ((words[2] as u32) << 16) | words[3] as u32,
            ring_len: words[4],
            channels: words[5],
            width: words[6],
        };
        if h.ring_len == 0 || h.period_ns == 0 || h.channels == 0 || !(1..=2).contains(&h.width) {
            return Err(BlockError::BadHeader { width: h.width });
        }
        Ok(h)
    }

    pub fn encode(&self) -> [u16; HEADER_REGISTERS as usize] {
        [
            (self.counter >> 16) as u16,
            self.counter as u16,
            (self.period_ns >> 16) as u16,
            self.period_ns as u16,
            self.ring_len,
            self.channels,
            self.width,
            0,
        ]
    }

    /// Registers per slot (one sample of every channel).
    pub fn slot_registers(&self) -> u16 {
        self.channels * self.width
    }

    /// Registers of header plus ring.
    pub fn total_registers(&self) -> u64 {
        HEADER_REGISTERS as u64 + self.ring_len as u64 * self.slot_registers() as u64
    }

    /// Check that the block fits at `base`.
    pub fn check_fits(&self, base: u16) -> Result<(), BlockError> {
        let registers = self.total_registers();
        if base as u64 + registers > 0x1_0000 || self.slot_registers() > MAX_READ_REGISTERS {
            return Err(BlockError::TooLarge { base, registers });
        }
        Ok(())
    }
}

/// One read of consecutive ring slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotRead {
    pub address: u16,
    pub count: u16,
    pub slots: u16,
}

/// What to read after a header: the lost samples (if any), then `count` samples from
/// sample index `first` (the device's counter extended past its u32 wrap).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlockPlan {
    pub header: BlockHeader,
    /// `(index of the first lost sample, samples lost, reason)`.
    pub lost: Option<(u64, u64, &'static str)>,
    pub first: u64,
    pub count: u64,
    pub reads: Vec<SlotRead>,
}

/// The reader's state: the next sample index it wants (the device counter extended past
/// its u32 wrap) and the device counter that index corresponds to.
#[derive(Debug, Clone, Default)]
pub struct BlockTracker {
    base: u16,
    state: Option<(u64, u32)>,
}

impl BlockTracker {
    pub fn new(base: u16) -> Self {
        BlockTracker { base, state: None }
    }

    /// The next sample index, once the first header was seen.
    pub fn next_index(&self) -> Option<u64> {
        self.state.map(|(n, _)| n)
    }

    /// Plan the reads after reading `header`. The first header only sets the starting
    /// point (history in the ring is not replayed).
    pub fn plan(&self, header: BlockHeader, channels: usize) -> Result<BlockPlan, BlockError> {
        if header.channels as usize != channels {
            return Err(BlockError::ChannelCount { device: header.channels, config: channels });
        }
        header.check_fits(self.base)?;
        let mut lost = None;
        let (next, newest) = match self.state {
            None => (header.counter as u64, header.counter as u64),
            Some((next, last)) => {
                let delta = header.counter.wrapping_sub(last);
                if delta > u32::MAX / 2 {
                    // The counter went backwards: the device restarted. Its samples since the
                    // restart follow ours; how many were lost before it is unknown (0 here).
                    lost = Some((next, 0, "device_reset"));
                    (next, next + header.counter as u64)
                } else {
                    (next, next + delta as u64)
                }
            }
        };
        let ring = header.ring_len as u64;
        let margin = ring / RING_MARGIN_DIVISOR as u64;
        let readable = (ring - margin).min(newest - next.min(newest));
        let oldest = newest - readable;
        let first = next.max(oldest).max(after_wrap_overwrites(&header, newest, oldest, margin));
        if first > next {
            lost = Some((next, first - next, "ring_overflow"));
        }
        let slot_regs = header.slot_registers();
        let per_read = (MAX_READ_REGISTERS / slot_regs).max(1) as u64;
        let mut reads = Vec::new();
        let mut i = first;
        while i < newest {
            // The device counter of sample i, and its slot.
            let c = header.counter.wrapping_sub((newest - i) as u32);
            let slot = (c % header.ring_len as u32) as u64;
            let to_wrap = (u32::MAX - c) as u64 + 1;
            let n = per_read.min(ring - slot).min(newest - i).min(to_wrap);
            reads.push(SlotRead {
                address: self.base + HEADER_REGISTERS + slot as u16 * slot_regs,
                count: n as u16 * slot_regs,
                slots: n as u16,
            });
            i += n;
        }
        Ok(BlockPlan { header, lost, first, count: newest - first, reads })
    }

    /// The plan's reads all succeeded: continue after them.
    pub fn commit(&mut self, plan: &BlockPlan) {
        self.state = Some((plan.first + plan.count, plan.header.counter));
    }
}

/// The first sample index from which no sample in `oldest..newest` is overwritten early by
/// the counter's wrap (`oldest` when none is). The sample of counter `c` sits in slot
/// `c mod N`; when N does not divide 2^32 the slot sequence jumps back to 0 at the wrap, so
/// the last `r = 2^32 mod N` samples before it are overwritten by counters `0..r` after it:
/// `r` samples later instead of N. Such a sample `i` counts as readable only while
/// `i + r >= newest + margin`, the rule every other sample meets with N in place of `r`.
fn after_wrap_overwrites(header: &BlockHeader, newest: u64, oldest: u64, margin: u64) -> u64 {
    let r = (1u64 << 32) % header.ring_len as u64;
    if r == 0 || oldest >= newest {
        return oldest;
    }
    // The first wrap after the oldest sample, as a sample index.
    let oldest_counter = header.counter.wrapping_sub((newest - oldest) as u32);
    let wrap = oldest + ((1u64 << 32) - oldest_counter as u64);
    // The samples it shortens: `wrap - r..wrap`, those present in `oldest..newest`.
    let (from, to) = (oldest.max(wrap.saturating_sub(r)), newest.min(wrap));
    // Overwritten (or within the margin of it): `i + r < newest + margin`.
    let bad_end = to.min((newest + margin).saturating_sub(r));
    if bad_end > from { bad_end } else { oldest }
}

/// Physical values of the slots read by one plan, interleaved sample by sample.
pub fn decode_slots(words: &[u16], header: &BlockHeader, channels: &[ChannelSpec], out: &mut Vec<f64>) {
    let w = header.width as usize;
    for slot in words.chunks_exact(header.slot_registers() as usize) {
        for (c, spec) in channels.iter().enumerate() {
            let raw = if w == 1 {
                slot[c] as i16 as f64
            } else {
                (((slot[2 * c] as u32) << 16) | slot[2 * c + 1] as u32) as i32 as f64
            };
            out.push(spec.physical(raw));
        }
    }
}

/// The device's side of the convention: writes samples into the ring and bumps the
/// counter, on a register image indexed by address.
#[derive(Debug, Clone)]
pub struct RingWriter {
    pub base: u16,
    pub header: BlockHeader,
}

impl RingWriter {
    /// A ring of `ring_len` slots of `channels` values `width` registers wide at `base`.
    pub fn new(base: u16, ring_len: u16, channels: u16, width: u16, period_ns: u32) -> Result<Self, BlockError> {
        let header = BlockHeader { counter: 0, period_ns, ring_len, channels, width };
        BlockHeader::parse(&header.encode())?;
        header.check_fits(base)?;
        Ok(RingWriter { base, header })
    }

    /// Write the header into `registers` (65536 holding registers).
    pub fn write_header(&self, registers: &mut [u16]) {
        let b = self.base as usize;
        registers[b..b + HEADER_REGISTERS as usize].copy_from_slice(&self.header.encode());
    }

    /// Append samples: `counts` holds whole samples of `channels` counts, interleaved.
    /// Counts saturate at the ring's integer width.
    pub fn push(&mut self, registers: &mut [u16], counts: &[i32]) {
        let c = self.header.channels as usize;
        let w = self.header.width as usize;
        let slot_regs = c * w;
        for sample in counts.chunks_exact(c) {
            let slot = (self.header.counter % self.header.ring_len as u32) as usize;
            let at = self.base as usize + HEADER_REGISTERS as usize + slot * slot_regs;
            for (k, &v) in sample.iter().enumerate() {
                if w == 1 {
                    registers[at + k] = v.clamp(i16::MIN as i32, i16::MAX as i32) as i16 as u16;
                } else {
                    registers[at + 2 * k] = ((v as u32) >> 16) as u16;
                    registers[at + 2 * k + 1] = v as u32 as u16;
                }
            }
            self.header.counter = self.header.counter.wrapping_add(1);
        }
        self.write_header(registers);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::sample::Role;

    fn channels(c: usize) -> Vec<ChannelSpec> {
        (0..c).map(|_| ChannelSpec { role: Role::Load, gain: 1.0, offset: 0.0 }).collect()
    }

    /// Read a plan from the register image like the driver does.
    fn read(registers: &[u16], plan: &BlockPlan, chans: &[ChannelSpec]) -> Vec<f64> {
        let mut out = Vec::new();
        for r in &plan.reads {
            let a = r.address as usize;
            decode_slots(&registers[a..a + r.count as usize], &plan.header, chans, &mut out);
        }
        out
    }

    #[test]
    fn header_words() {
        // counter 0x0001_0002 (65538) high word first, period 100_000 ns = 0x0001_86A0,
        // ring 512, 3 channels, width 2, reserved 0.
        let words = [0x0001, 0x0002, 0x0001, 0x86A0, 512, 3, 2, 0];
        let h = BlockHeader::parse(&words).unwrap();
        assert_eq!(h, BlockHeader { counter: 65538, period_ns: 100_000, ring_len: 512, channels: 3, width: 2 });
        assert_eq!(h.encode(), words);
        assert_eq!(BlockHeader::parse(&words[..7]), Err(BlockError::ShortHeader { got: 7 }));
        // Width 3 is not a thing.
        assert!(BlockHeader::parse(&[0, 0, 0, 1, 16, 1, 3, 0]).is_err());
        // A ring of 0 slots is not either.
        assert!(BlockHeader::parse(&[0, 0, 0, 1, 0, 1, 1, 0]).is_err());
    }

    #[test]
    fn new_samples_are_read_once_in_order_across_the_ring_end() {
        let mut regs = vec![0u16; 0x1_0000];
        let mut w = RingWriter::new(100, 64, 3, 2, 1000).unwrap();
        let chans = channels(3);
        let mut t = BlockTracker::new(100);
        w.push(&mut regs, &(0..30).collect::<Vec<i32>>()); // 10 samples before we look
        let h = BlockHeader::parse(&regs[100..108]).unwrap();
        let p = t.plan(h, 3).unwrap();
        assert_eq!((p.first, p.count, p.lost), (10, 0, None), "history is not replayed");
        t.commit(&p);
        // 50 samples, negative counts too: slots 10..60.
        let counts: Vec<i32> = (0..150).map(|k| k - 75).collect();
        w.push(&mut regs, &counts);
        let p = t.plan(BlockHeader::parse(&regs[100..108]).unwrap(), 3).unwrap();
        assert_eq!((p.first, p.count), (10, 50));
        // 125 / 6 = 20 samples per read.
        assert_eq!(p.reads.iter().map(|r| r.slots).collect::<Vec<_>>(), vec![20, 20, 10]);
        assert!(p.reads.iter().all(|r| r.count <= MAX_READ_REGISTERS));
        assert_eq!(read(&regs, &p, &chans), counts.iter().map(|&c| c as f64).collect::<Vec<_>>());
        t.commit(&p);
        // 20 more wrap the ring end (slots 60..64, then 0..16).
        let counts: Vec<i32> = (0..60).map(|k| 1_000_000 + k).collect();
        w.push(&mut regs, &counts);
        let p = t.plan(BlockHeader::parse(&regs[100..108]).unwrap(), 3).unwrap();
        assert_eq!(p.reads[0].slots, 4);
        assert_eq!(p.reads[0].address, 100 + 8 + 60 * 6);
        assert_eq!(p.reads[1].address, 100 + 8);
        assert_eq!(read(&regs, &p, &chans), counts.iter().map(|&c| c as f64).collect::<Vec<_>>());
    }

    #[test]
    fn a_counter_jump_larger_than_the_ring_is_lost_samples() {
        let mut regs = vec![0u16; 0x1_0000];
        let mut w = RingWriter::new(0, 64, 1, 1, 1000).unwrap();
        let mut t = BlockTracker::new(0);
        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap_or(w.header), 1).unwrap();
        t.commit(&p);
        w.push(&mut regs, &(0..200).collect::<Vec<i32>>());
        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
        // Readable: 64 - 64/8 = 56 newest samples; the 144 before are lost.
        assert_eq!(p.lost, Some((0, 144, "ring_overflow")));
        assert_eq!((p.first, p.count), (144, 56));
        assert_eq!(read(&regs, &p, &channels(1)), (144..200).map(|c| c as f64).collect::<Vec<_>>());
    }

    #[test]
    fn the_counter_wraps_past_u32() {
        let mut regs = vec![0u16; 0x1_0000];
        let mut w = RingWriter::new(0, 16, 1, 1, 1000).unwrap();
        // Just before the wrap: 2^32 - 3. 16 divides 2^32, so slot 15 is followed by slot 0
        // there as everywhere else (other ring lengths: the test below).
        w.header.counter = u32::MAX - 2;
        w.write_header(&mut regs);
        let mut t = BlockTracker::new(0);
        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
        t.commit(&p);
        w.push(&mut regs, &[1, 2, 3, 4, 5]);
        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
        assert_eq!(p.first, u32::MAX as u64 - 2);
        assert_eq!(p.count, 5);
        assert_eq!(p.lost, None);
        assert_eq!(read(&regs, &p, &channels(1)), vec![1.0, 2.0, 3.0, 4.0, 5.0]);
        t.commit(&p);
        assert_eq!(t.next_index(), Some(u32::MAX as u64 + 3));
    }

    /// A ring whose length does not divide 2^32 restarts at slot 0 when the counter wraps,
    /// so the last `2^32 mod N` samples before the wrap are overwritten early. Every ring
    /// length from 1 to 40 and powers of two, every start up to 2N before the wrap, and
    /// batches of 1 to N samples: what is read is exactly what was written at those sample
    /// indexes, and the rest is reported lost, never read from a slot rewritten since.
    #[test]
    fn near_the_counter_wrap_no_rewritten_slot_is_read_whatever_the_ring_length() {
        let mut regs = vec![0u16; 0x1_0000];
        let mut early_losses = 0;
        for ring in (1..=40u16).chain([64, 1000]) {
            for before in 1..=2 * ring as u32 {
                for batch in [1, ring as usize / 2 + 1, ring as usize] {
                    let mut w = RingWriter::new(0, ring, 1, 2, 1000).unwrap();
                    w.header.counter = 0u32.wrapping_sub(before);
                    w.write_header(&mut regs);
                    let mut t = BlockTracker::new(0);
                    let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
                    t.commit(&p);
                    // Two batches, so the wrap falls inside or between them; values are
                    // the sample's own index from the start.
                    let mut next_value = 0;
                    for _ in 0..2 {
                        let values: Vec<i32> = (next_value..next_value + batch as i32).collect();
                        next_value += batch as i32;
                        w.push(&mut regs, &values);
                        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
                        let lost = p.lost.map_or(0, |(_, n, _)| n);
                        assert_eq!(lost + p.count, batch as u64, "ring {ring}, {before} before the wrap");
                        let want: Vec<f64> = (next_value - p.count as i32..next_value).map(f64::from).collect();
                        assert_eq!(read(&regs, &p, &channels(1)), want, "ring {ring}, {before} before the wrap");
                        let margin_only = (ring - ring / 8) as u64;
                        if lost > 0 && p.count + lost <= margin_only {
                            early_losses += 1;
                        }
                        t.commit(&p);
                    }
                }
            }
        }
        // Rings that do not divide 2^32 lost samples the margin alone would have kept.
        assert!(early_losses > 0);
    }

    #[test]
    fn a_device_restart_is_reported_and_its_new_samples_read() {
        let mut regs = vec![0u16; 0x1_0000];
        let mut w = RingWriter::new(0, 32, 1, 1, 1000).unwrap();
        w.push(&mut regs, &[0; 20]);
        let mut t = BlockTracker::new(0);
        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
        t.commit(&p);
        let mut w = RingWriter::new(0, 32, 1, 1, 1000).unwrap();
        w.push(&mut regs, &[7, 8, 9]);
        let p = t.plan(BlockHeader::parse(&regs[..8]).unwrap(), 1).unwrap();
        assert_eq!(p.lost, Some((20, 0, "device_reset")));
        assert_eq!((p.first, p.count), (20, 3));
        assert_eq!(read(&regs, &p, &channels(1)), vec![7.0, 8.0, 9.0]);
    }

    #[test]
    fn i16_counts_with_gain_and_offset() {
        let mut regs = vec![0u16; 0x1_0000];
        let mut w = RingWriter::new(10, 8, 2, 1, 1000).unwrap();
        let mut t = BlockTracker::new(10);
        let p = t.plan(BlockHeader::parse(&regs[10..18]).unwrap_or(w.header), 2).unwrap();
        t.commit(&p);
        // 40000 saturates at i16::MAX; -5 is 0xFFFB on the wire.
        w.push(&mut regs, &[40000, -5]);
        let chans = [
            ChannelSpec { role: Role::Load, gain: 2.0, offset: 1.0 },
            ChannelSpec { role: Role::Acc, gain: 0.5, offset: 0.0 },
        ];
        let p = t.plan(BlockHeader::parse(&regs[10..18]).unwrap(), 2).unwrap();
        assert_eq!(read(&regs, &p, &chans), vec![1.0 + 2.0 * 32767.0, -2.5]);
    }

    #[test]
    fn a_channel_count_unlike_the_config_is_an_error() {
        let w = RingWriter::new(0, 8, 2, 1, 1000).unwrap();
        assert_eq!(BlockTracker::new(0).plan(w.header, 3), Err(BlockError::ChannelCount { device: 2, config: 3 }));
        // A ring that does not fit the address space.
        assert!(RingWriter::new(0xFF00, 4096, 3, 2, 1000).is_err());
    }
}
