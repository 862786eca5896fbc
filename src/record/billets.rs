//! The `/billets` channel's message (issue 22): a billet's summary to and from its protobuf
//! form, field for field.

use crate::estimate::billet_book::{BilletSummary, Trace};

use super::schema::pb;

pub(crate) fn to_pb(b: &BilletSummary) -> pb::BilletSummary {
    pb::BilletSummary {
        billet: b.billet,
        t_start_s: b.t_start_s,
        t_end_s: b.t_end_s,
        blows: b.blows,
        incomplete_blows: b.incomplete_blows,
        implausible_blows: b.implausible_blows,
        energies_partial: b.energies_partial,
        h_start_m: b.h_start_m,
        h_start_off_sheet_m: b.h_start_off_sheet_m,
        h_end_m: b.h_end_m,
        kinetic_in_j: b.kinetic_in_j,
        plastic_j: b.plastic_j,
        friction_j: b.friction_j,
        efficiency: b.efficiency,
        first_hard_blow: b.first_hard_blow,
        hard_blows: b.hard_blows,
        alerts: b.alerts,
        checked_blows: b.checked_blows,
        finished: b.finished,
        part_id: b.trace.part_id.clone(),
        lot: b.trace.lot.clone(),
        die_set: b.trace.die_set.clone(),
    }
}

pub(crate) fn from_pb(b: pb::BilletSummary) -> BilletSummary {
    BilletSummary {
        billet: b.billet,
        t_start_s: b.t_start_s,
        t_end_s: b.t_end_s,
        blows: b.blows,
        incomplete_blows: b.incomplete_blows,
        implausible_blows: b.implausible_blows,
        energies_partial: b.energies_partial,
        h_start_m: b.h_start_m,
        h_start_off_sheet_m: b.h_start_off_sheet_m,
        h_end_m: b.h_end_m,
        kinetic_in_j: b.kinetic_in_j,
        plastic_j: b.plastic_j,
        friction_j: b.friction_j,
        efficiency: b.efficiency,
        first_hard_blow: b.first_hard_blow,
        hard_blows: b.hard_blows,
        alerts: b.alerts,
        checked_blows: b.checked_blows,
        finished: b.finished,
        trace: Trace { part_id: b.part_id, lot: b.lot, die_set: b.die_set },
    }
}
