//! Monotonic clock, absolute sleeps and latency histograms for the real-time threads.
//!
//! On Linux the clock is `CLOCK_MONOTONIC` and sleeps are `clock_nanosleep(TIMER_ABSTIME)`,
//! so a late wake-up never shifts the following deadlines; the thread's timer slack is cut to
//! 1 µs ([`tighten_timer_slack`]). Elsewhere `std::time::Instant` and `thread::sleep` stand in.

/// Nanoseconds on the monotonic clock (arbitrary origin, never goes back).
#[cfg(target_os = "linux")]
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until the monotonic clock reads `deadline_ns` (returns at once if it has passed).
#[cfg(target_os = "linux")]
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remaining-time pointer may be null with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            break;
        }
    }
}

/// Sets the calling thread's timer slack to 1 µs, so that sleeps end close to their deadline
/// (the default slack is 50 µs). Returns whether the kernel accepted it.
#[cfg(target_os = "linux")]
pub fn tighten_timer_slack() -> bool {
    // SAFETY: PR_SET_TIMERSLACK takes an unsigned long and affects only the calling thread.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1000 as libc::c_ulong, 0, 0, 0) == 0 }
}

#[cfg(not(target_os = "linux"))]
mod fallback {
    use std::sync::OnceLock;
    use std::time::{Duration, Instant};
    static ORIGIN: OnceLock<Instant> = OnceLock::new();
    pub fn now_ns() -> u64 {
        ORIGIN.get_or_init(Instant::now).elapsed().as_nanos() as u64
    }
    pub fn sleep_until_ns(deadline_ns: u64) {
        let now = now_ns();
        if deadline_ns > now {
            std::thread::sleep(Duration::from_nanos(deadline_ns - now));
        }
    }
    pub fn tighten_timer_slack() -> bool {
        false
    }
}
#[cfg(not(target_os = "linux"))]
pub use fallback::{now_ns, sleep_until_ns, tighten_timer_slack};

/// A histogram of durations with 1 µs bins up to a bound, an overflow count and the exact
/// maximum. Allocates its bins once; [`Histogram::record`] never allocates.
#[derive(Debug, Clone)]
pub struct Histogram {
    bins: Vec<u32>,
    overflow: u64,
    count: u64,
    sum_ns: f64,
    max_ns: u64,
}

/// Percentiles of a [`Histogram`], µs.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TimingSummary {
    /// Median, µs (bin resolution 1 µs).
    pub p50: f64,
    /// 99th percentile, µs.
    pub p99: f64,
    /// Largest value, µs (exact).
    pub max: f64,
    /// Mean, µs.
    pub mean: f64,
    /// Number of values.
    pub count: u64,
}

impl Histogram {
    /// A histogram with 1 µs bins up to `bound_us` (values above count as overflow; the
    /// percentiles then report the bound).
    pub fn new(bound_us: usize) -> Self {
        Histogram {
            bins: vec![0; bound_us.max(1)],
            overflow: 0,
            count: 0,
            sum_ns: 0.0,
            max_ns: 0,
        }
    }

    /// Records one duration, ns.
    pub fn record(&mut self, ns: u64) {
        let bin = (ns / 1000) as usize;
        match self.bins.get_mut(bin) {
            Some(b) => *b = b.saturating_add(1),
            None => self.overflow += 1,
        }
        self.count += 1;
        self.sum_ns += ns as f64;
        self.max_ns = self.max_ns.max(ns);
    }

    /// Number of values recorded.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Largest value, ns.
    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    /// The `q`-quantile (0..=1), µs, at the upper edge of its bin (capped at the maximum).
    pub fn quantile_us(&self, q: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((q * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0u64;
        for (i, &n) in self.bins.iter().enumerate() {
            seen += n as u64;
            if seen >= rank {
                return ((i + 1) as f64).min(self.max_ns as f64 / 1000.0);
            }
        }
        self.max_ns as f64 / 1000.0
    }

    /// p50, p99, max and mean, µs.
    pub fn summary(&self) -> TimingSummary {
        TimingSummary {
            p50: self.quantile_us(0.5),
            p99: self.quantile_us(0.99),
            max: self.max_ns as f64 / 1000.0,
            mean: if self.count > 0 {
                self.sum_ns / self.count as f64 / 1000.0
            } else {
                0.0
            },
            count: self.count,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_is_monotonic_and_sleep_reaches_deadline() {
        let a = now_ns();
        sleep_until_ns(a + 2_000_000);
        let b = now_ns();
        assert!(b >= a + 2_000_000, "woke {} ns early", a + 2_000_000 - b);
        sleep_until_ns(a); // in the past: returns at once
        assert!(now_ns() - b < 1_000_000);
    }

    #[test]
    fn histogram_percentiles() {
        let mut h = Histogram::new(100);
        for us in 0..100u64 {
            h.record(us * 1000 + 500);
        }
        h.record(1_000_000); // overflow, 1 ms
        let s = h.summary();
        assert_eq!(s.count, 101);
        assert!((s.p50 - 51.0).abs() < 1e-9, "{s:?}");
        assert!((s.p99 - 100.0).abs() < 1e-9, "{s:?}");
        assert!((s.max - 1000.0).abs() < 1e-9);
    }
}
