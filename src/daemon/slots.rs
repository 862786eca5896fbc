//! The connection cap of a server, counted at accept (issue 39): HTTP, the PLC server and
//! OPC UA each hold at most their `max_connections` connections.
//!
//! A connection takes a [`Slot`] when it is accepted and gives it back when the slot is
//! dropped. A connection is *admitted* once its client proved itself (a request that passed
//! the token, a Modbus request, an activated OPC UA session). At the cap, a newcomer takes
//! the slot of the oldest connection not admitted yet, which is told to close (it is
//! *shed*); when every slot holds an admitted connection, the newcomer is refused. So
//! clients that connect and wait, or send half a request, can never keep out the ones that
//! work.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::{Context, Poll};

use futures_util::task::AtomicWaker;

/// A connection's admission, shared with whatever proves its client (the HTTP token check
/// gets it as a request extension).
#[derive(Clone, Debug, Default)]
pub struct Admission(Arc<AtomicBool>);

impl Admission {
    /// The client proved itself: the connection keeps its slot until it closes.
    pub fn admit(&self) {
        self.0.store(true, Ordering::Release);
    }

    pub fn is_admitted(&self) -> bool {
        self.0.load(Ordering::Acquire)
    }
}

/// What the slots have done since the server started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlotCounts {
    /// Connections shed to make room for a newcomer (or for a descriptor, when accept failed).
    pub shed: u64,
    /// Newcomers refused because every slot held an admitted connection.
    pub refused: u64,
    /// Accepts that failed (out of descriptors and the like).
    pub accept_failures: u64,
}

/// A server's slots: the cap and the connections holding one, in accept order.
#[derive(Debug, Clone)]
pub struct Slots {
    registry: Arc<Mutex<Registry>>,
}

#[derive(Debug)]
struct Registry {
    cap: usize,
    open: BTreeMap<u64, Arc<SlotState>>,
    next_id: u64,
    counts: SlotCounts,
}

#[derive(Debug, Default)]
struct SlotState {
    admission: Admission,
    shed: AtomicBool,
    waker: AtomicWaker,
}

/// One connection's slot, given back when it is dropped.
#[derive(Debug)]
pub struct Slot {
    id: u64,
    state: Arc<SlotState>,
    registry: Arc<Mutex<Registry>>,
}

impl Slot {
    /// Its place in accept order.
    pub fn id(&self) -> u64 {
        self.id
    }

    pub fn admission(&self) -> Admission {
        self.state.admission.clone()
    }

    /// The client proved itself (see [`Admission::admit`]).
    pub fn admit(&self) {
        self.state.admission.admit();
    }

    pub fn is_admitted(&self) -> bool {
        self.state.admission.is_admitted()
    }

    /// Whether a newcomer took this slot; wakes `cx` when one does.
    pub fn poll_shed(&self, cx: &Context<'_>) -> bool {
        self.state.waker.register(cx.waker());
        self.state.shed.load(Ordering::Acquire)
    }

    /// Resolves once a newcomer took this slot.
    pub async fn shed(&self) {
        std::future::poll_fn(|cx| if self.poll_shed(cx) { Poll::Ready(()) } else { Poll::Pending }).await;
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        // A shed slot was removed when it was shed; its id is not reused.
        lock(&self.registry).open.remove(&self.id);
    }
}

fn lock(registry: &Mutex<Registry>) -> MutexGuard<'_, Registry> {
    registry.lock().unwrap_or_else(|p| p.into_inner())
}

impl Slots {
    /// Slots for `cap` connections (at least one).
    pub fn new(cap: usize) -> Self {
        let registry = Registry { cap: cap.max(1), open: BTreeMap::new(), next_id: 0, counts: SlotCounts::default() };
        Slots { registry: Arc::new(Mutex::new(registry)) }
    }

