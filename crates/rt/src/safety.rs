//! Safety limits of the real-time loop and the reasons a run stops.
//!
//! Every tick the loop checks, in this order: a user stop; the watchdogs (no valid sensor
//! record / robot feedback for `watchdog_ms`); the force and moment limits on the measured
//! wrench (magnitudes, sensor frame); tracking: the robot's fed-back rod tip within
//! `tracking_limit` of a command of the last `tracking_window` ([`Tracking`]); that the
//! virtual energy stays below the scenario's divergence bound; then, on the new command, that
//! it is finite and that the commanded rod tip stays within `workspace` metres of where it
//! started. Any of them stops the run: the robot is commanded to hold its last fed-back pose
//! if that pose is inside the workspace and within `hold_deviation` of a command of the
//! tracking window (else the last command, which passed every check; [`hold_target`]), sensor
//! streaming is stopped, the sample log is drained, and the [`StopKind`] goes to
//! `metrics.json` and the exit code.

use hilcontact_core::frames::RelativeMotion;
use hilcontact_core::world::TwoBodySystem;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RtError};

/// The limits, with units. Defaults: 500 N, 100 N·m, 50 ms, 0.1 m workspace, 20 mm hold
/// deviation, 20 mm/s and 20 mm retreat, 10 mm tracking over a 0.5 s window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyLimits {
    /// Largest measured force magnitude, N (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub force_limit: f64,
    /// Largest measured moment magnitude about the sensor origin, N·m (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub moment_limit: f64,
    /// Longest time without a valid sensor record or robot feedback, ms (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub watchdog_ms: f64,
    /// Largest distance of the commanded rod tip from its initial position, m (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub workspace: f64,
    /// Largest distance between the robot's fed-back rod tip and the last command's for a
    /// stop to hold the robot where it reports to be, m (> 0); beyond it (or outside the
    /// workspace) the feedback is not trusted and the last command, which passed every
    /// check, is held instead.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub hold_deviation: f64,
    /// Speed at which a force or moment stop backs the robot away to its last contact-free
    /// pose, m/s (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub retreat_speed: f64,
    /// Longest retreat of a force or moment stop, m (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub retreat_distance: f64,
    /// Largest distance between the robot's fed-back rod tip and the nearest commanded rod
    /// tip of the last `tracking_window` seconds, m (> 0): beyond it the feedback is frozen or
    /// wrong, or the robot does not follow ([`Tracking`]).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub tracking_limit: f64,
    /// How far back the commands are compared with the feedback, s (> 0): longer than the
    /// robot's response delay (feedback shows a command that old), shorter than the time
    /// the command needs to move `tracking_limit`.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub tracking_window: f64,
    /// The predictive limit: each new command is checked, before it is sent, against
    /// `force_limit` and `moment_limit` with the wrench the scenario's contact law gives at
    /// the commanded rod tip (what the hardware will feel once the robot is there, one loop
    /// delay later); the measured-wrench limits stay as a second line. `false` leaves only
    /// the measured line.
    pub predictive: bool,
    /// The units check at the first contact: the measured force must be within this factor
    /// (either way) of the scenario's contact law at the robot's fed-back penetration (> 1;
    /// [`UnitsCheck`]).
    #[schemars(extend("exclusiveMinimum" = 1.0))]
    pub units_check_factor: f64,
    /// Largest relative difference between the robot's cycle measured from its own time
    /// stamps (RSI IPOC, EGM time) and the configured one, at the start and during the run
    /// (> 0; [`CycleMeter`]).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub cycle_tolerance: f64,
}

impl Default for SafetyLimits {
    fn default() -> Self {
        SafetyLimits {
            force_limit: 500.0,
            moment_limit: 100.0,
            watchdog_ms: 50.0,
            workspace: 0.1,
            hold_deviation: 0.02,
            retreat_speed: 0.02,
            retreat_distance: 0.02,
            tracking_limit: 0.01,
            tracking_window: 0.5,
            predictive: true,
            units_check_factor: 3.0,
            cycle_tolerance: 0.1,
        }
    }
}

