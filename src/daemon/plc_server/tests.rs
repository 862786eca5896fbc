//! The PLC image's unit tests: the encoding, the part block and the coils against `answer`.

use super::*;
use crate::estimate::result::Alert;

/// A blow with every field set (the advisor's tests use it too).
pub(crate) fn blow() -> BlowEstimate {
    crate::estimate::result::examples::intermediate()
}

fn u32_at(w: &[u16; IMAGE_WORDS], at: usize) -> u32 {
    (u32::from(w[at]) << 16) | u32::from(w[at + 1])
}

#[test]
fn each_value_is_scaled_and_rounded_to_its_unit() {
    let mut s = StatusSnapshot::new("hammer");
    s.blows = 70_000; // above a u16: the high word carries it
    s.billets = 3;
    let w = encode(41, &s, Some(&blow()), Warnings::default());
    assert_eq!(w[reg::HEARTBEAT], 41);
    assert_eq!(w[reg::STATUS_BITS], bit::RUNNING, "no source yet: not healthy; nothing latched");
    // Big-endian u32: 70 000 = 0x0001_1170, high word first.
    assert_eq!((w[2], w[3]), (0x0001, 0x1170));
    assert_eq!(u32_at(&w, reg::BILLETS), 3);
    assert_eq!(w[reg::CLASS], 2, "intermediate");
    assert_eq!(w[reg::EFFICIENCY], 7000, "0.69995 × 10 000 rounds to 7000");
    assert_eq!(u32_at(&w, reg::PLASTIC_J), 7196);
    assert_eq!(u32_at(&w, reg::KINETIC_J), 10_280);
    assert_eq!(w[reg::IMPACT_MM_PER_S], 5300);
    assert_eq!(u32_at(&w, reg::PEAK_LOAD_100N), 12_346);
    assert_eq!(w[reg::HEIGHT_10UM], 4012);
    assert_eq!((w[16], w[17], w[18], w[19]), (0, 0xFFFF, 0, 0), "no recipe, unknown, none");
    assert_eq!(w[reg::CHANNELS], 0b111, "load, acc and disp");
    assert_eq!(w[reg::EFFICIENCY_SD], 0, "no sd");
    // A blow without a load channel (issue 43): bits acc and disp, and its sd.
    let reduced = BlowEstimate {
        channels: crate::signal::sample::Channels::ALL.without(Role::Load),
        efficiency_sd: Some(0.00125),
        ..blow()
    };
    let w2 = encode(41, &s, Some(&reduced), Warnings::default());
    assert_eq!(w2[reg::CHANNELS], channel_bit::ACC | channel_bit::DISP);
    assert_eq!(w2[reg::EFFICIENCY_SD], 13, "0.00125 × 10 000 rounds to 13");
    // The advisor's plan: blows left, and the next blow's energy (70 123.6 J rounds to
    // 70 124 = 0x0001_11EC).
    let step = |kinetic_j| crate::advise::PlannedBlow {
        blow: 1,
        v0_mps: 4.6,
        kinetic_j,
        h_end_m: 0.05,
        efficiency: 0.9,
        class: "soft",
    };
    let plan = crate::advise::Plan {
        h_now_m: 0.08,
        target_m: 0.03,
        reachable: true,
        blows_to_target: Some(2),
        hard_blows: 0,
        plan: vec![step(70_123.6), step(5_000.0)],
        why: None,
    };
    let advice =
        |plan| super::super::advisor::Advice { billet: 1, after_blow: 3, plan, why_not: None, planned_ms: 30.0 };
    s.advice = Some(advice(Some(plan.clone())));
    let w = encode(41, &s, Some(&blow()), Warnings::default());
    assert_eq!((w[17], w[18], w[19]), (2, 0x0001, 0x11EC));
    // Not reachable, or no plan (an incomplete blow's height is not known): unknown, none.
    s.advice = Some(advice(Some(crate::advise::Plan { reachable: false, blows_to_target: None, ..plan })));
    let w = encode(41, &s, Some(&blow()), Warnings::default());
    assert_eq!((w[17], w[18], w[19]), (0xFFFF, 0, 0));
    s.advice = Some(advice(None));
    let w = encode(41, &s, Some(&blow()), Warnings::default());
    assert_eq!((w[17], w[18], w[19]), (0xFFFF, 0, 0));
}

