//! The links' and the loop's counters as other threads see them: [`SharedLinkStats`], the one
//! atomic mirror of [`LinkStats`] (a real-time thread stores its links' counters, a display or
//! the writer thread loads them, lock-free), and [`LoopCounters`], the counters the run's
//! events report, with the event texts derived from their fields.
//!
//! The counters themselves are defined once, in [`LinkStats`]; this module adds no counter.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::devices::LinkStats;

/// Number of counters in a [`LinkStats`].
const LINK_COUNTERS: usize = 11;

/// [`LinkStats`] as atomics: the thread that owns a link stores its counters (after each tick
/// or control period), other threads load them. Relaxed ordering: each counter is exact, a
/// snapshot of all of them is not taken at one instant.
#[derive(Debug, Default)]
pub struct SharedLinkStats([AtomicU64; LINK_COUNTERS]);

/// Writes the conversions between a [`LinkStats`] and its counters in the mirror's order from
/// one list of its fields (every field: adding one to [`LinkStats`] fails to compile here until
/// the list has it too).
macro_rules! mirror_order {
    ($($field:ident),+ $(,)?) => {
        /// The counters of `s`, in the mirror's order.
        fn to_array(s: &LinkStats) -> [u64; LINK_COUNTERS] {
            let LinkStats { $($field),+ } = *s;
            [$($field),+]
        }

        /// The [`LinkStats`] of counters in the mirror's order.
        fn from_array(v: [u64; LINK_COUNTERS]) -> LinkStats {
            let [$($field),+] = v;
            LinkStats { $($field),+ }
        }
    };
}

mirror_order!(
    received,
    accepted,
    malformed,
    invalid,
    foreign,
    stale,
    lost,
    late,
    sent,
    send_errors,
    io_errors,
);

impl SharedLinkStats {
    /// Stores every counter of `s` (never allocates).
    pub fn store(&self, s: &LinkStats) {
        for (a, v) in self.0.iter().zip(to_array(s)) {
            a.store(v, Ordering::Relaxed);
        }
    }

    /// The counters last stored.
    pub fn load(&self) -> LinkStats {
        from_array(std::array::from_fn(|i| self.0[i].load(Ordering::Relaxed)))
    }
}

/// A link's counters in a run's summary, as `(label, value)`: accepted, lost, late, dropped
/// (malformed, invalid, foreign or stale), socket errors.
pub fn link_summary(s: &LinkStats) -> [(&'static str, u64); 5] {
    [
        ("accepted", s.accepted),
        ("lost", s.lost),
        ("late", s.late),
        ("dropped", s.dropped()),
        ("socket errors", s.io_errors),
    ]
}

/// `"accepted 3, lost 0, late 1, dropped 0, socket errors 0"`: [`link_summary`] as text.
pub fn link_summary_text(s: &LinkStats) -> String {
    link_summary(s)
        .iter()
        .map(|(label, v)| format!("{label} {v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The loop's counters that a run's events report: overruns and both links' counters.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LoopCounters {
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// The sensor link's counters.
    pub sensor: LinkStats,
    /// The robot link's counters.
    pub robot: LinkStats,
}

impl LoopCounters {
    /// Names of the [`LoopCounters::faults`], as the fault events print them.
    pub const FAULT_NAMES: [&'static str; 5] = [
        "overruns",
        "sensor records lost",
        "robot feedback lost",
        "datagrams dropped",
        "socket errors",
    ];

    /// The fault counters (named by [`LoopCounters::FAULT_NAMES`]): overruns, sensor records
    /// lost, robot feedback lost, datagrams dropped and socket errors on both links.
    pub fn faults(&self) -> [u64; 5] {
        let (s, r) = (&self.sensor, &self.robot);
        [
            self.overruns,
            s.lost,
            r.lost,
            s.dropped() + r.dropped(),
            s.io_errors + r.io_errors,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mirror_keeps_every_counter() {
        let mut s = LinkStats::default();
        let values = (1..=LINK_COUNTERS as u64).collect::<Vec<_>>();
        for (field, v) in [
            &mut s.received,
            &mut s.accepted,
            &mut s.malformed,
            &mut s.invalid,
            &mut s.foreign,
            &mut s.stale,
            &mut s.lost,
            &mut s.late,
            &mut s.sent,
            &mut s.send_errors,
            &mut s.io_errors,
        ]
        .into_iter()
        .zip(&values)
        {
            *field = *v;
        }
        let shared = SharedLinkStats::default();
        shared.store(&s);
        assert_eq!(shared.load(), s);
        assert_eq!(to_array(&shared.load()).to_vec(), values);
    }

    #[test]
    fn the_summary_names_the_counters() {
        let s = LinkStats {
            accepted: 3,
            late: 1,
            stale: 2,
            ..LinkStats::default()
        };
        assert_eq!(
            link_summary_text(&s),
            "accepted 3, lost 0, late 1, dropped 2, socket errors 0"
        );
    }
}