impl SafetyLimits {
    /// Checks that every limit is a positive number.
    pub fn validate(&self) -> Result<()> {
        for (key, v) in [
            ("force_limit", self.force_limit),
            ("moment_limit", self.moment_limit),
            ("watchdog_ms", self.watchdog_ms),
            ("workspace", self.workspace),
            ("hold_deviation", self.hold_deviation),
            ("retreat_speed", self.retreat_speed),
            ("retreat_distance", self.retreat_distance),
            ("tracking_limit", self.tracking_limit),
            ("tracking_window", self.tracking_window),
            ("cycle_tolerance", self.cycle_tolerance),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RtError::option(
                    key,
                    format!("must be a positive number, got {v}"),
                ));
            }
        }
        let f = self.units_check_factor;
        if !(f.is_finite() && f > 1.0) {
            return Err(RtError::option(
                "units_check_factor",
                format!("must be a number above 1, got {f}"),
            ));
        }
        Ok(())
    }

    /// The watchdog in ns.
    pub fn watchdog_ns(&self) -> u64 {
        (self.watchdog_ms * 1e6) as u64
    }
}

/// A stop of the real-time loop: the core's one vocabulary of how runs stop.
pub type StopEvent = hilcontact_core::stop::Stop;
pub use hilcontact_core::stop::StopKind;

/// Checks the wrench limits (magnitudes of the measured force N and moment N·m).
pub fn check_wrench(
    limits: &SafetyLimits,
    force: &Vector3<f64>,
    moment: &Vector3<f64>,
    time: f64,
) -> Option<StopEvent> {
    let (f, m) = (force.norm(), moment.norm());
    if f.is_nan() || f > limits.force_limit {
        return Some(StopEvent {
            kind: StopKind::ForceLimit,
            time,
            value: f,
            limit: limits.force_limit,
        });
    }
    if m.is_nan() || m > limits.moment_limit {
        return Some(StopEvent {
            kind: StopKind::MomentLimit,
            time,
            value: m,
            limit: limits.moment_limit,
        });
    }
    None
}

/// The wrench the hardware will feel once the robot has reached `command` (the relative
/// motion commanded, `t`): the scenario's contact law at the commanded rod tip and its
/// velocity, against the scenario's walls; returns `(|F|` N, `|M|` N·m about the sensor
/// origin`)`, as the facility model computes the physical wrench. Never allocates.
pub fn predicted_wrench(system: &TwoBodySystem, command: &RelativeMotion) -> (f64, f64) {
    let wrench = system.contact_at(command, 0.0).wrench;
    (wrench.force.norm(), wrench.moment.norm())
}

/// The predictive limit on a new command's predicted wrench (`force` N, `moment` N·m, from
/// [`predicted_wrench`]): a stop before the command is sent.
pub fn check_predicted(
    limits: &SafetyLimits,
    force: f64,
    moment: f64,
    time: f64,
) -> Option<StopEvent> {
    if !limits.predictive {
        return None;
    }
    if force.is_nan() || force > limits.force_limit {
        return Some(StopEvent {
            kind: StopKind::PredictedForceLimit,
            time,
            value: force,
            limit: limits.force_limit,
        });
    }
    if moment.is_nan() || moment > limits.moment_limit {
        return Some(StopEvent {
            kind: StopKind::PredictedMomentLimit,
            time,
            value: moment,
            limit: limits.moment_limit,
        });
    }
    None
}

