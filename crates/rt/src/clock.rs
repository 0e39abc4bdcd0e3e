//! Monotonic clock, absolute sleeps and latency histograms for the real-time threads.
//!
//! On Linux the clock is `CLOCK_MONOTONIC` and sleeps are `clock_nanosleep(TIMER_ABSTIME)`,
//! so a late wake-up never shifts the following deadlines; the thread's timer slack is cut to
//! 1 µs ([`tighten_timer_slack`]). Elsewhere `std::time::Instant` and `thread::sleep` stand in.
//!
//! [`request_realtime`] asks the OS, for the calling thread, for `SCHED_FIFO`, locked memory and
//! a CPU of its own ([`SchedulingOptions`]), and reports what it got ([`SchedulingReport`]); a
//! refusal is reported, never an error (docs/realtime.md, "Real-time scheduling", says how to
//! grant it).

use serde::{Deserialize, Serialize};

use crate::error::{Result, RtError};

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

/// Real-time scheduling of the loop thread (`[scheduling]`; CLI `--rt-priority`,
/// `--no-lock-memory`, `--cpu`). What the OS refuses is reported in `metrics.json`
/// (`realtime.scheduling`), and the run goes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SchedulingOptions {
    /// `SCHED_FIFO` priority of the loop thread, 1–99 (99 highest); 0 = do not ask, normal
    /// scheduling (`SCHED_OTHER`).
    #[schemars(range(max = 99))]
    pub priority: u8,
    /// Lock the process's memory (`mlockall(MCL_CURRENT | MCL_FUTURE)`), so that no page fault
    /// stalls a tick.
    pub lock_memory: bool,
    /// Pin the loop thread to this CPU (0-based index, below the number of CPUs); None = any
    /// CPU.
    pub cpu: Option<usize>,
}

impl Default for SchedulingOptions {
    fn default() -> Self {
        SchedulingOptions {
            priority: 80,
            lock_memory: true,
            cpu: None,
        }
    }
}

