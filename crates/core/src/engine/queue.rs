//! The event queue: events ordered by (time, insertion order).
//!
//! Ties at the same instant are broken by the order in which the events were scheduled,
//! as in ns-3, so a run never depends on heap internals or on floating-point comparisons.

use crate::core::SimTime;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// What happens at an event. Events are plain data: the trial loop decides what each
/// kind means, so sources and estimators never see the queue.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum EventKind {
    /// Source number `0` takes its next sample.
    Sample(usize),
    /// A scoring instant of a periodic scoring grid (see `engine::trial::Scoring`).
    Score,
    /// The trial ends.
    End,
}

/// A scheduled event.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Event {
    pub t: SimTime,
    pub seq: u64,
    pub kind: EventKind,
}

/// A min-queue of events.
#[derive(Debug, Default)]
pub struct EventQueue {
    heap: BinaryHeap<Reverse<(SimTime, u64, EventKind)>>,
    next_seq: u64,
}

impl EventQueue {
    /// An empty queue with room for `capacity` pending events (one per source is typical).
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            heap: BinaryHeap::with_capacity(capacity),
            next_seq: 0,
        }
    }

    /// Schedules `kind` at `t`.
    pub fn schedule(&mut self, t: SimTime, kind: EventKind) {
        self.heap.push(Reverse((t, self.next_seq, kind)));
        self.next_seq += 1;
    }

    /// Removes and returns the earliest event (the first scheduled among equal times).
    pub fn pop(&mut self) -> Option<Event> {
        self.heap
            .pop()
            .map(|Reverse((t, seq, kind))| Event { t, seq, kind })
    }

    /// The time of the earliest pending event.
    pub fn peek_time(&self) -> Option<SimTime> {
        self.heap.peek().map(|Reverse((t, _, _))| *t)
    }

    /// Number of pending events.
    pub fn len(&self) -> usize {
        self.heap.len()
    }

    /// True when nothing is pending.
    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orders_by_time_then_insertion() {
        let mut q = EventQueue::with_capacity(4);
        q.schedule(SimTime(10), EventKind::Sample(2));
        q.schedule(SimTime(5), EventKind::Sample(7));
        q.schedule(SimTime(10), EventKind::Sample(1));
        q.schedule(SimTime(10), EventKind::End);
        let order: Vec<EventKind> = std::iter::from_fn(|| q.pop()).map(|e| e.kind).collect();
        assert_eq!(
            order,
            vec![
                EventKind::Sample(7),
                EventKind::Sample(2),
                EventKind::Sample(1),
                EventKind::End
            ]
        );
    }
}