/// The pose a stop holds the robot at (see the module doc): the fed-back pose `feedback` if
/// its rod tip (`rod`, servicer body frame, m) is inside the workspace around `start` (m, `t`)
/// and, once commands were sent, within `hold_deviation` of the nearest command of the
/// tracking window (`tracking`: the robot shows a command one delay old); else the last
/// command; `None` (send nothing) when neither is known and trusted.
pub fn hold_target(
    limits: &SafetyLimits,
    feedback: Option<RelativeMotion>,
    last_command: Option<RelativeMotion>,
    tracking: &Tracking,
    rod: &Vector3<f64>,
    start: &Vector3<f64>,
) -> Option<RelativeMotion> {
    let trusted = |pose: &RelativeMotion| {
        let tip = pose.point(rod);
        let inside = (tip - start).norm() <= limits.workspace;
        let tracking = tracking
            .deviation(&tip)
            .is_none_or(|d| d <= limits.hold_deviation);
        inside && tracking
    };
    match (feedback, last_command) {
        (Some(f), _) if trusted(&f) => Some(f),
        (_, Some(c)) => Some(c),
        _ => None,
    }
}

/// Checks a commanded rod tip (m, `t`) against the workspace around `start` (m, `t`).
pub fn check_workspace(
    limits: &SafetyLimits,
    tip: &Vector3<f64>,
    start: &Vector3<f64>,
    time: f64,
) -> Option<StopEvent> {
    if !tip.iter().all(|v| v.is_finite()) {
        return Some(StopEvent::plain(StopKind::NonFinite, time));
    }
    let distance = (tip - start).norm();
    (distance > limits.workspace).then_some(StopEvent {
        kind: StopKind::Workspace,
        time,
        value: distance,
        limit: limits.workspace,
    })
}

/// The tracking check: the commanded rod tips of the last `tracking_window` seconds in a
/// ring (allocated once), and the distance of a fed-back rod tip to the nearest of them. The
/// robot's feedback shows a command one response delay old, so the nearest command of the
/// window is the one the robot is following, whatever the delay (up to the window).
#[derive(Debug, Clone)]
pub struct Tracking {
    /// Commanded rod tips, m in `t` (a ring; `next` is the oldest once full).
    tips: Vec<Vector3<f64>>,
    next: usize,
    limit: f64,
}

impl Tracking {
    /// A check over `limits.tracking_window` at one command per `period` s.
    pub fn new(limits: &SafetyLimits, period: f64) -> Self {
        let n = (limits.tracking_window / period).ceil().max(1.0) as usize + 1;
        Tracking {
            tips: Vec::with_capacity(n),
            next: 0,
            limit: limits.tracking_limit,
        }
    }

    /// Remembers a commanded rod tip (m, `t`); forgets the oldest once the window is full.
    /// Never allocates.
    pub fn push(&mut self, tip: Vector3<f64>) {
        if self.tips.len() < self.tips.capacity() {
            self.tips.push(tip);
        } else {
            self.tips[self.next] = tip;
            self.next = (self.next + 1) % self.tips.len();
        }
    }

    /// Distance from the fed-back rod tip `fed_back` (m, `t`) to the nearest command of the
    /// window, m (None before the first command).
    pub fn deviation(&self, fed_back: &Vector3<f64>) -> Option<f64> {
        self.tips
            .iter()
            .map(|c| (c - fed_back).norm())
            .min_by(|a, b| a.total_cmp(b))
    }

    /// The stop when the fed-back rod tip is farther than `tracking_limit` from every command
    /// of the window (a non-finite tip is a stop too).
    pub fn check(&self, fed_back: &Vector3<f64>, time: f64) -> Option<StopEvent> {
        let d = self.deviation(fed_back)?;
        (d.is_nan() || d > self.limit).then_some(StopEvent {
            kind: StopKind::Tracking,
            time,
            value: d,
            limit: self.limit,
        })
    }
}

/// Steps of the robot's time stamps per measurement of its cycle ([`CycleMeter`]).
pub const CYCLE_WINDOW: u32 = 10;