impl SchedulingOptions {
    /// Checks the priority (≤ 99) and the CPU (below [`cpu_count`]).
    pub fn validate(&self) -> Result<()> {
        if self.priority > 99 {
            return Err(RtError::option(
                "scheduling.priority",
                format!(
                    "must be a SCHED_FIFO priority 1-99, or 0 for normal scheduling, got {}",
                    self.priority
                ),
            ));
        }
        if let Some(cpu) = self.cpu {
            let n = cpu_count();
            if cpu >= n {
                return Err(RtError::option(
                    "scheduling.cpu",
                    format!(
                        "CPU {cpu} does not exist: this machine has {n} CPUs (0 to {})",
                        n - 1
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// What [`request_realtime`] asked for and got, as `metrics.json` `realtime.scheduling`
/// reports it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SchedulingReport {
    /// The thread's scheduling policy once asked: `"fifo"` (`SCHED_FIFO`, granted or inherited,
    /// e.g. from `chrt -f`) or `"other"` (normal scheduling; `"rr"` for `SCHED_RR`).
    pub policy: &'static str,
    /// The thread's real-time priority once asked, 1–99 (0 under normal scheduling).
    pub priority: u8,
    /// Whether the requested `SCHED_FIFO` priority was granted (false when none was asked).
    pub fifo_granted: bool,
    /// Whether the process's memory is locked (`mlockall` granted; false when not asked).
    pub memory_locked: bool,
    /// The CPU the thread was asked to run on (None: not asked).
    pub cpu: Option<usize>,
    /// Whether the thread is pinned to that CPU.
    pub pinned: bool,
    /// One text per refusal: what was asked, the OS error and how to grant it.
    pub refused: Vec<String>,
}

impl SchedulingReport {
    /// Nothing asked, nothing granted: normal scheduling.
    pub fn normal() -> Self {
        SchedulingReport {
            policy: "other",
            priority: 0,
            fifo_granted: false,
            memory_locked: false,
            cpu: None,
            pinned: false,
            refused: Vec::new(),
        }
    }
}

/// Number of CPUs of the machine (configured, online or not; at least 1).
#[cfg(target_os = "linux")]
pub fn cpu_count() -> usize {
    // SAFETY: sysconf has no preconditions.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_CONF) };
    if n > 0 {
        n as usize
    } else {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    }
}

/// The symbolic name of an errno value (`EPERM`), or `errno N`.
#[cfg(target_os = "linux")]
fn errno_name(errno: i32) -> String {
    let name = match errno {
        libc::EPERM => "EPERM",
        libc::EINVAL => "EINVAL",
        libc::ENOMEM => "ENOMEM",
        libc::EAGAIN => "EAGAIN",
        libc::ESRCH => "ESRCH",
        libc::EFAULT => "EFAULT",
        libc::ENOSYS => "ENOSYS",
        _ => return format!("errno {errno}"),
    };
    name.to_string()
}

/// The text of one refusal: `what`, the OS error `errno` (name and description) and `hint`.
#[cfg(target_os = "linux")]
fn refusal(what: &str, errno: i32, hint: &str) -> String {
    let description = std::io::Error::from_raw_os_error(errno).to_string();
    // "Operation not permitted (os error 1)" -> "Operation not permitted"
    let description = description
        .split(" (os error")
        .next()
        .unwrap_or(&description);
    let mut text = format!("{what}: {} ({description})", errno_name(errno));
    if !hint.is_empty() {
        text.push_str(": ");
        text.push_str(hint);
    }
    text
}

/// Where docs/realtime.md says how to grant each request (the end of every refusal's hint).
#[cfg(target_os = "linux")]
const SEE_DOCS: &str = "see docs/realtime.md";

/// Asks the OS, for the calling thread, for what `options` request, in this order: locked
/// memory (`mlockall(MCL_CURRENT | MCL_FUTURE)`, process-wide and kept after the run), the CPU
/// (`sched_setaffinity`), then `SCHED_FIFO` at `options.priority` (`pthread_setschedparam`),
/// and reports what was granted. Call it on the loop thread before the loop (it allocates);
/// threads it starts later inherit the policy and the CPU.
///
/// Memory is not locked when the memlock limit (`ulimit -l`) is finite and the process lacks
/// `CAP_IPC_LOCK`: with `MCL_FUTURE`, every later allocation beyond that limit would fail.
#[cfg(target_os = "linux")]
pub fn request_realtime(options: &SchedulingOptions) -> SchedulingReport {
    let mut report = SchedulingReport::normal();
    report.cpu = options.cpu;
    if options.lock_memory {
        match lock_memory() {
            Ok(()) => report.memory_locked = true,
            Err(text) => report.refused.push(text),
        }
    }
    if let Some(cpu) = options.cpu {
        match pin_to_cpu(cpu) {
            Ok(()) => report.pinned = true,
            Err(text) => report.refused.push(text),
        }
    }
    if options.priority > 0 {
        match set_fifo(options.priority) {
            Ok(()) => report.fifo_granted = true,
            Err(text) => report.refused.push(text),
        }
    }
    let (policy, priority) = current_policy();
    report.policy = policy;
    report.priority = priority;
    report
}

/// `mlockall(MCL_CURRENT | MCL_FUTURE)`, unless the memlock limit would make later allocations
/// fail (above); the refusal's text otherwise.
#[cfg(target_os = "linux")]
fn lock_memory() -> std::result::Result<(), String> {
    let what = "memory lock (mlockall)";
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `limit` is a valid, writable rlimit.
    let have_limit = unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut limit) } == 0;
    if have_limit && limit.rlim_cur != libc::RLIM_INFINITY && !has_capability(CAP_IPC_LOCK) {
        return Err(format!(
            "{what}: not asked: the memlock limit is {} KiB (ulimit -l) and the process lacks CAP_IPC_LOCK, so every allocation beyond it would fail once locked: set memlock unlimited, {SEE_DOCS}",
            limit.rlim_cur / 1024
        ));
    }
    // SAFETY: mlockall takes flags only.
    if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
        return Ok(());
    }
    let errno = std::io::Error::last_os_error().raw_os_error().unwrap_or(0);
    let hint = match errno {
        libc::EPERM => format!("needs CAP_IPC_LOCK or memlock unlimited: {SEE_DOCS}"),
        libc::ENOMEM | libc::EAGAIN => {
            format!("the process is larger than the memlock limit (ulimit -l): set memlock unlimited, {SEE_DOCS}")
        }
        _ => SEE_DOCS.to_string(),
    };
    Err(refusal(what, errno, &hint))
}

/// `CAP_IPC_LOCK`'s bit in the capability sets.
#[cfg(target_os = "linux")]
const CAP_IPC_LOCK: u32 = 14;

/// Whether the process's effective capabilities (`/proc/self/status` `CapEff`) hold `bit`.
#[cfg(target_os = "linux")]
fn has_capability(bit: u32) -> bool {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return false;
    };
    status
        .lines()
        .find_map(|line| line.strip_prefix("CapEff:"))
        .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        .is_some_and(|caps| caps & (1u64 << bit) != 0)
}

/// Pins the calling thread to `cpu` (`sched_setaffinity`); the refusal's text otherwise.
#[cfg(target_os = "linux")]
fn pin_to_cpu(cpu: usize) -> std::result::Result<(), String> {
    let what = format!("CPU pinning to CPU {cpu} (sched_setaffinity)");
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(refusal(&what, libc::EINVAL, "beyond CPU_SETSIZE"));
    }
    // SAFETY: an all-zero cpu_set_t is the empty set; CPU_SET writes inside it (cpu checked
    // against CPU_SETSIZE); pid 0 is the calling thread.
    let r = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if r == 0 {
        return Ok(());
    }
    let errno = std::io::Error::last_os_error().raw_os_error().unwrap_or(0);
    let hint = match errno {
        libc::EINVAL => format!(
            "the CPU is offline or outside the CPUs this process may use (taskset, cgroup cpuset): {SEE_DOCS}"
        ),
        _ => SEE_DOCS.to_string(),
    };
    Err(refusal(&what, errno, &hint))
}

/// Puts the calling thread under `SCHED_FIFO` at `priority` (`pthread_setschedparam`); the
/// refusal's text otherwise.
#[cfg(target_os = "linux")]
fn set_fifo(priority: u8) -> std::result::Result<(), String> {
    let param = libc::sched_param {
        sched_priority: priority as libc::c_int,
    };
    // SAFETY: pthread_self() is the calling thread; `param` is a valid sched_param.
    let errno =
        unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if errno == 0 {
        return Ok(());
    }
    let hint = match errno {
        libc::EPERM => format!("needs CAP_SYS_NICE or an rtprio limit: {SEE_DOCS}"),
        _ => SEE_DOCS.to_string(),
    };
    Err(refusal(
        &format!("SCHED_FIFO priority {priority}"),
        errno,
        &hint,
    ))
}

/// The calling thread's policy (`"fifo"`, `"rr"` or `"other"`) and real-time priority (0 under
/// normal scheduling).
#[cfg(target_os = "linux")]
fn current_policy() -> (&'static str, u8) {
    let mut policy: libc::c_int = 0;
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pthread_self() is the calling thread; both pointers are valid and writable.
    let r = unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut policy, &mut param) };
    if r != 0 {
        return ("other", 0);
    }
    let priority = param.sched_priority.clamp(0, 99) as u8;
    match policy {
        libc::SCHED_FIFO => ("fifo", priority),
        libc::SCHED_RR => ("rr", priority),
        _ => ("other", 0),
    }
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
    pub fn cpu_count() -> usize {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    }
    pub fn request_realtime(options: &super::SchedulingOptions) -> super::SchedulingReport {
        let mut report = super::SchedulingReport::normal();
        report.cpu = options.cpu;
        if options.priority > 0 || options.lock_memory || options.cpu.is_some() {
            report
                .refused
                .push("real-time scheduling (SCHED_FIFO, mlockall, CPU pinning) is only requested on Linux".to_string());
        }
        report
    }
}
#[cfg(not(target_os = "linux"))]
pub use fallback::{cpu_count, now_ns, request_realtime, sleep_until_ns, tighten_timer_slack};

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

    #[test]
    fn scheduling_options_are_checked() {
        assert!(SchedulingOptions::default().validate().is_ok());
        let ok = SchedulingOptions {
            priority: 99,
            lock_memory: false,
            cpu: Some(0),
        };
        assert!(ok.validate().is_ok());
        let error = SchedulingOptions {
            priority: 100,
            ..ok
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(
            error.starts_with("scheduling.priority:") && error.contains("100"),
            "{error}"
        );
        let error = SchedulingOptions {
            cpu: Some(9999),
            ..ok
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(
            error.starts_with("scheduling.cpu:") && error.contains("9999"),
            "{error}"
        );
        // unknown keys are refused, left-out keys take their defaults
        let parsed: SchedulingOptions = serde_json::from_str(r#"{"priority": 0}"#).unwrap();
        assert_eq!(
            (parsed.priority, parsed.lock_memory, parsed.cpu),
            (0, true, None)
        );
        assert!(serde_json::from_str::<SchedulingOptions>(r#"{"prio": 1}"#).is_err());
    }

    /// Granted or refused depends on the machine: the report must agree with itself.
    #[test]
    fn the_report_says_what_was_granted_or_why_not() {
        let asked = SchedulingOptions {
            priority: 10,
            lock_memory: false,
            cpu: Some(0),
        };
        let report = std::thread::spawn(move || request_realtime(&asked))
            .join()
            .unwrap();
        assert_eq!(report.cpu, Some(0));
        assert!(!report.memory_locked);
        if report.fifo_granted {
            assert_eq!((report.policy, report.priority), ("fifo", 10), "{report:?}");
        } else {
            assert!(
                report
                    .refused
                    .iter()
                    .any(|t| t.starts_with("SCHED_FIFO priority 10")),
                "{report:?}"
            );
        }
        assert_eq!(
            report.pinned,
            !report.refused.iter().any(|t| t.starts_with("CPU pinning")),
            "{report:?}"
        );
        assert_eq!(
            report.refused.len(),
            usize::from(!report.fifo_granted) + usize::from(!report.pinned),
            "{report:?}"
        );

        // nothing asked: nothing granted, nothing refused, the policy the thread inherited
        let nothing = SchedulingOptions {
            priority: 0,
            lock_memory: false,
            cpu: None,
        };
        let (inherited, report) = std::thread::spawn(move || {
            let inherited = current_policy();
            (inherited, request_realtime(&nothing))
        })
        .join()
        .unwrap();
        assert!(report.refused.is_empty() && !report.fifo_granted && !report.pinned);
        assert_eq!((report.policy, report.priority), inherited);
    }

    #[test]
    fn a_refusal_names_the_error_and_how_to_grant_it() {
        let text = refusal(
            "SCHED_FIFO priority 80",
            libc::EPERM,
            "needs CAP_SYS_NICE or an rtprio limit: see docs/realtime.md",
        );
        assert_eq!(
            text,
            "SCHED_FIFO priority 80: EPERM (Operation not permitted): needs CAP_SYS_NICE or an rtprio limit: see docs/realtime.md"
        );
    }

    /// Without privilege (not root, no CAP_SYS_NICE) and an rtprio limit of 0, SCHED_FIFO is
    /// refused with EPERM and the run goes on at normal priority. Skipped when privileged (the
    /// limit does not bind then).
    #[test]
    fn fifo_is_refused_under_an_rtprio_limit_of_zero() {
        const CAP_SYS_NICE: u32 = 23;
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } == 0 || has_capability(CAP_SYS_NICE) {
            eprintln!("skipped: privileged, the rtprio limit does not apply");
            return;
        }
        let mut limit = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: valid rlimit pointers; only the soft limit is lowered, then restored.
        unsafe {
            assert_eq!(libc::getrlimit(libc::RLIMIT_RTPRIO, &mut limit), 0);
            let zero = libc::rlimit {
                rlim_cur: 0,
                rlim_max: limit.rlim_max,
            };
            assert_eq!(libc::setrlimit(libc::RLIMIT_RTPRIO, &zero), 0);
        }
        let asked = SchedulingOptions {
            priority: 80,
            lock_memory: false,
            cpu: None,
        };
        let report = std::thread::spawn(move || request_realtime(&asked))
            .join()
            .unwrap();
        // SAFETY: as above.
        unsafe { libc::setrlimit(libc::RLIMIT_RTPRIO, &limit) };
        assert!(
            !report.fifo_granted && report.policy == "other",
            "{report:?}"
        );
        assert_eq!(
            report.refused,
            vec!["SCHED_FIFO priority 80: EPERM (Operation not permitted): needs CAP_SYS_NICE or an rtprio limit: see docs/realtime.md".to_string()]
        );
    }
}
