//! The live blow advisor (issue 20, docs/interfaces.md §9): after each blow the service replans the
//! billet's next blows from its measured height with the identified model (`advise`), and
//! serves the plan in `/status` (`advice`), on the dashboard and in the PLC image
//! (registers 17–19). A new billet is planned from its process sheet's height.
//!
//! It listens to the live feed like any front end, so it never holds up the pipeline: a plan
//! takes tens of ms (`benches/advise.rs`) on a blocking thread; blows that end meanwhile are
//! not queued, the latest one is planned next. A blow whose height is not known (incomplete,
//! samples lost) makes the advice unknown until the next measured blow: no plan is served
//! from a height the service did not measure.

use std::sync::Arc;

use anyhow::Context;
use tokio::sync::broadcast;

use super::live::{Live, LiveEvent};
use super::status::SharedStatus;
pub use crate::advise::Advice;
use crate::advise::{Advisor, PlanRequest};
use crate::config::advisor::AdvisorConfig;
use crate::estimate::BlowEstimate;
use crate::physics::effects::EffectSet;
use crate::physics::machine::Machine;
use crate::physics::process::Process;

/// What the advisor plans with, owned so that a plan runs on a blocking thread.
struct Model {
    machine: Machine,
    effects: EffectSet,
    process: Process,
    cfg: AdvisorConfig,
}

/// What to plan next.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Job {
    billet: u32,
    after_blow: u32,
    /// `None`: the height is not known (the blow was incomplete).
    h_now_m: Option<f64>,
}

/// The running advisor; it stops with the live feed (when the service stops) or when dropped.
pub struct AdvisorTask {
    task: tokio::task::JoinHandle<()>,
}

impl Drop for AdvisorTask {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl super::faces::Face for AdvisorTask {}

/// The advisor as a face (`faces::FACES`): `[advisor]`.
pub fn face<'a>(
    ctx: &'a super::faces::FaceContext<'a>,
) -> futures_util::future::BoxFuture<'a, anyhow::Result<Option<Box<dyn super::faces::Face>>>> {
    let hook = ctx.on_advice.lock().ok().and_then(|mut h| h.take());
    let task = start(
        ctx.config.advisor.as_ref(),
        ctx.machine,
        ctx.machine_text,
        ctx.process,
        ctx.status.clone(),
        ctx.bus,
        hook,
    );
    Box::pin(async move { Ok(super::faces::boxed(task?)) })
}

/// Start the advisor when `[advisor]` is configured. It needs the billet's process sheet
/// (the law it plans with and the start height); `machine_text` gives the machine's effects.
pub fn start(
    cfg: Option<&AdvisorConfig>,
    machine: &Machine,
    machine_text: &str,
    process: Option<&Process>,
    status: SharedStatus,
    live: &Live,
    hook: Option<super::AdviceHook>,
) -> anyhow::Result<Option<AdvisorTask>> {
    let Some(cfg) = cfg else { return Ok(None) };
    let process = process.context("[advisor] needs the billet's process sheet: set `process` in service.toml")?;
    let file = crate::config::parse_machine("machine.toml", machine_text)?;
    let model =
        Arc::new(Model { machine: *machine, effects: file.effect_set(), process: process.clone(), cfg: cfg.clone() });
    let task = tokio::spawn(run(model, live.subscribe(), status, live.clone(), hook));
    Ok(Some(AdvisorTask { task }))
}

/// The job a live event asks for, if any.
fn job_for(ev: &LiveEvent, sheet_height_m: f64) -> Option<Job> {
    match ev {
        LiveEvent::Blow(b) => Some(job_after(b)),
        LiveEvent::NewBillet => Some(Job { billet: 0, after_blow: 0, h_now_m: Some(sheet_height_m) }),
        _ => None,
    }
}

fn job_after(b: &BlowEstimate) -> Job {
    let known = b.has_energies().then_some(b.h_end_m).flatten();
    Job { billet: b.billet.billet, after_blow: b.billet.billet_blow, h_now_m: known }
}