/// The robot's cycle measured from its own time stamps (RSI: IPOC, ms; EGM: the feedback's
/// time), against the configured one (`configured`, s) within `tolerance` (relative).
///
/// A step of the robot's time shorter than `configured·(1 − tolerance)` is a mismatch at
/// once (the robot runs faster than configured); over each window of [`CYCLE_WINDOW`] steps
/// the shortest step is the measured cycle (lost messages only lengthen steps), and a
/// measured cycle longer than `configured·(1 + tolerance)` is a mismatch (the robot runs
/// slower). A step that is not positive (a stale or repeated time) is not counted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleMeter {
    /// The configured cycle, s (0: nothing checked).
    pub configured: f64,
    /// Relative tolerance.
    pub tolerance: f64,
    last: Option<f64>,
    window_min: f64,
    window_steps: u32,
    /// The shortest step of the last full window, s.
    pub measured: Option<f64>,
    /// The first mismatch: the measured cycle (or the too-short step), s.
    pub mismatch: Option<f64>,
}

impl CycleMeter {
    /// A meter of a robot configured at `configured` s (0 = unchecked), within `tolerance`.
    pub fn new(configured: f64, tolerance: f64) -> Self {
        CycleMeter {
            configured,
            tolerance,
            last: None,
            window_min: f64::INFINITY,
            window_steps: 0,
            measured: None,
            mismatch: None,
        }
    }

    /// Takes the robot's time stamp of an accepted message, s. Never allocates.
    pub fn push(&mut self, robot_time: f64) {
        let Some(last) = self.last.replace(robot_time) else {
            return;
        };
        let step = robot_time - last;
        if !(step > 0.0) || self.configured <= 0.0 {
            return;
        }
        if step < self.configured * (1.0 - self.tolerance) && self.mismatch.is_none() {
            self.measured = Some(step);
            self.mismatch = Some(step);
        }
        self.window_min = self.window_min.min(step);
        self.window_steps += 1;
        if self.window_steps >= CYCLE_WINDOW {
            let measured = self.window_min;
            self.measured = Some(measured);
            if measured > self.configured * (1.0 + self.tolerance) && self.mismatch.is_none() {
                self.mismatch = Some(measured);
            }
            self.window_min = f64::INFINITY;
            self.window_steps = 0;
        }
    }

    /// Forgets the time stamps (not the result): e.g. after a restart of the stream.
    pub fn restart(&mut self) {
        self.last = None;
        self.window_min = f64::INFINITY;
        self.window_steps = 0;
    }
}

/// The units and scale check of the first contact: the measured force against the force the
/// scenario's contact law gives at the robot's fed-back pose (what the hardware feels, if the
/// scenario's stiffness is the hardware's).
///
/// Both peaks are followed from the first tick the expected force passes `threshold`
/// (`0.1·force_limit`); the check decides once the contact's first peak is past on both
/// sides: the expected force has stayed below half its peak since it first fell there, and
/// the measured force, one loop delay later, has fallen below half its own peak too. A dip of
/// the expected force that does not last (a late or jumping robot feedback under load) is no
/// decision: the peaks go on being followed. A measured force that never comes down (a stuck
/// sensor) is decided `patience` after the expected dip, and a force or moment stop decides
/// at once with what was seen. The ratio of the peaks, measured / expected, must be within
/// `1/factor ..= factor`; else the run stops ([`StopKind::Units`]) with the likely unit named
/// ([`hilcontact_core::stop::likely_unit`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitsCheck {
    /// Allowed factor either way (> 1).
    pub factor: f64,
    /// Expected force from which the contact counts, N.
    pub threshold: f64,
    /// Longest wait, after the expected force's dip, for the measured force to come down, s
    /// (`limits.tracking_window`: longer than the loop's delay).
    pub patience: f64,
    peak_expected: f64,
    peak_measured: f64,
    /// When the expected force fell below half its peak and has stayed there since, s.
    dip_since: Option<f64>,
    /// The ratio of the peaks, once decided.
    pub ratio: Option<f64>,
}

impl UnitsCheck {
    /// A check with `limits.units_check_factor` from `0.1·limits.force_limit` on, waiting at
    /// most `limits.tracking_window` for the measured force's peak.
    pub fn new(limits: &SafetyLimits) -> Self {
        UnitsCheck {
            factor: limits.units_check_factor,
            threshold: 0.1 * limits.force_limit,
            patience: limits.tracking_window,
            peak_expected: 0.0,
            peak_measured: 0.0,
            dip_since: None,
            ratio: None,
        }
    }