#[test]
fn values_that_do_not_fit_saturate_and_unknown_ones_are_zero() {
    let mut s = StatusSnapshot::new("hammer");
    s.blows = u64::from(u32::MAX) + 5;
    let mut b = blow();
    b.v_impact_mps = 70.0; // 70 000 mm/s > 65 535
    b.peak_load_n = 1e15; // 1e13 × 100 N > u32
    b.h_end_m = Some(1.0); // 100 000 × 0.01 mm > 65 535
    b.plastic_j = Some(-3.0); // below the type: 0
    b.kinetic_in_j = Some(f64::NAN);
    let w = encode(0, &s, Some(&b), Warnings::default());
    assert_eq!(u32_at(&w, reg::BLOWS), u32::MAX);
    assert_eq!(w[reg::IMPACT_MM_PER_S], u16::MAX);
    assert_eq!(u32_at(&w, reg::PEAK_LOAD_100N), u32::MAX);
    assert_eq!(w[reg::HEIGHT_10UM], u16::MAX);
    assert_eq!(u32_at(&w, reg::PLASTIC_J), 0);
    assert_eq!(u32_at(&w, reg::KINETIC_J), 0);
    // An incomplete blow: no energies, its bit and class set.
    let mut b = blow();
    (b.class, b.efficiency, b.plastic_j, b.kinetic_in_j, b.h_end_m) = (BlowClass::Incomplete, None, None, None, None);
    let w = encode(0, &s, Some(&b), Warnings::default());
    assert_eq!(w[reg::CLASS], 4);
    assert_eq!(w[reg::STATUS_BITS] & bit::LAST_INCOMPLETE, bit::LAST_INCOMPLETE);
    assert_eq!((w[reg::EFFICIENCY], u32_at(&w, reg::PLASTIC_J), w[reg::HEIGHT_10UM]), (0, 0, 0));
    // An implausible blow: likewise, with its own bit and class.
    let mut b = blow();
    (b.class, b.efficiency, b.plastic_j, b.kinetic_in_j, b.h_end_m) = (BlowClass::Implausible, None, None, None, None);
    let w = encode(0, &s, Some(&b), Warnings::default());
    assert_eq!(w[reg::CLASS], 5);
    assert_eq!(w[reg::STATUS_BITS] & (bit::LAST_IMPLAUSIBLE | bit::LAST_INCOMPLETE), bit::LAST_IMPLAUSIBLE);
    assert_eq!((w[reg::EFFICIENCY], u32_at(&w, reg::PLASTIC_J), w[reg::HEIGHT_10UM]), (0, 0, 0));
    // Before the first blow: class 0, every value 0.
    let w = encode(0, &StatusSnapshot::new("hammer"), None, Warnings::default());
    assert_eq!(w[reg::CLASS], 0);
    assert!(w[reg::EFFICIENCY..reg::JUDGEMENT].iter().all(|&x| x == 0));
}

#[test]
fn status_bits_follow_the_sources_the_latched_alert_and_the_warnings() {
    let mut s = StatusSnapshot::new("hammer");
    s.sources
        .insert("daq".into(), super::super::status::SourceState { state: "connected".into(), ..Default::default() });
    let alert = Alert { kind: AlertKind::Sensor, blow: 7, reason: String::new(), figures: Default::default() };
    s.latched_alert = Some(alert);
    let mut warn = Warnings::default();
    warn.raise(AlertKind::Sensor);
    warn.raise(AlertKind::ElasticBlow);
    let w = encode(0, &s, None, warn);
    assert_eq!(w[reg::STATUS_BITS], bit::RUNNING | bit::SOURCES_HEALTHY | bit::ALERT_LATCHED | bit::SENSOR);
    s.sources
        .insert("plc".into(), super::super::status::SourceState { state: "reconnecting".into(), ..Default::default() });
    s.latched_alert = None;
    warn.raise(AlertKind::ModelHealth);
    let w = encode(0, &s, None, warn);
    assert_eq!(w[reg::STATUS_BITS], bit::RUNNING | bit::MODEL_HEALTH | bit::SENSOR);
}