async fn run(
    model: Arc<Model>,
    mut rx: broadcast::Receiver<LiveEvent>,
    status: SharedStatus,
    live: Live,
    mut hook: Option<super::AdviceHook>,
) {
    let sheet = model.process.billet.height_m;
    // The first billet is planned before its first blow, from its sheet.
    let mut next = Some(Job { billet: 0, after_blow: 0, h_now_m: Some(sheet) });
    loop {
        if let Some(job) = next.take() {
            let m = model.clone();
            let Ok(advice) = tokio::task::spawn_blocking(move || plan(&m, job)).await else { return };
            if let Ok(mut s) = status.lock() {
                s.advice = Some(advice.clone());
            }
            if let Some(h) = hook.as_mut() {
                h(&advice);
            }
            live.publish(LiveEvent::Advice(Arc::new(advice)));
        }
        // Whatever ended while planning: only the latest counts.
        loop {
            match rx.try_recv() {
                Ok(ev) => next = job_for(&ev, sheet).or(next),
                Err(broadcast::error::TryRecvError::Lagged(_)) => {
                    next = status.lock().ok().and_then(|s| s.last_blow.as_ref().map(job_after)).or(next);
                }
                Err(broadcast::error::TryRecvError::Closed) => return,
                Err(broadcast::error::TryRecvError::Empty) => break,
            }
        }
        if next.is_none() {
            match rx.recv().await {
                Ok(ev) => next = job_for(&ev, sheet),
                Err(broadcast::error::RecvError::Lagged(_)) => {
                    next = status.lock().ok().and_then(|s| s.last_blow.as_ref().map(job_after));
                }
                Err(broadcast::error::RecvError::Closed) => return,
            }
        }
    }
}

/// Plan `job` with the model (blocking: tens of ms).
fn plan(m: &Model, job: Job) -> Advice {
    let started = std::time::Instant::now();
    let mut advice =
        Advice { billet: job.billet, after_blow: job.after_blow, plan: None, why_not: None, planned_ms: 0.0 };
    match job.h_now_m {
        None => advice.why_not = Some("the last blow was incomplete: the billet's height is not known".into()),
        Some(h_now_m) => {
            let advisor = Advisor::new(&m.machine, &m.effects, &m.process);
            let req = PlanRequest {
                h_now_m,
                target_m: m.cfg.target_height_m,
                blows_done: job.after_blow as usize,
                speeds: m.cfg.speeds.clone(),
            };
            match advisor.plan(&req) {
                Ok(p) => advice.plan = Some(p),
                Err(e) => advice.why_not = Some(e.to_string()),
            }
        }
    }
    advice.planned_ms = started.elapsed().as_secs_f64() * 1e3;
    advice
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blow's height is planned from only when the blow is complete: an incomplete blow's
    /// height is carried from before the samples were lost, not measured.
    #[test]
    fn only_a_complete_blow_with_a_height_is_planned_from() {
        let mut b = super::super::plc_server::tests::blow();
        b.h_end_m = Some(0.05);
        b.billet.billet = 2;
        b.billet.billet_blow = 3;
        assert_eq!(job_after(&b), Job { billet: 2, after_blow: 3, h_now_m: Some(0.05) });
        b.class = crate::estimate::BlowClass::Incomplete;
        assert_eq!(job_after(&b).h_now_m, None);
        let m = Model {
            machine: crate::config::parse_machine("m", include_str!("../../config/hammer-lg1000.machine.toml"))
                .expect("machine")
                .machine,
            effects: EffectSet::NONE,
            process: crate::config::parse_process("p", include_str!("../../config/steel-16NiCrMo13.process.toml"))
                .expect("sheet"),
            cfg: AdvisorConfig { target_height_m: 0.03, speeds: crate::advise::Speeds::Settings(vec![3.9, 5.3]) },
        };
        let a = plan(&m, job_after(&b));
        assert!(a.plan.is_none() && a.why_not.as_deref().is_some_and(|w| w.contains("incomplete")), "{a:?}");
        assert_eq!((a.blows_to_target(), a.next_kinetic_j()), (None, None));
    }
}