    /// Takes one tick's expected (N, from the law at the fed-back pose) and measured force
    /// magnitudes at `time` (s); returns a stop when the check decides against the units.
    /// Never allocates.
    pub fn push(&mut self, expected: f64, measured: f64, time: f64) -> Option<StopEvent> {
        if self.ratio.is_some() {
            return None;
        }
        if self.peak_expected < self.threshold && expected < self.threshold {
            return None;
        }
        self.peak_expected = self.peak_expected.max(expected);
        self.peak_measured = self.peak_measured.max(measured);
        if expected >= 0.5 * self.peak_expected {
            // still in the first peak, or a dip that did not last
            self.dip_since = None;
            return None;
        }
        let since = *self.dip_since.get_or_insert(time);
        if measured < 0.5 * self.peak_measured || time - since >= self.patience {
            return self.decide(time);
        }
        None
    }

    /// Decides with what was seen (a force or moment stop before the first peak was past):
    /// the stop when the peaks disagree, None when they agree or no contact was seen.
    pub fn decide(&mut self, time: f64) -> Option<StopEvent> {
        if self.ratio.is_some() || self.peak_expected < self.threshold {
            return None;
        }
        let ratio = self.peak_measured / self.peak_expected;
        self.ratio = Some(ratio);
        (!(ratio >= 1.0 / self.factor && ratio <= self.factor)).then_some(StopEvent {
            kind: StopKind::Units,
            time,
            value: ratio,
            limit: self.factor,
        })
    }

    /// The expected and measured peaks so far, N.
    pub fn peaks(&self) -> (f64, f64) {
        (self.peak_expected, self.peak_measured)
    }
}

