//! The bytes of each recorded message: domain values to protobuf and back. Sans-IO: no
//! file, no clock; the writer and the reader wrap it.
//!
//! `SampleBatch` is the hot path (100 kHz × 3 channels is 2.4 MB/s of doubles), so its
//! encoder and decoder are written by hand against the protobuf wire format
//! (protobuf.dev/programming-guides/encoding): the packed doubles are copied as one block
//! instead of one call per value. The bytes are exactly those `prost` writes for
//! [`pb::SampleBatch`], and the decoder reads anything a conforming encoder writes
//! (packed or unpacked repeated fields, unknown fields, fields in any order); tests check
//! both against `prost`. Every other message goes through the `prost`-generated types.

use prost::Message;

use crate::alert::{Alert, AlertKind};
use crate::estimate::billet::BilletCheck;
use crate::estimate::fit::PhaseResidual;
use crate::estimate::plausibility::{Check, Implausible};
use crate::estimate::{BilletTag, BlowClass, BlowEstimate, HeightCheck, HeightSource};
use crate::signal::sample::{Channels, Role, SampleBatch};

use super::error::DecodeError;
use super::message::{BlowBoundary, ConfigFile, Gap, Payload, Status};
use super::schema::{MessageKind, pb};

/// Append the protobuf encoding of `batch` (a `forgemon.SampleBatch`) to `buf`.
/// Fails when the values do not fill whole samples of the batch's channels.
pub fn encode_samples(batch: &SampleBatch, buf: &mut Vec<u8>) -> Result<(), DecodeError> {
    check_batch_shape(batch.values.len(), batch.roles.len())?;
    if !batch.source.is_empty() {
        wire::put_key(buf, 1, wire::LEN);
        wire::put_varint(buf, batch.source.len() as u64);
        buf.extend_from_slice(batch.source.as_bytes());
    }
    if batch.seq != 0 {
        wire::put_key(buf, 2, wire::VARINT);
        wire::put_varint(buf, batch.seq);
    }
    if batch.device_time_ns != 0 {
        wire::put_key(buf, 3, wire::VARINT);
        wire::put_varint(buf, batch.device_time_ns as u64); // int64: two's complement, 10 bytes if negative
    }
    if batch.host_time_ns != 0 {
        wire::put_key(buf, 4, wire::VARINT);
        wire::put_varint(buf, batch.host_time_ns as u64);
    }
    if batch.period_ns != 0.0 {
        wire::put_key(buf, 5, wire::FIXED64);
        buf.extend_from_slice(&batch.period_ns.to_le_bytes());
    }
    if !batch.roles.is_empty() {
        // Every role value is 1..=3: one varint byte each.
        wire::put_key(buf, 6, wire::LEN);
        wire::put_varint(buf, batch.roles.len() as u64);
        buf.extend(batch.roles.iter().map(|r| role_to_pb(*r) as u8));
    }
    if !batch.values.is_empty() {
        wire::put_key(buf, 7, wire::LEN);
        wire::put_varint(buf, batch.values.len() as u64 * 8);
        buf.reserve(batch.values.len() * 8);
        for v in &batch.values {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    Ok(())
}

/// Decode a `forgemon.SampleBatch`.
pub fn decode_samples(mut bytes: &[u8]) -> Result<SampleBatch, DecodeError> {
    let mut batch = SampleBatch {
        source: String::new(),
        seq: 0,
        device_time_ns: 0,
        host_time_ns: 0,
        period_ns: 0.0,
        roles: Vec::new(),
        values: Vec::new(),
    };
    let buf = &mut bytes;
    while !buf.is_empty() {
        let (field, wire_type) = wire::get_key(buf)?;
        match (field, wire_type) {
            (1, wire::LEN) => {
                let s = wire::get_len_delimited(buf)?;
                batch.source = String::from_utf8(s.to_vec())
                    .map_err(|_| DecodeError::Wire { what: "invalid UTF-8 in source".into() })?;
            }
            (2, wire::VARINT) => batch.seq = wire::get_varint(buf)?,
            (3, wire::VARINT) => batch.device_time_ns = wire::get_varint(buf)? as i64,
            (4, wire::VARINT) => batch.host_time_ns = wire::get_varint(buf)? as i64,
            (5, wire::FIXED64) => batch.period_ns = f64::from_le_bytes(wire::get_fixed64(buf)?),
            (6, wire::LEN) => {
                let mut packed = wire::get_len_delimited(buf)?;
                while !packed.is_empty() {
                    batch.roles.push(role_from_pb(wire::get_varint(&mut packed)? as i32)?);
                }
            }
            (6, wire::VARINT) => batch.roles.push(role_from_pb(wire::get_varint(buf)? as i32)?),
            (7, wire::LEN) => {
                let packed = wire::get_len_delimited(buf)?;
                if !packed.len().is_multiple_of(8) {
                    return Err(DecodeError::Wire { what: "packed doubles not a multiple of 8 bytes".into() });
                }
                batch.values.reserve(packed.len() / 8);
                batch.values.extend(packed.as_chunks::<8>().0.iter().map(|c| f64::from_le_bytes(*c)));
            }
            (7, wire::FIXED64) => batch.values.push(f64::from_le_bytes(wire::get_fixed64(buf)?)),
            (1..=7, _) => return Err(DecodeError::Wire { what: format!("field {field} has the wrong wire type") }),
            _ => wire::skip(buf, wire_type)?,
        }
    }
    check_batch_shape(batch.values.len(), batch.roles.len())?;
    Ok(batch)
}

fn check_batch_shape(values: usize, channels: usize) -> Result<(), DecodeError> {
    // `n.is_multiple_of(0)` only for n = 0: no channels, no values.
    if values.is_multiple_of(channels) { Ok(()) } else { Err(DecodeError::RaggedBatch { values, channels }) }
}

fn role_to_pb(role: Role) -> pb::Role {
    match role {
        Role::Load => pb::Role::LoadN,
        Role::Disp => pb::Role::DispM,
        Role::Acc => pb::Role::AccMps2,
    }
}

fn role_from_pb(value: i32) -> Result<Role, DecodeError> {
    match pb::Role::try_from(value) {
        Ok(pb::Role::LoadN) => Ok(Role::Load),
        Ok(pb::Role::DispM) => Ok(Role::Disp),
        Ok(pb::Role::AccMps2) => Ok(Role::Acc),
        Ok(pb::Role::Unspecified) | Err(_) => Err(DecodeError::UnknownRole { value }),
    }
}

/// The protobuf message of a non-sample payload, appended to `buf`.
pub fn encode_payload(payload: &Payload, buf: &mut Vec<u8>) -> Result<(), DecodeError> {
    match payload {
        Payload::Samples(batch) => return encode_samples(batch, buf),
        Payload::Boundary(b) => boundary_to_pb(b).encode_raw(buf),
        Payload::Result(r) => result_to_pb(r).encode_raw(buf),
        Payload::Alert(a) => alert_to_pb(a).encode_raw(buf),
        Payload::Gap(g) => gap_to_pb(g).encode_raw(buf),
        Payload::Status(s) => status_to_pb(s).encode_raw(buf),
        Payload::Config(c) => pb::ConfigFile { name: c.name.clone(), text: c.text.clone() }.encode_raw(buf),
        Payload::Billet(b) => super::billets::to_pb(b).encode_raw(buf),
    }
    Ok(())
}

/// Decode a message of the given kind.
pub fn decode_payload(kind: MessageKind, bytes: &[u8]) -> Result<Payload, DecodeError> {
    Ok(match kind {
        MessageKind::Samples => Payload::Samples(decode_samples(bytes)?),
        MessageKind::Boundary => {
            let b = pb::BlowBoundary::decode(bytes)?;
            Payload::Boundary(BlowBoundary {
                blow: b.blow,
                t_trigger_s: b.t_trigger_s,
                t_contact_s: b.t_contact_s,
                t_end_s: b.t_end_s,
                source: b.source,
            })
        }
        MessageKind::Result => Payload::Result(Box::new(result_from_pb(pb::BlowResult::decode(bytes)?)?)),
        MessageKind::Alert => Payload::Alert(alert_from_pb(pb::Alert::decode(bytes)?)?),
        MessageKind::Gap => {
            let g = pb::Gap::decode(bytes)?;
            Payload::Gap(Gap { source: g.source, t_s: g.t_s, samples_lost: g.samples_lost, reason: g.reason })
        }
        MessageKind::Status => {
            let s = pb::Status::decode(bytes)?;
            Payload::Status(Status {
                source: s.source,
                state: s.state,
                samples: s.samples,
                frames: s.frames,
                drops: s.drops,
                gaps: s.gaps,
                crc_errors: s.crc_errors,
                decode_errors: s.decode_errors,
                reconnects: s.reconnects,
                detail: s.detail,
            })
        }
        MessageKind::Config => {
            let c = pb::ConfigFile::decode(bytes)?;
            Payload::Config(ConfigFile { name: c.name, text: c.text })
        }
        MessageKind::Billet => Payload::Billet(Box::new(super::billets::from_pb(pb::BilletSummary::decode(bytes)?))),
    })
}

fn boundary_to_pb(b: &BlowBoundary) -> pb::BlowBoundary {
    pb::BlowBoundary {
        blow: b.blow,
        t_trigger_s: b.t_trigger_s,
        t_contact_s: b.t_contact_s,
        t_end_s: b.t_end_s,
        source: b.source.clone(),
    }
}

fn alert_to_pb(a: &Alert) -> pb::Alert {
    pb::Alert { kind: a.kind.as_str().to_string(), blow: a.blow, reason: a.reason.clone(), figures: a.figures.clone() }
}

fn alert_from_pb(a: pb::Alert) -> Result<Alert, DecodeError> {
    let kind = match a.kind.as_str() {
        "elastic_blow" => AlertKind::ElasticBlow,
        "model_health" => AlertKind::ModelHealth,
        "sensor" => AlertKind::Sensor,
        "nok" => AlertKind::Nok,
        "storage" => AlertKind::Storage,
        "die_life" => AlertKind::DieLife,
        "drift" => AlertKind::Drift,
        _ => return Err(DecodeError::UnknownAlertKind { kind: a.kind }),
    };
    Ok(Alert { kind, blow: a.blow, reason: a.reason, figures: a.figures })
}

fn result_to_pb(r: &BlowEstimate) -> pb::BlowResult {
    pb::BlowResult {
        blow: r.blow,
        t_contact_s: r.t_contact_s,
        v_impact_mps: r.v_impact_mps,
        kinetic_in_j: r.kinetic_in_j,
        plastic_j: r.plastic_j,
        friction_j: r.friction_j,
        damped_j: r.damped_j,
        elastic_j: r.elastic_j,
        efficiency: r.efficiency,
        final_load_n: r.final_load_n,
        h_end_m: r.h_end_m,
        class: r.class.as_str().to_string(),
        alert: r.alert.as_ref().map(alert_to_pb),
        t_end_s: r.t_end_s,
        peak_load_n: r.peak_load_n,
        residual: r.residual,
        gap_s: r.gap_s,
        h_start_m: r.h_start_m,
        height_check: r.height_check.map(|h| pb::HeightCheck {
            sheet_m: h.sheet_m,
            encoder_m: h.encoder_m,
            tolerance_m: h.tolerance_m,
            agree: h.agree,
        }),
        billet: (r.billet.billet > 0).then_some(r.billet.billet),
        billet_blow: (r.billet.billet > 0).then_some(r.billet.billet_blow),
        billet_check: r.billet.billet_check.map(|c| c.as_str().to_string()),
        h_start_off_sheet_m: r.billet.h_start_off_sheet_m,
        sensor_check: r.sensor_check,
        method: r.method.map(|m| m.as_str().to_string()),
        height_source: Some(r.height_source.as_str().to_string()),
        implausible: r.implausible.as_ref().map(|i| i.check.as_str().to_string()),
        reason: r.implausible.as_ref().map(|i| i.reason.clone()),
        at_bound: r.at_bound.iter().map(|(k, v)| (k.clone(), *v)).collect(),
        flow_stress_scale: r.flow_stress_scale,
        model_residual: r.model_residual,
        model_residual_by_phase: r.model_residual_by_phase.map(|p| pb::PhaseResidual {
            impact: p.impact,
            forming: p.forming,
            spring_back: p.spring_back,
        }),
        judgement: r.judgement.as_ref().map(|j| pb::Judgement {
            ok: j.ok,
            recipe: j.recipe.clone(),
            reasons: j.reasons.clone(),
        }),
        channels: r.channels.names().into_iter().map(String::from).collect(),
        efficiency_sd: r.efficiency_sd,
        unobserved: r.unobserved.iter().map(|(k, v)| (k.clone(), v.clone())).collect(),
        excluded: r.excluded.iter().map(|(k, v)| (k.clone(), v.clone())).collect(),
        acc_check: r.acc_check,
    }
}

fn result_from_pb(r: pb::BlowResult) -> Result<BlowEstimate, DecodeError> {
    let Some(class) = BlowClass::parse(&r.class) else {
        return Err(DecodeError::UnknownClass { class: r.class });
    };
    // A complete, plausible blow always has its energies; a writer from before they were
    // optional left a 0 out.
    let reported = !matches!(class, BlowClass::Incomplete | BlowClass::Implausible);
    let energy = |v: Option<f64>| if reported { Some(v.unwrap_or(0.0)) } else { v };
    let implausible = match (r.implausible.as_deref().and_then(Check::parse), r.reason) {
        (Some(check), Some(reason)) => Some(Implausible { check, reason }),
        _ => None,
    };
    Ok(BlowEstimate {
        judgement: r.judgement.map(|j| crate::recipe::Judgement { ok: j.ok, recipe: j.recipe, reasons: j.reasons }),
        blow: r.blow,
        t_contact_s: r.t_contact_s,
        v_impact_mps: r.v_impact_mps,
        kinetic_in_j: energy(r.kinetic_in_j),
        plastic_j: energy(r.plastic_j),
        friction_j: r.friction_j,
        damped_j: energy(r.damped_j),
        elastic_j: energy(r.elastic_j),
        efficiency: energy(r.efficiency),
        final_load_n: r.final_load_n,
        h_end_m: r.h_end_m,
        class,
        alert: r.alert.map(alert_from_pb).transpose()?,
        t_end_s: r.t_end_s,
        peak_load_n: r.peak_load_n,
        residual: energy(r.residual),
        sensor_check: r.sensor_check,
        method: r.method.as_deref().and_then(crate::estimate::Method::parse),
        gap_s: r.gap_s,
        h_start_m: r.h_start_m,
        height_source: r.height_source.as_deref().and_then(HeightSource::parse).unwrap_or(HeightSource::Unknown),
        height_check: r.height_check.map(|h| HeightCheck {
            sheet_m: h.sheet_m,
            encoder_m: h.encoder_m,
            tolerance_m: h.tolerance_m,
            agree: h.agree,
        }),
        // Recordings from before issue 22 carry no billet: 0, and no check.
        billet: BilletTag {
            billet: r.billet.unwrap_or(0),
            billet_blow: r.billet_blow.unwrap_or(0),
            billet_check: r.billet_check.as_deref().and_then(BilletCheck::parse),
            h_start_off_sheet_m: r.h_start_off_sheet_m,
        },
        implausible,
        flow_stress_scale: r.flow_stress_scale,
        scale_by_half: None,
        model_residual: r.model_residual,
        model_residual_by_phase: r.model_residual_by_phase.map(|p| PhaseResidual {
            impact: p.impact,
            forming: p.forming,
            spring_back: p.spring_back,
        }),
        at_bound: r.at_bound.into_iter().collect(),
        // Recordings from before issue 43 used all three channels.
        channels: if r.channels.is_empty() {
            Channels::ALL
        } else {
            Channels::parse(r.channels.iter().map(String::as_str))
                .map_err(|c| DecodeError::Wire { what: format!("unknown channel {c:?} in a blow result") })?
        },
        efficiency_sd: r.efficiency_sd,
        unobserved: r.unobserved.into_iter().collect(),
        excluded: r.excluded.into_iter().collect(),
        acc_check: r.acc_check,
    })
}

fn gap_to_pb(g: &Gap) -> pb::Gap {
    pb::Gap { source: g.source.clone(), t_s: g.t_s, samples_lost: g.samples_lost, reason: g.reason.clone() }
}

fn status_to_pb(s: &Status) -> pb::Status {
    pb::Status {
        source: s.source.clone(),
        state: s.state.clone(),
        samples: s.samples,
        frames: s.frames,
        drops: s.drops,
        gaps: s.gaps,
        crc_errors: s.crc_errors,
        decode_errors: s.decode_errors,
        reconnects: s.reconnects,
        detail: s.detail.clone(),
    }
}

/// The few pieces of the protobuf wire format the sample codec needs.
mod wire {
    use super::DecodeError;

    pub const VARINT: u8 = 0;
    pub const FIXED64: u8 = 1;
    pub const LEN: u8 = 2;
    pub const FIXED32: u8 = 5;

    fn err(what: &'static str) -> DecodeError {
        DecodeError::Wire { what: what.to_string() }
    }

    pub fn put_varint(buf: &mut Vec<u8>, mut v: u64) {
        while v >= 0x80 {
            buf.push((v as u8) | 0x80);
            v >>= 7;
        }
        buf.push(v as u8);
    }

    pub fn put_key(buf: &mut Vec<u8>, field: u32, wire_type: u8) {
        put_varint(buf, (u64::from(field) << 3) | u64::from(wire_type));
    }

    pub fn get_varint(buf: &mut &[u8]) -> Result<u64, DecodeError> {
        let mut v = 0u64;
        for i in 0..10 {
            let Some((&b, rest)) = buf.split_first() else { return Err(err("truncated varint")) };
            *buf = rest;
            v |= u64::from(b & 0x7f) << (7 * i);
            if b < 0x80 {
                return Ok(v);
            }
        }
        Err(err("varint longer than 10 bytes"))
    }

    pub fn get_key(buf: &mut &[u8]) -> Result<(u32, u8), DecodeError> {
        let key = get_varint(buf)?;
        let field = u32::try_from(key >> 3).map_err(|_| err("field number out of range"))?;
        if field == 0 {
            return Err(err("field number 0"));
        }
        Ok((field, (key & 7) as u8))
    }

    pub fn get_len_delimited<'a>(buf: &mut &'a [u8]) -> Result<&'a [u8], DecodeError> {
        let len = get_varint(buf)?;
        let len = usize::try_from(len).map_err(|_| err("length out of range"))?;
        if len > buf.len() {
            return Err(err("length-delimited field runs past the message"));
        }
        let (field, rest) = buf.split_at(len);
        *buf = rest;
        Ok(field)
    }

    pub fn get_fixed64(buf: &mut &[u8]) -> Result<[u8; 8], DecodeError> {
        let Some((bytes, rest)) = buf.split_first_chunk::<8>() else { return Err(err("truncated fixed64")) };
        *buf = rest;
        Ok(*bytes)
    }

    pub fn skip(buf: &mut &[u8], wire_type: u8) -> Result<(), DecodeError> {
        match wire_type {
            VARINT => get_varint(buf).map(drop),
            FIXED64 => get_fixed64(buf).map(drop),
            LEN => get_len_delimited(buf).map(drop),
            FIXED32 => {
                let Some((_, rest)) = buf.split_first_chunk::<4>() else { return Err(err("truncated fixed32")) };
                *buf = rest;
                Ok(())
            }
            _ => Err(err("unsupported wire type (groups are not used by forgemon)")),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use std::collections::BTreeMap;

    use super::*;

    pub(crate) fn batch(n: usize) -> SampleBatch {
        SampleBatch {
            source: "daq0".to_string(),
            seq: 41,
            device_time_ns: -1_234_567,
            host_time_ns: 79_962_097_800,
            period_ns: 10_000.0,
            roles: vec![Role::Load, Role::Disp, Role::Acc],
            values: (0..3 * n).map(|i| i as f64 * 0.5 - 7.25).collect(),
        }
    }

    fn to_pb(b: &SampleBatch) -> pb::SampleBatch {
        pb::SampleBatch {
            source: b.source.clone(),
            seq: b.seq,
            device_time_ns: b.device_time_ns,
            host_time_ns: b.host_time_ns,
            period_ns: b.period_ns,
            roles: b.roles.iter().map(|r| role_to_pb(*r) as i32).collect(),
            values: b.values.clone(),
        }
    }

    #[test]
    fn samples_encode_exactly_like_prost() {
        for b in [batch(0), batch(1), batch(500), SampleBatch { seq: 0, host_time_ns: 0, ..batch(3) }] {
            let mut ours = Vec::new();
            encode_samples(&b, &mut ours).expect("encodes");
            assert_eq!(ours, to_pb(&b).encode_to_vec(), "batch of {} samples", b.len());
        }
    }

    #[test]
    fn samples_round_trip() {
        let b = batch(257);
        let mut bytes = Vec::new();
        encode_samples(&b, &mut bytes).expect("encodes");
        assert_eq!(decode_samples(&bytes).expect("decodes"), b);
        assert_eq!(decode_payload(MessageKind::Samples, &bytes).expect("decodes"), Payload::Samples(b));
    }

    #[test]
    fn samples_decoder_reads_unpacked_fields_unknown_fields_and_any_order() {
        let b = batch(2);
        let mut bytes = Vec::new();
        // Field 99 (unknown), varint 5: key 99<<3|0 = 792 = 0x98 0x06, value 0x05.
        bytes.extend_from_slice(&[0x98, 0x06, 0x05]);
        // Values first, unpacked: key 7<<3|1 = 0x39, then 8 LE bytes each.
        for v in &b.values {
            bytes.push(0x39);
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        // Roles unpacked: key 6<<3|0 = 0x30, then the enum value.
        for r in &b.roles {
            bytes.extend_from_slice(&[0x30, role_to_pb(*r) as u8]);
        }
        let mut rest = Vec::new();
        encode_samples(&SampleBatch { roles: vec![], values: vec![], ..b.clone() }, &mut rest).expect("encodes");
        bytes.extend_from_slice(&rest);
        assert_eq!(decode_samples(&bytes).expect("decodes"), b);
    }

    #[test]
    fn samples_decoder_rejects_garbage_without_panicking() {
        let mut good = Vec::new();
        encode_samples(&batch(4), &mut good).expect("encodes");
        // Every truncation either decodes to something consistent or errors; none panics.
        for cut in 0..good.len() {
            let _ = decode_samples(&good[..cut]);
        }
        // Values field whose length claims more bytes than there are: 0x3a = key 7<<3|2, len 0x7f.
        assert!(decode_samples(&[0x3a, 0x7f, 0x00]).is_err());
        // Packed doubles of 5 bytes.
        assert!(decode_samples(&[0x3a, 0x05, 1, 2, 3, 4, 5]).is_err());
        // Role 9 does not exist: 0x32 = key 6<<3|2, len 1, value 9.
        assert_eq!(decode_samples(&[0x32, 0x01, 0x09]), Err(DecodeError::UnknownRole { value: 9 }));
        // Two roles, three values: ragged.
        let ragged = SampleBatch { roles: vec![Role::Load, Role::Acc], values: vec![1.0, 2.0, 3.0], ..batch(0) };
        let bytes = to_pb(&ragged).encode_to_vec();
        assert_eq!(decode_samples(&bytes), Err(DecodeError::RaggedBatch { values: 3, channels: 2 }));
        assert!(encode_samples(&ragged, &mut Vec::new()).is_err());
        // Field 1 as a varint: wrong wire type.
        assert!(decode_samples(&[0x08, 0x01]).is_err());
        // A varint of 11 continuation bytes.
        assert!(decode_samples(&[0x10, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01]).is_err());
    }

    pub(crate) fn estimate(with_optional: bool) -> BlowEstimate {
        BlowEstimate {
            judgement: with_optional.then(|| crate::recipe::Judgement {
                ok: false,
                recipe: "flange".into(),
                reasons: vec!["peak_load above window".into()],
            }),
            blow: 3,
            t_contact_s: 81.2031,
            v_impact_mps: 5.21,
            kinetic_in_j: Some(14931.0),
            plastic_j: Some(6020.0),
            friction_j: with_optional.then_some(6900.0),
            damped_j: Some(520.0),
            elastic_j: Some(1490.0),
            efficiency: Some(0.403),
            final_load_n: 2.1e6,
            h_end_m: with_optional.then_some(0.0124),
            class: BlowClass::Intermediate,
            alert: with_optional.then(|| alert(AlertKind::ElasticBlow)),
            t_end_s: 81.2152,
            peak_load_n: 2.6e6,
            residual: Some(-0.012),
            sensor_check: with_optional.then_some(0.034),
            method: with_optional.then_some(crate::estimate::Method::ModelFit),
            gap_s: if with_optional { 2e-5 } else { 0.0 },
            h_start_m: with_optional.then_some(0.0151),
            height_source: if with_optional {
                crate::estimate::HeightSource::Encoder
            } else {
                crate::estimate::HeightSource::Unknown
            },
            implausible: None,
            flow_stress_scale: with_optional.then_some(1.04),
            scale_by_half: None,
            model_residual: with_optional.then_some(0.004),
            model_residual_by_phase: with_optional.then_some(PhaseResidual {
                impact: 0.001,
                forming: 0.005,
                spring_back: 0.002,
            }),
            at_bound: if with_optional { [("damped_J".to_string(), -3.5)].into() } else { Default::default() },
            height_check: with_optional.then_some(HeightCheck {
                sheet_m: 0.0150,
                encoder_m: 0.0151,
                tolerance_m: 8e-5,
                agree: false,
            }),
            billet: BilletTag {
                billet: 2,
                billet_blow: 3,
                billet_check: with_optional.then_some(BilletCheck::ContactAboveLastEnd),
                h_start_off_sheet_m: with_optional.then_some(-0.0021),
            },
            channels: if with_optional { Channels::ALL.without(Role::Load) } else { Channels::ALL },
            efficiency_sd: with_optional.then_some(0.004),
            unobserved: if with_optional {
                [("h_end_m".to_string(), "no encoder".to_string())].into()
            } else {
                Default::default()
            },
            excluded: if with_optional {
                [("load".to_string(), "load_N read 0 N throughout the blow (dead)".to_string())].into()
            } else {
                Default::default()
            },
            acc_check: with_optional.then_some(0.012),
        }
    }

    /// A billet's summary, with or without the optional figures.
    pub(crate) fn billet(with_optional: bool) -> crate::estimate::billet_book::BilletSummary {
        let some = |x: f64| with_optional.then_some(x);
        crate::estimate::billet_book::BilletSummary {
            billet: 4,
            t_start_s: 81.2031,
            t_end_s: 84.9,
            blows: 8,
            incomplete_blows: u32::from(!with_optional),
            energies_partial: !with_optional,
            implausible_blows: u32::from(!with_optional),
            h_start_m: some(0.112),
            h_start_off_sheet_m: some(-0.0021),
            h_end_m: some(0.0401),
            kinetic_in_j: 98_000.0,
            plastic_j: 61_000.0,
            friction_j: some(0.0),
            efficiency: some(0.622),
            first_hard_blow: with_optional.then_some(6),
            hard_blows: 3,
            alerts: 1,
            checked_blows: 0,
            finished: with_optional,
            trace: crate::estimate::billet_book::Trace {
                part_id: with_optional.then(|| "P-000417".into()),
                lot: with_optional.then(|| "4711".into()),
                die_set: with_optional.then(|| "17".into()),
            },
        }
    }

    pub(crate) fn alert(kind: AlertKind) -> Alert {
        Alert {
            kind,
            blow: 3,
            reason: "3 of the last 5 blows below efficiency 0.5".to_string(),
            figures: BTreeMap::from([("efficiency".to_string(), 0.403), ("k".to_string(), 3.0)]),
        }
    }

    #[test]
    fn every_payload_round_trips() {
        let payloads = vec![
            Payload::Samples(batch(10)),
            Payload::Boundary(BlowBoundary {
                blow: 7,
                t_trigger_s: 1.5,
                t_contact_s: 1.501,
                t_end_s: 1.53,
                source: "daq0".into(),
            }),
            Payload::Result(Box::new(estimate(true))),
            Payload::Result(Box::new(estimate(false))),
            Payload::Result(Box::new(BlowEstimate { class: BlowClass::Soft, ..estimate(false) })),
            Payload::Result(Box::new(BlowEstimate { class: BlowClass::Hard, ..estimate(false) })),
            Payload::Result(Box::new(BlowEstimate {
                judgement: None,
                class: BlowClass::Incomplete,
                kinetic_in_j: None,
                plastic_j: None,
                damped_j: None,
                elastic_j: None,
                efficiency: None,
                residual: None,
                sensor_check: None,
                method: None,
                gap_s: 0.01,
                ..estimate(false)
            })),
            Payload::Result(Box::new(BlowEstimate {
                class: BlowClass::Implausible,
                kinetic_in_j: None,
                plastic_j: None,
                damped_j: None,
                elastic_j: None,
                efficiency: None,
                residual: None,
                h_start_m: None,
                implausible: Some(Implausible {
                    check: Check::StartHeight,
                    reason: "start height -6.76 mm outside (0, 90.05] mm".into(),
                }),
                ..estimate(true)
            })),
            Payload::Alert(alert(AlertKind::ElasticBlow)),
            Payload::Alert(alert(AlertKind::ModelHealth)),
            Payload::Alert(alert(AlertKind::Sensor)),
            Payload::Gap(Gap { source: "daq0".into(), t_s: 12.5, samples_lost: 400, reason: "sequence_jump".into() }),
            Payload::Status(Status {
                source: "daq0".into(),
                state: "connected".into(),
                samples: 1,
                frames: 2,
                drops: 3,
                gaps: 4,
                crc_errors: 5,
                decode_errors: 6,
                reconnects: 7,
                detail: "/dev/ttyACM0".into(),
            }),
            Payload::Config(ConfigFile { name: "machine.toml".into(), text: "kind = \"hammer\"\n".into() }),
            Payload::Billet(Box::new(billet(true))),
            Payload::Billet(Box::new(billet(false))),
        ];
        for p in payloads {
            let mut bytes = Vec::new();
            encode_payload(&p, &mut bytes).expect("encodes");
            assert_eq!(decode_payload(p.kind(), &bytes).expect("decodes"), p);
        }
    }

    #[test]
    fn an_absent_optional_stays_absent_and_zero_stays_zero() {
        let zero = BlowEstimate { friction_j: Some(0.0), h_end_m: None, ..estimate(false) };
        let mut bytes = Vec::new();
        encode_payload(&Payload::Result(Box::new(zero.clone())), &mut bytes).expect("encodes");
        let back = pb::BlowResult::decode(bytes.as_slice()).expect("decodes");
        assert_eq!(back.friction_j, Some(0.0), "proto3 optional keeps an explicit zero");
        assert_eq!(back.h_end_m, None);
    }

    /// Issue 16: `sensor_check` is field 24, present when reported and absent when not (an
    /// incomplete blow, or a recording from before it existed).
    #[test]
    fn the_sensor_check_round_trips_and_stays_absent_when_absent() {
        for check in [Some(0.1), Some(0.0), Some(-0.031), None] {
            let r = BlowEstimate { sensor_check: check, ..estimate(false) };
            let mut bytes = Vec::new();
            encode_payload(&Payload::Result(Box::new(r.clone())), &mut bytes).expect("encodes");
            assert_eq!(pb::BlowResult::decode(bytes.as_slice()).expect("decodes").sensor_check, check);
            assert_eq!(decode_payload(MessageKind::Result, &bytes).expect("decodes"), Payload::Result(Box::new(r)));
        }
    }

    #[test]
    fn unknown_strings_are_errors() {
        let mut r = result_to_pb(&estimate(false));
        r.class = "medium".into();
        let bytes = r.encode_to_vec();
        assert_eq!(
            decode_payload(MessageKind::Result, &bytes),
            Err(DecodeError::UnknownClass { class: "medium".into() })
        );
        let mut a = alert_to_pb(&alert(AlertKind::ModelHealth));
        a.kind = "fire".into();
        assert_eq!(
            decode_payload(MessageKind::Alert, &a.encode_to_vec()),
            Err(DecodeError::UnknownAlertKind { kind: "fire".into() })
        );
    }
}