    /// A slot for a connection just accepted: a free one, or the oldest unadmitted
    /// connection's, which is shed; `None` (counted) when admitted connections hold them all.
    pub fn open(&self) -> Option<Slot> {
        let mut r = lock(&self.registry);
        if r.open.len() >= r.cap && !shed_oldest_unadmitted(&mut r) {
            r.counts.refused += 1;
            return None;
        }
        let (id, state) = (r.next_id, Arc::new(SlotState::default()));
        r.next_id += 1;
        r.open.insert(id, state.clone());
        Some(Slot { id, state, registry: self.registry.clone() })
    }

    /// An accept failed (out of descriptors): count it, and shed the oldest unadmitted
    /// connection to free a descriptor; whether there was one.
    pub fn accept_failed(&self) -> bool {
        let mut r = lock(&self.registry);
        r.counts.accept_failures += 1;
        shed_oldest_unadmitted(&mut r)
    }

    /// Connections holding a slot now.
    pub fn len(&self) -> usize {
        lock(&self.registry).open.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn counts(&self) -> SlotCounts {
        lock(&self.registry).counts
    }
}

/// Tell the oldest connection not admitted to close and free its slot; whether there was one.
fn shed_oldest_unadmitted(r: &mut Registry) -> bool {
    let Some(id) = r.open.iter().find(|(_, s)| !s.admission.is_admitted()).map(|(id, _)| *id) else {
        return false;
    };
    if let Some(victim) = r.open.remove(&id) {
        victim.shed.store(true, Ordering::Release);
        victim.waker.wake();
        r.counts.shed += 1;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn was_shed(slot: &Slot) -> bool {
        slot.poll_shed(&Context::from_waker(std::task::Waker::noop()))
    }

    #[test]
    fn at_the_cap_a_newcomer_sheds_the_oldest_unadmitted_connection() {
        let slots = Slots::new(3);
        let s: Vec<Slot> = (0..3).map(|_| slots.open().expect("room")).collect();
        assert_eq!(slots.len(), 3);
        s[0].admit();
        // The fourth takes the slot of the oldest not admitted (1), not of the admitted 0.
        let d = slots.open().expect("a slot shed");
        assert!(was_shed(&s[1]) && !was_shed(&s[0]) && !was_shed(&s[2]));
        assert_eq!((slots.len(), slots.counts().shed), (3, 1));
        let mut s = s.into_iter();
        let (s0, s1, s2) = (s.next().unwrap(), s.next().unwrap(), s.next().unwrap());
        // A shed connection ending frees nothing more.
        drop(s1);
        assert_eq!(slots.len(), 3);
        s2.admit();
        d.admit();
        // Every slot admitted: the newcomer is refused, and no one is shed.
        assert!(slots.open().is_none());
        assert_eq!(slots.counts(), SlotCounts { shed: 1, refused: 1, accept_failures: 0 });
        assert!(!slots.accept_failed());
        // A connection that ends frees its slot.
        drop(s0);
        let e = slots.open().expect("a free slot");
        assert!(!was_shed(&e));
        assert_eq!(slots.counts(), SlotCounts { shed: 1, refused: 1, accept_failures: 1 });
        assert_eq!(slots.len(), 3);
    }

    #[test]
    fn a_cap_of_zero_still_holds_one_connection() {
        let slots = Slots::new(0);
        let a = slots.open().expect("one");
        let b = slots.open().expect("sheds the first");
        assert!(was_shed(&a) && !was_shed(&b));
        assert_eq!(slots.len(), 1);
    }

    #[tokio::test]
    async fn a_shed_slot_wakes_its_waiting_connection() {
        let slots = Slots::new(1);
        let a = slots.open().expect("one");
        let waiting = tokio::spawn(async move { a.shed().await });
        tokio::task::yield_now().await;
        let _b = slots.open().expect("sheds a");
        tokio::time::timeout(std::time::Duration::from_secs(5), waiting)
            .await
            .expect("the shed connection was woken")
            .expect("joined");
    }
}