/// What the safety functions saw over a run (`metrics.json` `realtime.safety`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SafetyReport {
    /// Largest predicted force of the commands sent (the law at the commanded rod tip), N.
    pub predicted_peak_force: f64,
    /// Largest predicted moment of the commands sent, N·m.
    pub predicted_peak_moment: f64,
    /// Largest measured force magnitude, N.
    pub measured_peak_force: f64,
    /// Which line of the force and moment limits tripped: `"predicted"` (the command was
    /// not sent), `"measured"`, or None.
    pub limit_line: Option<&'static str>,
    /// The robot's cycle measured from its time stamps, s (None: not enough of them).
    pub robot_cycle: Option<f64>,
    /// The configured robot cycle, s.
    pub robot_cycle_configured: f64,
    /// Virtual steps per robot cycle (robot pacing; 1 on the clock).
    pub steps_per_cycle: u64,
    /// The units check's ratio, measured / expected peak force at the first contact (None:
    /// no contact reached the check's threshold).
    pub units_ratio: Option<f64>,
    /// The units check's expected peak (the law at the fed-back pose), N.
    pub units_expected_peak: f64,
    /// The units check's measured peak, N.
    pub units_measured_peak: f64,
    /// Whether the robot's session ended the way its program expects (KUKA RSI: the end
    /// signal answered until the controller stopped sending); None: no end of session in the
    /// protocol, or no pose to hold.
    pub session_ended_cleanly: Option<bool>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use hilcontact_core::stop::Status;

    #[test]
    fn limits_trip_above_and_on_nan() {
        let l = SafetyLimits::default();
        assert!(
            check_wrench(&l, &Vector3::new(300.0, 300.0, 0.0), &Vector3::zeros(), 0.0).is_none()
        );
        let e = check_wrench(&l, &Vector3::new(400.0, 400.0, 0.0), &Vector3::zeros(), 1.5).unwrap();
        assert_eq!(e.kind, StopKind::ForceLimit);
        assert!((e.value - 565.685).abs() < 1e-3);
        assert!(e.reason().unwrap().contains("565.7 N > 500.0 N"));
        assert_eq!(
            check_wrench(
                &l,
                &Vector3::new(f64::NAN, 0.0, 0.0),
                &Vector3::zeros(),
                0.0
            )
            .unwrap()
            .kind,
            StopKind::ForceLimit
        );
        assert_eq!(
            check_wrench(&l, &Vector3::zeros(), &Vector3::new(0.0, 101.0, 0.0), 0.0)
                .unwrap()
                .kind,
            StopKind::MomentLimit
        );
        let start = Vector3::new(0.005, 0.0, 0.0);
        assert!(check_workspace(&l, &Vector3::new(0.05, 0.0, 0.0), &start, 0.0).is_none());
        assert_eq!(
            check_workspace(&l, &Vector3::new(0.2, 0.0, 0.0), &start, 0.0)
                .unwrap()
                .kind,
            StopKind::Workspace
        );
        assert_eq!(
            check_workspace(&l, &Vector3::new(f64::INFINITY, 0.0, 0.0), &start, 0.0)
                .unwrap()
                .kind,
            StopKind::NonFinite
        );
    }

    #[test]
    fn codes_and_exit_codes() {
        for k in [
            StopKind::Completed,
            StopKind::User,
            StopKind::ForceLimit,
            StopKind::Diverged,
            StopKind::RobotWatchdog,
            StopKind::Tracking,
            StopKind::NonFinite,
        ] {
            assert_eq!(StopKind::from_code(k.code()), Some(k));
        }
        assert_eq!(StopKind::from_code(0), None);
        assert_eq!(StopKind::Completed.exit_code(), 0);
        assert_eq!(StopKind::User.exit_code(), 130);
        assert_eq!(StopKind::SensorWatchdog.exit_code(), 3);
        assert_eq!(StopKind::ForceLimit.status(), Status::Stopped);
    }

    #[test]
    fn invalid_limits_are_errors() {
        assert!(SafetyLimits {
            force_limit: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(SafetyLimits {
            watchdog_ms: f64::NAN,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(SafetyLimits::default().validate().is_ok());
    }

    #[test]
    fn tracking_allows_the_delay_and_catches_frozen_feedback() {
        let limits = SafetyLimits::default(); // 10 mm over 0.5 s
        let period = 0.004;
        let mut tracking = Tracking::new(&limits, period);
        assert!(tracking.check(&Vector3::zeros(), 0.0).is_none()); // no command yet
        let speed = 0.05; // m/s, along x
        let delay = 0.12; // s: a slow robot follows 6 mm behind
        let mut frozen_stop = None;
        for k in 0..500 {
            let t = k as f64 * period;
            tracking.push(Vector3::new(speed * t, 0.0, 0.0));
            let following = Vector3::new(speed * (t - delay).max(0.0), 0.0, 0.0);
            assert!(
                tracking.check(&following, t).is_none(),
                "a robot {delay} s behind is tracking"
            );
            if frozen_stop.is_none() {
                frozen_stop = tracking.check(&Vector3::zeros(), t);
            }
        }
        // frozen at the start: stopped once the window's oldest command is 10 mm away,
        // i.e. 0.2 s + 0.5 s after the start
        let stop = frozen_stop.expect("frozen feedback is a tracking stop");
        assert_eq!(stop.kind, StopKind::Tracking);
        assert!((stop.time - 0.7).abs() < 0.01, "stopped at {}", stop.time);
        assert!(stop.reason().unwrap().contains("tracking_limit"));
        // a feedback 300 mm off is a stop at once, and NaN too
        assert!(tracking.check(&Vector3::new(0.3, 0.3, 0.0), 2.0).is_some());
        assert!(tracking
            .check(&Vector3::new(f64::NAN, 0.0, 0.0), 2.0)
            .is_some());
    }

    #[test]
    fn a_stop_holds_the_feedback_only_when_it_is_plausible() {
        use nalgebra::UnitQuaternion;
        let l = SafetyLimits::default();
        let rod = Vector3::new(1.0, 0.0, 0.0);
        let at = |x: f64| RelativeMotion {
            position: Vector3::new(x, 0.0, 0.0),
            orientation: UnitQuaternion::identity(),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        };
        let start = at(-0.995).point(&rod);
        let period = 0.004;
        let commanded = |x: f64| {
            let mut t = Tracking::new(&l, period);
            t.push(at(x).point(&rod));
            t
        };
        // a robot 15 mm behind the last command but on a command of the window (a slow
        // robot)
        let mut window = Tracking::new(&l, period);
        for x in [-0.990, -0.985, -0.980, -0.975] {
            window.push(at(x).point(&rod));
        }
        let none = Tracking::new(&l, period);
        // (feedback x, last command x, tracking window, the x held or None), with why
        let cases = [
            // tracking: the robot 5 mm behind the command is held where it is
            (Some(-0.990), Some(-0.985), &commanded(-0.985), Some(-0.990)),
            // a feedback 300 mm off (inside a 100 m plausibility bound, outside the
            // workspace): the last command is held, not the bogus pose
            (Some(-0.695), Some(-0.985), &commanded(-0.985), Some(-0.985)),
            // the slow robot on a command of the window: trusted
            (Some(-0.990), Some(-0.975), &window, Some(-0.990)),
            // inside the workspace but 50 mm from the command: the command too
            (Some(-0.935), Some(-0.985), &commanded(-0.985), Some(-0.985)),
            // before any command (a refused start): the robot's own pose if inside the
            // workspace, else nothing at all
            (Some(-0.945), None, &none, Some(-0.945)),
            (Some(0.4), None, &none, None),
            (None, None, &none, None),
        ];
        for (feedback, last, tracking, expected) in cases {
            let held = hold_target(&l, feedback.map(at), last.map(at), tracking, &rod, &start);
            assert_eq!(
                held.map(|h| h.position.x),
                expected,
                "feedback {feedback:?}, last command {last:?}"
            );
        }
    }

    #[test]
    fn the_cycle_meter_finds_both_mismatches_and_tolerates_lost_messages() {
        // a 4 ms robot with every third message lost: measured 4 ms, no mismatch
        let mut m = CycleMeter::new(0.004, 0.1);
        for i in 0..100u32 {
            if i % 3 != 2 {
                m.push(f64::from(i) * 0.004);
            }
        }
        assert!((m.measured.unwrap() - 0.004).abs() < 1e-12 && m.mismatch.is_none());
        // a 12 ms robot configured at 4 ms: the window's shortest step is 12 ms
        let mut m = CycleMeter::new(0.004, 0.1);
        for i in 0..(CYCLE_WINDOW + 1) {
            assert!(m.mismatch.is_none());
            m.push(f64::from(i) * 0.012);
        }
        assert!((m.mismatch.unwrap() - 0.012).abs() < 1e-12);
        // a 4 ms robot configured at 12 ms: the first step
        let mut m = CycleMeter::new(0.012, 0.1);
        m.push(1.000);
        m.push(1.004);
        assert!((m.mismatch.unwrap() - 0.004).abs() < 1e-12);
        // repeated or older stamps are not steps
        let mut m = CycleMeter::new(0.004, 0.1);
        for t in [1.0, 1.0, 0.9, 1.004] {
            m.push(t);
        }
        assert!(m.mismatch.is_none());
    }

    #[test]
    fn the_units_check_takes_the_peaks_and_names_the_unit() {
        let limits = SafetyLimits::default(); // threshold 50 N, factor 3
                                              // a half sine of 400 N expected, measured 3 ms late in `scale` units
        for (scale, stops, unit) in [
            (1.0, false, ""),
            (9.80665, true, "kgf"),
            (4.448222, true, "lbf"),
            (1e-3, true, "mN"),
            (2.0, false, ""),
        ] {
            let mut check = UnitsCheck::new(&limits);
            let f = |t: f64| (400.0 * (t * std::f64::consts::PI / 0.25).sin()).max(0.0);
            let mut stop = None;
            for k in 0..400 {
                let t = k as f64 * 0.001;
                if let Some(s) = check.push(f(t), f(t - 0.003) / scale, t) {
                    stop = Some(s);
                    break;
                }
            }
            let ratio = check.ratio.expect("decided");
            assert!((ratio * scale - 1.0).abs() < 0.01, "{scale}: {ratio}");
            assert_eq!(stop.is_some(), stops, "{scale}");
            if let Some(s) = stop {
                assert_eq!(s.kind, StopKind::Units);
                assert!(s.reason().unwrap().contains(unit), "{:?}", s.reason());
            }
        }
        // no contact above the threshold: nothing decided, nothing stopped
        let mut check = UnitsCheck::new(&limits);
        assert!(check.push(40.0, 4.0, 0.0).is_none() && check.decide(0.0).is_none());
        assert!(check.ratio.is_none());
    }

    #[test]
    fn an_early_dip_of_the_expected_force_is_no_decision() {
        // A 180 N half sine expected; the sensor (in N) lags 10 ms. At 61 N on the rise the
        // robot's feedback comes late for 3 ticks and the expected force dips to 20 N (the
        // case a busy machine produced: ratio 0.344 from deciding on the dip).
        let limits = SafetyLimits::default();
        let f = |t: f64| (180.0 * (t * std::f64::consts::PI / 0.25).sin()).max(0.0);
        let mut check = UnitsCheck::new(&limits);
        let rise = (61.0f64 / 180.0).asin() * 0.25 / std::f64::consts::PI;
        let mut decided_at = None;
        for k in 0..600 {
            let t = k as f64 * 0.001;
            let glitch = t >= rise && t < rise + 0.003;
            let expected = if glitch { 20.0 } else { f(t) };
            assert!(check.push(expected, f(t - 0.010), t).is_none());
            if check.ratio.is_some() && decided_at.is_none() {
                decided_at = Some(t);
            }
        }
        let ratio = check.ratio.expect("decided");
        assert!((ratio - 1.0).abs() < 0.01, "{ratio}");
        // decided once the measured force (peak at 0.135 s) fell below half: 0.2083 s + 10 ms
        let t = decided_at.unwrap();
        assert!(t > 0.218 && t < 0.221, "{t}");
    }

    #[test]
    fn a_measured_force_that_never_comes_down_is_decided_after_the_patience() {
        let limits = SafetyLimits::default();
        // one contact, then nothing
        let f = |t: f64| {
            if t < 0.25 {
                (400.0 * (t * std::f64::consts::PI / 0.25).sin()).max(0.0)
            } else {
                0.0
            }
        };
        let mut check = UnitsCheck::new(&limits);
        let mut stop = None;
        for k in 0..2000 {
            let t = k as f64 * 0.001;
            // a stuck sensor: 41 N from the contact's start on (400 N in kgf, frozen)
            let measured = if f(t) > 0.0 || t > 0.1 { 40.8 } else { 0.0 };
            if let Some(s) = check.push(f(t), measured, t) {
                stop = Some((s, t));
                break;
            }
        }
        let (s, t) = stop.expect("a stop");
        assert_eq!(s.kind, StopKind::Units);
        // the expected force fell below 200 N at 0.2083 s; decided one patience later
        let dip = 0.25 - (0.5f64).asin() * 0.25 / std::f64::consts::PI;
        assert!((t - (dip + limits.tracking_window)).abs() < 0.0025, "{t}");
        assert!(s.reason().unwrap().contains("kgf"), "{:?}", s.reason());
    }

    #[test]
    fn the_predicted_limit_trips_above_the_limit_only_when_on() {
        let l = SafetyLimits::default();
        assert!(check_predicted(&l, 499.0, 10.0, 0.0).is_none());
        assert_eq!(
            check_predicted(&l, 501.0, 10.0, 0.0).unwrap().kind,
            StopKind::PredictedForceLimit
        );
        assert_eq!(
            check_predicted(&l, 10.0, 101.0, 0.0).unwrap().kind,
            StopKind::PredictedMomentLimit
        );
        let off = SafetyLimits {
            predictive: false,
            ..l
        };
        assert!(check_predicted(&off, 1e6, 1e6, 0.0).is_none());
    }
}