#[test]
fn the_image_is_read_only_the_part_block_is_written_and_the_coils_send_their_commands() {
    let image: [u16; IMAGE_WORDS] = std::array::from_fn(|i| i as u16 * 3);
    let mut block = [0u16; part_block::WORDS];
    let mut sent = Vec::new();
    let mut take = |c| {
        sent.push(c);
        true
    };
    assert_eq!(
        answer(&image, &mut block, Request::ReadHoldingRegisters(18, 2), &mut take),
        Ok(Response::ReadHoldingRegisters(vec![54, 57]))
    );
    let mut spare = [0u16; part_block::WORDS];
    let mut refused = |r| answer(&image, &mut spare, r, |_| true);
    assert_eq!(refused(Request::ReadHoldingRegisters(29, 2)), Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(refused(Request::ReadHoldingRegisters(99, 2)), Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(refused(Request::ReadHoldingRegisters(147, 2)), Err(ExceptionCode::IllegalDataAddress));
    // A quantity outside 1..=125 is a value error, before any address is looked at.
    assert_eq!(refused(Request::ReadHoldingRegisters(0, 0)), Err(ExceptionCode::IllegalDataValue));
    assert_eq!(refused(Request::ReadHoldingRegisters(0, 126)), Err(ExceptionCode::IllegalDataValue));
    assert_eq!(refused(Request::ReadHoldingRegisters(0, 31)), Err(ExceptionCode::IllegalDataAddress));
    // The image is read-only: a write to it is not a function it offers.
    assert_eq!(refused(Request::WriteSingleRegister(0, 1)), Err(ExceptionCode::IllegalFunction));
    assert_eq!(refused(Request::WriteMultipleRegisters(0, vec![1].into())), Err(ExceptionCode::IllegalFunction));
    assert_eq!(
        refused(Request::WriteMultipleRegisters(146, vec![1; 3].into())),
        Err(ExceptionCode::IllegalDataAddress)
    );
    assert_eq!(refused(Request::ReadCoils(0, 2)), Err(ExceptionCode::IllegalFunction));
    assert_eq!(refused(Request::ReadInputRegisters(0, 2)), Err(ExceptionCode::IllegalFunction));
    assert_eq!(refused(Request::WriteSingleCoil(4, true)), Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(spare, [0u16; part_block::WORDS], "nothing written by a refused request");
    assert_eq!(
        answer(&image, &mut block, Request::WriteSingleCoil(0, true), &mut take),
        Ok(Response::WriteSingleCoil(0, true))
    );
    // Writing false does nothing; both at once send both.
    assert!(answer(&image, &mut block, Request::WriteSingleCoil(1, false), &mut take).is_ok());
    assert!(answer(&image, &mut block, Request::WriteMultipleCoils(0, vec![true, true].into()), &mut take).is_ok());
    assert_eq!(sent, [Control::Acknowledge, Control::Acknowledge, Control::NewBillet { at_device_ns: None }]);
    // A service that cannot take the command now says so.
    assert_eq!(
        answer(&image, &mut block, Request::WriteSingleCoil(1, true), |_| false),
        Err(ExceptionCode::ServerDeviceBusy)
    );
}

#[test]
fn the_part_block_is_written_read_back_and_sent_by_coils_2_and_3() {
    let image = [0u16; IMAGE_WORDS];
    let mut block = [0u16; part_block::WORDS];
    let mut sent = Vec::new();
    let mut take = |c| {
        sent.push(c);
        true
    };
    // The part block: the PLC writes the part id and the die set, reads them back, and
    // coils 2 and 3 send them.
    let part = part_block::encode("P-000418");
    assert_eq!(
        answer(&image, &mut block, Request::WriteMultipleRegisters(100, part.to_vec().into()), &mut take),
        Ok(Response::WriteMultipleRegisters(100, 16))
    );
    assert!(
        answer(&image, &mut block, Request::WriteSingleRegister(132, u16::from_be_bytes(*b"18")), &mut take).is_ok()
    );
    assert_eq!(
        answer(&image, &mut block, Request::ReadHoldingRegisters(100, 2), &mut take),
        Ok(Response::ReadHoldingRegisters(part[..2].to_vec()))
    );
    assert!(answer(&image, &mut block, Request::WriteMultipleCoils(2, vec![true, true].into()), &mut take).is_ok());
    let eighteen = Some(Some("18".to_string()));
    assert_eq!(
        sent,
        [
            Control::NewBilletAs {
                at_device_ns: None,
                change: Box::new(crate::config::history::TraceUpdate {
                    part_id: Some(Some("P-000418".into())),
                    lot: None,
                    die_set: eighteen.clone(),
                })
            },
            Control::DieChange(Box::new(crate::config::history::TraceUpdate {
                die_set: eighteen,
                ..Default::default()
            })),
        ]
    );
    // A control character is refused whole; a field with a leading space refuses its coil.
    assert_eq!(
        answer(&image, &mut block, Request::WriteSingleRegister(116, 0x0941), |_| true),
        Err(ExceptionCode::IllegalDataValue)
    );
    assert!(answer(&image, &mut block, Request::WriteSingleRegister(116, 0x2041), |_| true).is_ok());
    assert_eq!(
        answer(&image, &mut block, Request::WriteSingleCoil(2, true), |_| panic!("nothing sent")),
        Err(ExceptionCode::IllegalDataValue)
    );
}

#[test]
fn the_die_set_s_counts_level_and_share_of_life_used_are_in_registers_22_to_29() {
    let mut s = StatusSnapshot::new("hammer");
    s.die_life.count.blows = 70_000;
    s.die_life.count.hard_blows = 12;
    s.die_life.count.energy_j = 3.6e9;
    s.die_life.level = crate::history::die::DieLevel::Warning;
    s.die_life.limit_blows = Some(80_000);
    let w = encode(0, &s, None, Warnings::default());
    assert_eq!(u32_at(&w, reg::DIE_BLOWS), 70_000);
    assert_eq!(u32_at(&w, reg::DIE_HARD_BLOWS), 12);
    assert_eq!(u32_at(&w, reg::DIE_ENERGY_KJ), 3_600_000);
    assert_eq!(w[reg::DIE_LEVEL], 1);
    assert_eq!(w[reg::DIE_USED_PERMILLE], 875, "70 000 of 80 000 blows");
    // The nearer limit: the energy's, 3.6 GJ of 3 GJ.
    s.die_life.limit_energy_j = Some(3e9);
    assert_eq!(encode(0, &s, None, Warnings::default())[reg::DIE_USED_PERMILLE], 1200);
    // Without limits: 0.
    s.die_life.limit_blows = None;
    s.die_life.limit_energy_j = None;
    assert_eq!(encode(0, &s, None, Warnings::default())[reg::DIE_USED_PERMILLE], 0);
}

#[tokio::test]
async fn other_units_are_refused_and_counted() {
    let (tx, _rx) = watch::channel([7u16; IMAGE_WORDS]);
    let (control, mut commands) = mpsc::channel(4);
    let stats = Arc::new(PlcStats::default());
    let block = Arc::new(std::sync::Mutex::new([0u16; part_block::WORDS]));
    let s = ImageService { image: tx.subscribe(), block, control, stats: stats.clone() };
    let req = |slave, request| SlaveRequest { slave, request };
    assert_eq!(s.call(req(2, Request::ReadHoldingRegisters(0, 1))).await, Err(ExceptionCode::GatewayTargetDevice));
    assert_eq!(s.call(req(1, Request::ReadHoldingRegisters(0, 1))).await, Ok(Response::ReadHoldingRegisters(vec![7])));
    assert!(s.call(req(1, Request::WriteSingleCoil(1, true))).await.is_ok());
    assert_eq!(commands.try_recv().ok(), Some(Control::NewBillet { at_device_ns: None }));
    assert_eq!(stats.requests.load(Ordering::Relaxed), 3);
    assert_eq!(stats.exceptions.load(Ordering::Relaxed), 1);
    assert_eq!(stats.commands.load(Ordering::Relaxed), 1);
}
