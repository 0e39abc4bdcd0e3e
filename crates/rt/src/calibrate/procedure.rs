//! The calibration procedure as a tick-by-tick state machine: what to command next from what
//! was measured. It names no device and no clock: [`super::simulate`] steps it against the
//! facility model, a real-time loop against the device links.
//!
//! 1. **Settle** at the start pose, then **excite**: a three-sine motion of the rod tip in free
//!    space along the direction farthest from every wall's normal; the sensor's bias and noise
//!    are measured there, and the robot's delay and servo lag from command against feedback
//!    ([`fit_robot_response`]).
//! 2. For each wall of the scenario, a grid of probes around the point where the scenario's
//!    ideal run first touches it (the point nearest the start tip if it never does): move to a point outside the wall (the nominal plane plus `standoff` for the
//!    first probe, the plane predicted by the probes so far plus `margin` for the others),
//!    approach along the normal at a speed whose overshoot over the loop's delay stays below a
//!    quarter of `press_force`, press to `press_force`, dwell and oscillate outwards from the
//!    pressed point (`dwell_cycles` at `dwell_frequency`: fast against the robot's slow
//!    repeatability drift, so that stiffness and damping are observable), retreat. The law and
//!    each probe's contact point are fitted from the samples of the dwell and oscillation. A wall not touched within `search_depth` beyond its
//!    nominal plane stops the procedure with a message naming it.
//! 3. Each wall's probes are fitted ([`fit_surface`]); then the next wall.
//!
//! Every command stays within `workspace` of the start tip; a measured force above
//! `abort_force` (or a failed fit) ends the procedure: the tip retreats out of contact along the
//! current wall's normal, then holds.

use nalgebra::{UnitQuaternion, Vector3};

use hilcontact_core::calibration::{
    fit_plane, fit_robot_response, fit_surface, smooth, FitError, FitForm, LawFit, ProbeSample,
    RobotResponse, SurfaceFit,
};
use hilcontact_core::contact::{ContactModel, Wall};
use hilcontact_core::facility::Measurement;
use hilcontact_core::frames::RelativeMotion;
use hilcontact_core::Plan;

use super::options::CalibrateOptions;

/// Seconds at rest before the excitation.
const SETTLE: f64 = 0.3;
/// Half-width of the quadratic smoothing of the reported positions, s (12 samples at a 1 ms
/// loop, 3 at RSI's 4 ms): a time, so that the smoothing keeps the dwell's oscillation
/// (`ω·SMOOTHING = 0.6` at 8 Hz: 0.4 % off) at any loop period.
const SMOOTHING: f64 = 0.012;
/// Capacity of the undrained progress events (one comes per tick at most, drained each tick).
const EVENTS: usize = 4;

/// What one tick of the procedure asks.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Command this relative motion (`t` frame) for the next tick.
    Command(RelativeMotion),
    /// The procedure is over (finished or stopped): hold the last command.
    Done,
}

/// A progress event, surface by surface: a fixed-size message (no heap), so that the
/// real-time loop hands it on without allocating and its line is formatted elsewhere
/// ([`super::describe`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// The robot's response was measured, with the sensor noise (N, std per axis) and the
    /// detection force (N) measured with it.
    Robot {
        /// The robot's delay and servo lag.
        response: RobotResponse,
        /// Sensor noise, N (std per axis).
        noise: f64,
        /// The force that counts as contact, N.
        detect_force: f64,
    },
    /// Wall `index` (the scenario's order) was fitted, in `spent` s.
    Wall {
        /// The wall's index in the scenario.
        index: usize,
        /// The fit's numbers.
        fit: WallSummary,
        /// Time spent on the wall, s.
        spent: f64,
    },
}

/// A wall's fit without its contact points (a fixed-size progress message).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallSummary {
    /// Probes fitted.
    pub probes: usize,
    /// A point of the plane, `t`, m.
    pub point: Vector3<f64>,
    /// Unit normal into free space, `t`.
    pub normal: Vector3<f64>,
    /// Standard deviation of the plane's offset, m.
    pub offset_sigma: f64,
    /// Standard deviation of the normal's direction, rad.
    pub angle_sigma: f64,
    /// The law and its uncertainties.
    pub law: LawFit,
}

impl WallSummary {
    /// The summary of a fit.
    pub fn of(fit: &SurfaceFit) -> Self {
        WallSummary {
            probes: fit.contact_points.len(),
            point: fit.point,
            normal: fit.normal,
            offset_sigma: fit.offset_sigma,
            angle_sigma: fit.angle_sigma,
            law: fit.law,
        }
    }
}

/// Why the procedure stopped itself: its numbers only, held without allocating in the tick
/// that stops (a wall by its index, a failed fit with the error the fitting thread made); the
/// message is formatted when asked ([`Procedure::error`]), after the loop ended, the tip
/// backed out and the robot holding.
#[derive(Debug, Clone, PartialEq)]
pub enum StopReason {
    /// The measured force (N) passed the calibration's bound (N).
    ForceBound {
        /// The measured force's magnitude, N.
        force: f64,
        /// The bound, N.
        bound: f64,
    },
    /// A command left the procedure's workspace.
    Workspace,
    /// The excitation outgrew its preallocated log (capacity, ticks).
    ExcitationLog(usize),
    /// The probes' logs were not sized (no robot response delivered).
    LogsNotSized,
    /// The robot did not follow the excitation: no delay could be fitted.
    RobotNotFollowing,
    /// Wall `wall` was not found within `search_depth` (m) beyond its nominal plane, at probe
    /// `probe` (from 0) of `probes`.
    NotFound {
        /// The wall's index.
        wall: usize,
        /// The search depth, m.
        search_depth: f64,
        /// The probe, from 0.
        probe: usize,
        /// The wall's probes.
        probes: usize,
    },
    /// Wall `wall` pressed `probe_depth` (m) past the first contact without reaching
    /// `press_force` (N), at probe `probe`.
    TooSoft {
        /// The wall's index.
        wall: usize,
        /// The probe depth, m.
        probe_depth: f64,
        /// The press force, N.
        press_force: f64,
        /// The probe, from 0.
        probe: usize,
    },
    /// Wall `wall` still in contact `retreat_distance` (m) out from the pressed point.
    StillInContact {
        /// The wall's index.
        wall: usize,
        /// The retreat distance, m.
        retreat_distance: f64,
        /// The probe, from 0.
        probe: usize,
    },
    /// A probe of wall `wall` outgrew its samples' log (capacity, samples).
    ProbeLog {
        /// The wall's index.
        wall: usize,
        /// The probe, from 0.
        probe: usize,
        /// The log's capacity, samples.
        capacity: usize,
    },
    /// Wall `wall`'s probes could not be fitted.
    Fit {
        /// The wall's index.
        wall: usize,
        /// The fit's error.
        error: FitError,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Settle,
    Excite,
    /// Moving in a straight line to `target` at `speed`, then `then`.
    Move,
    Approach,
    Press,
    Dwell,
    Retreat,
    /// Holding at rest while the robot's response is fitted ([`Procedure::take_fit_job`]).
    RobotFit,
    /// Holding at rest, out of contact, while the wall's fit runs ([`Procedure::take_fit_job`]).
    Fitting,
    /// Backing out after a stop, then done.
    Abort,
    Done,
}

/// The procedure's state.
pub struct Procedure {
    options: CalibrateOptions,
    period: f64,
    sensor_delay_ticks: usize,
    /// Sensor to `t`.
    sensor_orientation: UnitQuaternion<f64>,
    rod: Vector3<f64>,
    orientation: UnitQuaternion<f64>,
    start_tip: Vector3<f64>,
    walls: Vec<(String, Wall)>,
    /// Where each wall is probed: the point of its nominal plane where the nominal run first
    /// touches it (the ideal reference of the scenario as stated), else the point nearest the
    /// start tip.
    centres: Vec<Vector3<f64>>,
    law: ContactModel,
    form: FitForm,
    force_limit: f64,
    phase: Phase,
    tick: u64,
    phase_start: u64,
    /// The commanded tip now.
    tip: Vector3<f64>,
    /// Where a move goes and how fast, m and m/s; what follows.
    move_target: Vector3<f64>,
    move_speed: f64,
    after_move: Phase,
    excite_direction: Vector3<f64>,
    /// The excitation's logs: the commanded and the reported tip, the free-space force, one
    /// entry per excitation tick; preallocated for `excitation_duration / period + 2` entries
    /// (the excitation's ticks and rounding), which the excitation never passes (past it the
    /// procedure stops rather than grow them).
    commanded: Vec<Vector3<f64>>,
    reported: Vec<Vector3<f64>>,
    free_forces: Vec<Vector3<f64>>,
    /// What sizes the probes' logs once the robot's response is known.
    sizing: Sizing,
    bias: Vector3<f64>,
    noise: f64,
    robot: Option<RobotResponse>,
    approach_speed: f64,
    detect_force: f64,
    /// The current wall and probe.
    wall: usize,
    probe: usize,
    /// Each wall's probe points (computed once: a wall's start allocates nothing).
    grids: Vec<Vec<Vector3<f64>>>,
    /// The probes' logs, one slot per probe of a wall, sized when the robot's response is
    /// known (on the fitting thread) and handed back and forth with each wall's fit.
    logs: ProbeLogs,
    recording: bool,
    /// The last ticks' poses (tip position and velocity, `t`), forces on the rod (`t`, N) and
    /// whether each pose was new robot feedback (not held or extrapolated between the robot's
    /// messages): rings of `sensor_delay_ticks + 2` entries (a sample pairs a force with the
    /// pose `sensor_delay_ticks` older), indexed by the tick count `ticks_logged`.
    poses: Vec<(Vector3<f64>, Vector3<f64>)>,
    fresh: Vec<bool>,
    /// Whether the coming tick's pose is new feedback ([`Procedure::set_robot_fresh`]).
    robot_fresh: bool,
    /// Whether the coming tick's force is a new sensor record ([`Procedure::set_sensor_fresh`]).
    sensor_fresh: bool,
    /// Samples in contact whose force was a held sensor record (not logged), and all samples
    /// in contact with a new pose, over the calibration ([`Procedure::held_forces`]).
    held_forces: (u64, u64),
    /// The rod tip of the newest pose that was new robot feedback (`t`, m; None before the
    /// first): what the real-time loop's units check measures the penetration from
    /// ([`Procedure::fed_back_tip`]).
    fresh_tip: Option<Vector3<f64>>,
    forces: Vec<Vector3<f64>>,
    /// Ticks logged into the rings so far.
    ticks_logged: usize,
    /// The current wall's probes' contact points (capacity: a wall's probes).
    contact_points: Vec<Vector3<f64>>,
    /// Their standard deviations for the predicted plane, m (one per probe, preallocated).
    point_sigmas: Vec<f64>,
    /// A second leg after the current move: to this point, then approach.
    pending_leg: Option<Vector3<f64>>,
    /// The commanded tip when the contact was detected.
    detect_tip: Vector3<f64>,
    dwell_centre: Vector3<f64>,
    wall_started: u64,
    /// The pending fit (the robot's response, or the current wall's), until taken.
    fit_job: Option<FitJob>,
    /// The fitted walls (capacity: the scenario's walls).
    pub fits: Vec<SurfaceFit>,
    /// Progress events not yet drained (capacity [`EVENTS`]; at most one comes per tick).
    events: Vec<Progress>,
    error: Option<StopReason>,
}

impl Procedure {
    /// The procedure for a plan's nominal hardware, starting from the plan's initial pose;
    /// `force_limit` is the run's force limit (N). Refuses, before anything is commanded, a
    /// plan whose probes would leave the workspace or whose walls the start tip is inside.
    pub fn new(plan: &Plan, options: &CalibrateOptions, force_limit: f64) -> Result<Self, String> {
        options.validate(force_limit)?;
        let nominal = &plan.nominal;
        let start = nominal.relative_motion(&plan.initial);
        let start_tip = start.point(&nominal.rod_tip);
        let walls: Vec<(String, Wall)> = plan
            .scenario
            .walls
            .iter()
            .map(|w| w.name.clone())
            .zip(nominal.contact.walls.iter().copied())
            .collect();
        for (name, w) in &walls {
            let clearance = w.signed_distance(&start_tip);
            if clearance <= options.standoff {
                return Err(format!(
                    "the rod tip starts {:.3} mm from wall '{name}', within the standoff {:.3} mm: move the start pose out",
                    clearance * 1e3,
                    options.standoff * 1e3
                ));
            }
        }
        // the excitation: along the direction farthest from every normal
        let candidates = [Vector3::x(), Vector3::y(), Vector3::z()];
        let excite_direction = candidates
            .iter()
            .copied()
            .min_by(|a, b| {
                let worst = |d: &Vector3<f64>| {
                    walls
                        .iter()
                        .map(|(_, w)| d.dot(&w.normal).abs())
                        .fold(0.0, f64::max)
                };
                worst(a).total_cmp(&worst(b))
            })
            .unwrap_or(Vector3::x());
        let clearance = walls
            .iter()
            .map(|(_, w)| w.signed_distance(&start_tip))
            .fold(f64::INFINITY, f64::min);
        // where the run will touch each wall: the nominal reference's first contact with it
        let mut nominal_plan = plan.clone();
        nominal_plan.system = plan.nominal.clone();
        let (_, reference) = hilcontact_core::sim::run_reference(&nominal_plan, true);
        let centres = walls
            .iter()
            .map(|(_, w)| {
                let touch = reference
                    .iter()
                    .map(|r| r.tip_position)
                    .find(|p| w.penetration(p) > 0.0)
                    .unwrap_or(start_tip);
                touch - w.normal * w.signed_distance(&touch)
            })
            .collect();
        let ring = plan.sensor.delay_ticks + 2;
        let excitation = (options.excitation_duration / plan.period).ceil() as usize + 2;
        let walls_count = walls.len();
        let mut procedure = Procedure {
            options: options.clone(),
            period: plan.period,
            sensor_delay_ticks: plan.sensor.delay_ticks,
            sensor_orientation: plan.sensor.orientation,
            rod: nominal.rod_tip,
            orientation: start.orientation,
            start_tip,
            walls,
            centres,
            law: nominal.contact.law,
            form: match nominal.contact.law {
                ContactModel::Linear(_) => FitForm::Linear,
                ContactModel::HuntCrossley(_) => FitForm::HuntCrossley,
            },
            force_limit,
            phase: Phase::Settle,
            tick: 0,
            phase_start: 0,
            tip: start_tip,
            move_target: start_tip,
            move_speed: options.move_speed,
            after_move: Phase::Done,
            excite_direction,
            commanded: Vec::with_capacity(excitation),
            reported: Vec::with_capacity(excitation),
            free_forces: Vec::with_capacity(excitation),
            sizing: Sizing {
                options: options.clone(),
                sensor_delay_ticks: plan.sensor.delay_ticks,
                period: plan.period,
                press: 0.0,
                stiffness: 0.0,
                probes: 0,
            },
            bias: Vector3::zeros(),
            noise: 0.0,
            robot: None,
            approach_speed: options.max_approach_speed,
            detect_force: 1.0,
            wall: 0,
            probe: 0,
            grids: Vec::new(),
            logs: ProbeLogs::default(),
            recording: false,
            poses: vec![(Vector3::zeros(), Vector3::zeros()); ring],
            fresh: vec![false; ring],
            robot_fresh: true,
            sensor_fresh: true,
            held_forces: (0, 0),
            fresh_tip: None,
            forces: vec![Vector3::zeros(); ring],
            ticks_logged: 0,
            contact_points: Vec::new(),
            point_sigmas: Vec::new(),
            pending_leg: None,
            detect_tip: start_tip,
            dwell_centre: start_tip,
            wall_started: 0,
            fit_job: None,
            fits: Vec::with_capacity(walls_count),
            events: Vec::with_capacity(EVENTS),
            error: None,
        };
        procedure.grids = (0..walls_count).map(|i| procedure.grid_of(i)).collect();
        let probes = procedure.grids.iter().map(Vec::len).max().unwrap_or(0);
        procedure.contact_points = Vec::with_capacity(probes);
        procedure.point_sigmas = vec![1e-5; probes];
        procedure.sizing.probes = probes;
        procedure.sizing.press = options.press_force(force_limit);
        procedure.sizing.stiffness = procedure.sizing.press / procedure.press_depth();
        // the excitation's amplitude stays well inside the free space
        procedure.options.excitation_amplitude =
            options.excitation_amplitude.min(0.3 * clearance.max(0.0));
        for i in 0..procedure.walls.len() {
            for p in procedure.grid_of(i) {
                for q in [p, p + procedure.walls[i].1.normal * options.standoff] {
                    if (q - start_tip).norm() > options.workspace {
                        return Err(format!(
                            "wall '{}': a probe at {:?} m is {:.1} mm from the start tip, outside the workspace ({:.1} mm): lower the option probe_spacing or raise workspace",
                            procedure.walls[i].0,
                            q.as_slice(),
                            (q - start_tip).norm() * 1e3,
                            options.workspace * 1e3
                        ));
                    }
                }
            }
        }
        Ok(procedure)
    }

    /// The probe points of wall `i`, on its nominal plane, around its centre (where the run
    /// first touches it).
    fn grid_of(&self, i: usize) -> Vec<Vector3<f64>> {
        let w = &self.walls[i].1;
        let centre = self.centres[i];
        let u = w
            .normal
            .cross(&if w.normal.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            })
            .normalize();
        let v = w.normal.cross(&u);
        let side = self.options.points_per_side as i32;
        let half = (side - 1) as f64 / 2.0;
        let mut grid = vec![centre];
        for a in 0..side {
            for b in 0..side {
                let (x, y) = (a as f64 - half, b as f64 - half);
                if x == 0.0 && y == 0.0 {
                    continue;
                }
                grid.push(centre + (u * x + v * y) * self.options.probe_spacing);
            }
        }
        grid
    }

    /// The command of a tip position, at rest in attitude, moving at `velocity`.
    fn command(&self, tip: Vector3<f64>, velocity: Vector3<f64>) -> RelativeMotion {
        RelativeMotion {
            position: tip - self.orientation * self.rod,
            orientation: self.orientation,
            velocity,
            angular_velocity: Vector3::zeros(),
        }
    }

    /// Hands the events since the last call (progress, surface by surface) to `f`, in
    /// order; allocates nothing.
    pub fn drain_events(&mut self, mut f: impl FnMut(Progress)) {
        for event in self.events.drain(..) {
            f(event);
        }
    }

    /// Queues a progress event (drained each tick: never past its capacity).
    fn event(&mut self, event: Progress) {
        if self.events.len() < self.events.capacity() {
            self.events.push(event);
        }
    }

    /// The pose and velocity of the tip logged at tick index `i` (one of the ring's last).
    fn pose(&self, i: usize) -> (Vector3<f64>, Vector3<f64>) {
        self.poses[i % self.poses.len()]
    }

    /// Why the procedure stopped, if it did not finish: the message, formatted here (it
    /// allocates: never in a tick).
    pub fn error(&self) -> Option<String> {
        let name = |w: &usize| self.walls.get(*w).map_or("?", |(n, _)| n.as_str());
        self.error.as_ref().map(|reason| match reason {
            StopReason::ForceBound { force, bound } => format!(
                "the measured force {force:.1} N passed the calibration's bound {bound:.1} N"
            ),
            StopReason::Workspace => "a command left the workspace".into(),
            StopReason::ExcitationLog(capacity) => {
                format!("the excitation outgrew its log ({capacity} ticks)")
            }
            StopReason::LogsNotSized => "the probes' logs were not sized".into(),
            StopReason::RobotNotFollowing => "the robot did not follow the excitation: no delay could be fitted (is the robot feedback live?)".into(),
            StopReason::NotFound { wall, search_depth, probe, probes } => format!(
                "wall '{}' was not found where the scenario says: no contact within {:.2} mm beyond its nominal plane (probe {} of {probes}); check the scenario's [[walls]] against the hardware, or raise the option search_depth",
                name(wall),
                search_depth * 1e3,
                probe + 1,
            ),
            StopReason::TooSoft { wall, probe_depth, press_force, probe } => format!(
                "wall '{}': pressed {:.2} mm past the first contact without reaching {press_force:.1} N (probe {}): the contact is softer than the scenario says, or raise the option probe_depth",
                name(wall),
                probe_depth * 1e3,
                probe + 1
            ),
            StopReason::StillInContact { wall, retreat_distance, probe } => format!(
                "wall '{}': still in contact {:.1} mm out from the pressed point (probe {})",
                name(wall),
                retreat_distance * 1e3,
                probe + 1
            ),
            StopReason::ProbeLog { wall, probe, capacity } => format!(
                "wall '{}': probe {} took more than its {capacity} samples' log (a probe's travel at the approach speed, its dwell and retreat): the procedure stops rather than grow it",
                name(wall),
                probe + 1,
            ),
            StopReason::Fit { wall, error } => {
                format!("wall '{}': the probes could not be fitted: {error}", name(wall))
            }
        })
    }

    /// Why the procedure stopped itself, if it did (its numbers, unformatted).
    pub fn stop_reason(&self) -> Option<&StopReason> {
        self.error.as_ref()
    }

    /// The robot's response measured.
    pub fn robot(&self) -> Option<RobotResponse> {
        self.robot
    }

    /// Where the procedure is: its phase, wall and probe (for messages).
    pub fn whereabouts(&self) -> String {
        format!(
            "{:?}, wall {} probe {}, tip {:?}, first contact {:?}, last force {:?} N",
            self.phase,
            self.wall + 1,
            self.probe + 1,
            self.tip.as_slice(),
            self.detect_tip.as_slice(),
            self.ticks_logged
                .checked_sub(1)
                .map(|i| self.forces[i % self.forces.len()])
                .map(|f| [f.x, f.y, f.z])
        )
    }

    /// The wall names, in the scenario's order.
    pub fn wall_names(&self) -> Vec<String> {
        self.walls.iter().map(|(n, _)| n.clone()).collect()
    }

    /// The measured sensor noise (N, std per axis) and the detection force used (N).
    pub fn noise(&self) -> (f64, f64) {
        (self.noise, self.detect_force)
    }

    /// Probes per wall: the grid and its centre.
    pub fn probes_per_wall(&self) -> u32 {
        self.grid_of(0).len() as u32
    }

    /// The form of the law fitted.
    pub fn form(&self) -> FitForm {
        self.form
    }

    /// The rod tip of the newest pose that was new robot feedback, as reported (`t`, m; None
    /// before the first): not extrapolated between the robot's messages. Over EGM the loop
    /// extrapolates its pose quadratically from the last three 4 ms reports, which multiplies
    /// their reporting noise about 4.4 times (0.13 mm at a 0.03 mm repeatability, 25 N at
    /// this stiffness): the units check's expected force, taken at that pose, spiked up to
    /// 70 N over the law early in a press and read the measured force 0.43–0.97 times the
    /// law in 17 runs of `calibrate_realtime`, so that a spike early enough would stop the
    /// calibration for its units (`1/3`).
    pub fn fed_back_tip(&self) -> Option<Vector3<f64>> {
        self.fresh_tip
    }

    /// Where the current probe first felt its wall: the commanded tip at the detection (m,
    /// `t`) and the wall's nominal normal, while the probe presses, dwells or retreats; None
    /// otherwise (for the real-time loop's units check).
    pub fn contact_reference(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        matches!(self.phase, Phase::Press | Phase::Dwell | Phase::Retreat)
            .then(|| (self.detect_tip, self.walls[self.wall].1.normal))
    }

    fn elapsed(&self) -> f64 {
        (self.tick - self.phase_start) as f64 * self.period
    }

    fn enter(&mut self, phase: Phase) {
        self.phase = phase;
        self.phase_start = self.tick;
    }

    fn move_to(&mut self, target: Vector3<f64>, speed: f64, then: Phase) {
        self.move_target = target;
        self.move_speed = speed;
        self.after_move = then;
        self.enter(Phase::Move);
    }

    /// Stops: backs out of contact along the current wall's normal, then holds. Allocates
    /// nothing (the reason is formatted once the loop has ended: [`Procedure::error`]).
    fn abort(&mut self, reason: StopReason) {
        if self.error.is_none() {
            self.error = Some(reason);
        }
        let normal = self
            .walls
            .get(self.wall)
            .map_or(Vector3::zeros(), |w| w.1.normal);
        self.move_target = self.tip + normal * self.options.retreat_distance;
        self.move_speed = self.options.move_speed;
        self.enter(Phase::Abort);
    }

    /// Whether the coming tick's measured pose is a new robot feedback (true, the default, at
    /// every tick of the simulated facility), or held or extrapolated between the robot's
    /// messages (EGM's 4 ms feedback in a 1 ms loop). The law fit takes the new ones only: an
    /// extrapolated pose carries the reported noise of the last poses amplified and
    /// correlated over the robot's cycle, which the smoothing does not average down, and the
    /// noise in the regressor biases k low (errors in variables).
    pub fn set_robot_fresh(&mut self, fresh: bool) {
        self.robot_fresh = fresh;
    }

    /// Whether the coming tick's force is a new sensor record (true, the default, at every
    /// tick of the simulated facility) or the last one held because the record of this
    /// period had not arrived yet (the loop counts those `late`). A held force is one period
    /// older than the poses it would be paired with: a sample is taken only with a new one
    /// (at k ≈ 1.9e5 N/m a pairing 0.1 ms late on average reads as 19 N·s/m of damping).
    pub fn set_sensor_fresh(&mut self, fresh: bool) {
        self.sensor_fresh = fresh;
    }

    /// Samples with a new robot pose whose force was a held sensor record (left out), and all
    /// samples with a new robot pose, over the calibration so far.
    pub fn held_forces(&self) -> (u64, u64) {
        self.held_forces
    }

    /// One tick: the measurement of this tick in, the next command out.
    pub fn step(&mut self, m: &Measurement) -> Step {
        let force = -(self.sensor_orientation * m.force) - self.bias; // on the rod, t
        let tip = m.actual.point(&self.rod);
        let tip_velocity = m.actual.point_velocity(&self.rod);
        let slot = self.ticks_logged % self.poses.len();
        self.poses[slot] = (tip, tip_velocity);
        self.fresh[slot] = self.robot_fresh;
        if self.robot_fresh {
            self.fresh_tip = Some(tip);
        }
        self.forces[slot] = force;
        self.ticks_logged += 1;
        self.tick += 1;
        // the safety line: the measured force
        if force.norm() > self.options.abort_force(self.force_limit)
            && !matches!(self.phase, Phase::Abort | Phase::Done)
        {
            self.abort(StopReason::ForceBound {
                force: force.norm(),
                bound: self.options.abort_force(self.force_limit),
            });
        }
        let velocity = self.advance(force);
        if (self.tip - self.start_tip).norm() > self.options.workspace
            && !matches!(self.phase, Phase::Abort | Phase::Done)
        {
            self.abort(StopReason::Workspace);
        }
        match self.phase {
            Phase::Done => Step::Done,
            _ => Step::Command(self.command(self.tip, velocity)),
        }
    }

    /// Moves the procedure one tick on; returns the commanded tip velocity.
    fn advance(&mut self, force: Vector3<f64>) -> Vector3<f64> {
        let t = self.period;
        match self.phase {
            Phase::Settle => {
                if self.elapsed() >= SETTLE {
                    self.enter(Phase::Excite);
                }
                Vector3::zeros()
            }
            Phase::Excite => {
                let s = self.elapsed();
                let a = self.options.excitation_amplitude;
                let two_pi = 2.0 * std::f64::consts::PI;
                // three sines, faded in and out over 0.5 s
                let fade = (s / 0.5)
                    .min((self.options.excitation_duration - s) / 0.5)
                    .clamp(0.0, 1.0);
                let (x, v) = [(0.7, 1.0), (2.3, 0.35), (5.1, 0.15)].iter().fold(
                    (0.0, 0.0),
                    |(x, v), &(hz, share)| {
                        (
                            x + share * (two_pi * hz * s).sin(),
                            v + share * two_pi * hz * (two_pi * hz * s).cos(),
                        )
                    },
                );
                self.tip = self.start_tip + self.excite_direction * (a * fade * x);
                if self.commanded.len() == self.commanded.capacity() {
                    self.abort(StopReason::ExcitationLog(self.commanded.capacity()));
                    return Vector3::zeros();
                }
                self.commanded.push(self.tip);
                self.reported.push(self.pose(self.ticks_logged - 1).0);
                self.free_forces.push(force);
                if s >= self.options.excitation_duration {
                    self.finish_excitation();
                }
                self.excite_direction * (a * fade * v)
            }
            Phase::Move | Phase::Abort => {
                let to = self.move_target - self.tip;
                let step = self.move_speed * t;
                if to.norm() <= step {
                    self.tip = self.move_target;
                    if self.phase == Phase::Abort {
                        // hold until the robot, a delay behind, is out of contact
                        if self.elapsed() > self.hold_time() && force.norm() < self.detect_force {
                            self.enter(Phase::Done);
                        }
                        return Vector3::zeros();
                    }
                    if let Some(leg) = self.pending_leg.take() {
                        self.move_to(leg, self.options.move_speed, Phase::Approach);
                        return Vector3::zeros();
                    }
                    let next = self.after_move;
                    self.enter(next);
                    if next == Phase::Approach {
                        self.recording = self.logs.start(self.probe);
                        if !self.recording {
                            self.abort(StopReason::LogsNotSized);
                        }
                    }
                    Vector3::zeros()
                } else {
                    let v = to.normalize() * self.move_speed;
                    self.tip += v * t;
                    v
                }
            }
            Phase::Approach | Phase::Press => {
                let wall = self.walls[self.wall].1;
                self.record();
                let f = force.dot(&wall.normal);
                if self.phase == Phase::Approach && f > self.detect_force {
                    self.detect_tip = self.tip;
                    self.enter(Phase::Press);
                }
                if self.phase == Phase::Press && f >= self.options.press_force(self.force_limit) {
                    self.dwell_centre = self.tip;
                    self.mark_window_start();
                    self.enter(Phase::Dwell);
                    return Vector3::zeros();
                }
                // beyond the nominal plane by more than the search depth: not found
                let depth = -wall.signed_distance(&self.tip);
                if self.phase == Phase::Approach && depth > self.options.search_depth {
                    self.abort(StopReason::NotFound {
                        wall: self.wall,
                        search_depth: self.options.search_depth,
                        probe: self.probe,
                        probes: self.grids[self.wall].len(),
                    });
                    return Vector3::zeros();
                }
                if self.phase == Phase::Press
                    && (self.detect_tip - self.tip).dot(&wall.normal) > self.options.probe_depth
                {
                    self.abort(StopReason::TooSoft {
                        wall: self.wall,
                        probe_depth: self.options.probe_depth,
                        press_force: self.options.press_force(self.force_limit),
                        probe: self.probe,
                    });
                    return Vector3::zeros();
                }
                let v = -wall.normal * self.approach_speed;
                self.tip += v * t;
                v
            }
            Phase::Dwell => {
                self.record();
                let wall = self.walls[self.wall].1;
                let oscillate = self.options.dwell_cycles > 0;
                let s = self.elapsed();
                let hold = self.hold_time();
                let (hz, cycles) = (
                    self.options.dwell_frequency,
                    self.options.dwell_cycles as f64,
                );
                let length = if oscillate { hold + cycles / hz } else { hold };
                if s >= length {
                    self.tip = self.dwell_centre;
                    self.mark_window_end();
                    self.enter(Phase::Retreat);
                    return Vector3::zeros();
                }
                if oscillate && s > hold {
                    // out and back in, never deeper than the pressed point
                    let two_pi = 2.0 * std::f64::consts::PI;
                    let a = self.options.dwell_amplitude * self.press_depth();
                    let phase = two_pi * hz * (s - hold);
                    self.tip = self.dwell_centre + wall.normal * (a * (1.0 - phase.cos()));
                    wall.normal * (a * two_pi * hz * phase.sin())
                } else {
                    self.tip = self.dwell_centre;
                    Vector3::zeros()
                }
            }
            Phase::Retreat => {
                self.record();
                let wall = self.walls[self.wall].1;
                // out past the first contact (commanded a loop delay early) and the margin, at
                // the moves' speed; further, slowly, while a force remains
                let span = self.approach_speed * self.hold_time() + self.options.margin;
                let out = (self.tip - self.detect_tip).dot(&wall.normal);
                // out far enough, to a tenth of a micrometre (the last step lands on the span
                // up to rounding)
                let far = out >= span - 1e-7;
                let f = force.dot(&wall.normal);
                let settled = self.elapsed()
                    > self.hold_time() + self.options.margin / self.options.move_speed;
                let v = if !far {
                    wall.normal * self.options.move_speed.min((span - out) / t)
                } else if f >= self.detect_force && settled {
                    wall.normal * self.approach_speed
                } else {
                    Vector3::zeros()
                };
                if (self.tip - self.dwell_centre).dot(&wall.normal) > self.options.retreat_distance
                {
                    self.abort(StopReason::StillInContact {
                        wall: self.wall,
                        retreat_distance: self.options.retreat_distance,
                        probe: self.probe,
                    });
                    return Vector3::zeros();
                }
                self.tip += v * t;
                // out of contact for a loop delay: the probe is over
                if f < self.detect_force && settled && far {
                    self.finish_probe();
                }
                v
            }
            Phase::RobotFit | Phase::Fitting | Phase::Done => Vector3::zeros(),
        }
    }

    /// The loop's delay from a command to its force: robot delay (and servo lag), sensor
    /// delay, and two ticks.
    fn hold_time(&self) -> f64 {
        hold_time_of(self.robot, self.sensor_delay_ticks, self.period)
    }

    /// The nominal law's penetration at the press force, m.
    fn press_depth(&self) -> f64 {
        let f = self.options.press_force(self.force_limit);
        match self.law {
            ContactModel::Linear(l) => f / l.stiffness,
            ContactModel::HuntCrossley(h) => (f / h.stiffness).powf(1.0 / h.exponent),
        }
    }

    /// Marks the start of the current probe's fit window as the press reaches its force: the
    /// pose a loop delay ([`Procedure::hold_time`], with its 50 ms of settling) after the next
    /// one the samples take (tick index), once the robot is at the pressed point.
    fn mark_window_start(&mut self) {
        let delay = (self.hold_time() / self.period).round() as usize;
        let n = self.ticks_logged.saturating_sub(self.sensor_delay_ticks);
        if let Some(w) = self.logs.windows.get_mut(self.probe) {
            w.0 = n + delay;
        }
    }

    /// Marks the end (exclusive) of the current probe's fit window as the dwell ends (this
    /// tick commands the dwell's last point, the next one the first step of the retreat): the
    /// last pose before the robot can answer the retreat. The retreat's first command (tick
    /// `T + 1`, `T` this tick's pose index) reaches the reported poses the measured robot
    /// delay `τ_r` later; the smoothing ([`SMOOTHING`]) reaches that far forward, and two
    /// ticks more cover the delay's own error (σ 0.3 ms over EGM, 1.2 ms over RSI's 4 ms
    /// cycle): the window ends at `T + 1 + ⌊(τ_r − SMOOTHING)/period⌋ − 2`, never before it
    /// starts. Ended a loop delay and 50 ms into the retreat instead, as it was, it took
    /// samples the fast retreat pulled out of contact (`k·d + c·ḋ < 0` while the tip is still
    /// inside the plane, the force reads 0): they pulled c 9 % low.
    fn mark_window_end(&mut self) {
        let now = self.ticks_logged as f64; // T + 1
        let delay = self.robot.map_or(0.0, |r| r.delay);
        let end = now + ((delay - SMOOTHING) / self.period).floor() - 2.0;
        if let Some(w) = self.logs.windows.get_mut(self.probe) {
            w.1 = (end.max(0.0) as usize).max(w.0);
        }
    }

    /// Records this tick's sample: the force with the pose `τ_p` earlier, when that pose was
    /// new robot feedback ([`Procedure::set_robot_fresh`]) and the force a new sensor record
    /// ([`Procedure::set_sensor_fresh`]).
    fn record(&mut self) {
        if !self.recording {
            return;
        }
        let n = self.ticks_logged;
        if n <= self.sensor_delay_ticks {
            return;
        }
        let i = n - 1 - self.sensor_delay_ticks;
        let ring = self.poses.len();
        if !self.fresh[i % ring] {
            return;
        }
        self.held_forces.1 += 1;
        if !self.sensor_fresh {
            self.held_forces.0 += 1;
            return;
        }
        let (position, velocity) = self.pose(i);
        let force = self.forces[(n - 1) % ring];
        let sample = ProbeSample {
            position,
            velocity,
            force,
        };
        if !self.logs.push(self.probe, sample, i) {
            self.abort(StopReason::ProbeLog {
                wall: self.wall,
                probe: self.probe,
                capacity: self.logs.capacity,
            });
        }
    }

    fn finish_excitation(&mut self) {
        let n = self.free_forces.len() as f64;
        let mean = self.free_forces.iter().fold(Vector3::zeros(), |a, f| a + f) / n;
        let var = self
            .free_forces
            .iter()
            .map(|f| (f - mean).norm_squared())
            .sum::<f64>()
            / (3.0 * n);
        self.bias = mean;
        self.noise = var.sqrt();
        self.detect_force = self.options.detect_force.max(6.0 * self.noise);
        // the robot's response is fitted off the loop's thread ([`Procedure::take_fit_job`]),
        // the probes' logs sized there; the procedure holds at rest until then
        self.fit_job = Some(FitJob::Robot(RobotJob {
            commanded: std::mem::take(&mut self.commanded),
            reported: std::mem::take(&mut self.reported),
            max_delay: self.options.max_delay,
            sizing: self.sizing.clone(),
        }));
        self.enter(Phase::RobotFit);
    }

    /// The robot's response fitted: the approach speed, the probes' logs, the first wall.
    fn deliver_robot(&mut self, response: Option<RobotResponse>, logs: Option<ProbeLogs>) {
        let (Some(r), Some(logs)) = (response, logs) else {
            self.abort(StopReason::RobotNotFollowing);
            return;
        };
        self.robot = Some(r);
        self.logs = logs;
        self.event(Progress::Robot {
            response: r,
            noise: self.noise,
            detect_force: self.detect_force,
        });
        self.approach_speed = self.sizing.approach_speed(Some(r));
        self.start_wall(0);
    }

    fn start_wall(&mut self, i: usize) {
        if i >= self.walls.len() {
            self.move_to(self.start_tip, self.options.move_speed, Phase::Done);
            return;
        }
        self.wall = i;
        self.probe = 0;
        self.contact_points.clear();
        self.wall_started = self.tick;
        // two legs: the start tip, then the first probe's start
        self.move_to(self.start_tip, self.options.move_speed, Phase::Approach);
        self.pending_leg = Some(self.probe_start(0));
    }

    /// Where probe `j` of the current wall starts: outside the nominal plane by `standoff`
    /// (the first), outside the plane the probes so far predict by `margin` (the others).
    fn probe_start(&self, j: usize) -> Vector3<f64> {
        let wall = self.walls[self.wall].1;
        let g = self.grids[self.wall][j];
        if self.contact_points.is_empty() {
            return g + wall.normal * self.options.standoff;
        }
        let sigmas = &self.point_sigmas[..self.contact_points.len()];
        let plane = fit_plane(&self.contact_points, sigmas, &wall.normal);
        let h = plane.normal.dot(&(g - plane.point)) / plane.normal.dot(&wall.normal).max(0.5);
        // g moved along the nominal normal to the predicted plane, then out by the margin
        g - wall.normal * h + wall.normal * self.options.margin
    }

    fn finish_probe(&mut self) {
        // the contact point of this probe from its samples (for the next probes' starts)
        let wall = self.walls[self.wall].1;
        self.recording = false;
        if let Some(samples) = self.logs.probes.get(self.probe) {
            let first = samples
                .iter()
                .find(|s| s.force.dot(&wall.normal) > self.detect_force);
            if let Some(first) = first {
                // corrected for the force at detection through the nominal law
                let f = first.force.dot(&wall.normal);
                let d = self.law_depth(f);
                if self.contact_points.len() < self.contact_points.capacity() {
                    self.contact_points.push(first.position + wall.normal * d);
                }
            }
        }
        self.probe += 1;
        if self.probe < self.grids[self.wall].len() {
            let start = self.probe_start(self.probe);
            // out along the normal, then across
            let out = self.tip.max_by_normal(&wall.normal, &start);
            self.move_to(out, self.options.move_speed, Phase::Move);
            self.pending_leg = Some(start);
            return;
        }
        self.fit_wall();
    }

    fn law_depth(&self, f: f64) -> f64 {
        match self.law {
            ContactModel::Linear(l) => f / l.stiffness,
            ContactModel::HuntCrossley(h) => (f / h.stiffness).powf(1.0 / h.exponent),
        }
    }

    /// The current wall's probes are done: its fit becomes a job ([`Procedure::take_fit_job`])
    /// and the procedure holds at rest until the result is delivered.
    fn fit_wall(&mut self) {
        let wall = self.walls[self.wall].1;
        self.fit_job = Some(FitJob::Wall(WallJob {
            logs: std::mem::take(&mut self.logs),
            probes: self.grids[self.wall].len(),
            normal: wall.normal,
            form: self.form,
            detect_force: self.detect_force,
            period: self.period,
        }));
        self.enter(Phase::Fitting);
    }

    /// The pending fit, once due (the robot's response after the excitation, a wall's after
    /// its probes; the procedure holds at rest until [`Procedure::deliver_fit`]); None
    /// otherwise. The caller runs it ([`FitJob::run`]) where it likes: inline, or off the
    /// real-time loop's thread.
    pub fn take_fit_job(&mut self) -> Option<FitJob> {
        self.fit_job.take()
    }

    /// The result of the job [`Procedure::take_fit_job`] gave: the robot's response (the
    /// walls begin), or a wall's fit (the wall is measured and the next begins), or the
    /// procedure stops. The logs it carries come back into use. Ignored unless the procedure
    /// waits for it (a stop while it ran).
    pub fn deliver_fit(&mut self, done: FitDone) {
        match (done, self.phase) {
            (FitDone::Robot { response, logs }, Phase::RobotFit) => {
                self.deliver_robot(response, logs)
            }
            (FitDone::Wall { result, logs }, Phase::Fitting) => {
                self.logs = logs;
                match result {
                    Ok(fit) => {
                        let spent = (self.tick - self.wall_started) as f64 * self.period;
                        self.event(Progress::Wall {
                            index: self.wall,
                            fit: WallSummary::of(&fit),
                            spent,
                        });
                        if self.fits.len() < self.fits.capacity() {
                            self.fits.push(fit);
                        }
                        let next = self.wall + 1;
                        self.start_wall(next);
                    }
                    Err(error) => self.abort(StopReason::Fit {
                        wall: self.wall,
                        error,
                    }),
                }
            }
            _ => {}
        }
    }

    /// Runs a pending fit at once, in this thread ([`super::simulate`]).
    pub fn fit_inline(&mut self) {
        if let Some(job) = self.take_fit_job() {
            let done = job.run();
            self.deliver_fit(done);
        }
    }
}

/// The loop's delay from a command to its force, s: robot delay (and servo lag), sensor
/// delay, and two ticks.
fn hold_time_of(robot: Option<RobotResponse>, sensor_delay_ticks: usize, period: f64) -> f64 {
    let robot = robot.map_or(0.0, |r| {
        r.delay
            + if r.servo_frequency > 0.0 {
                2.0 * r.servo_damping / (2.0 * std::f64::consts::PI * r.servo_frequency)
            } else {
                0.0
            }
    });
    robot + (sensor_delay_ticks as f64 + 2.0) * period + 0.05
}

/// What sizes the probes' logs: the options, the loop, the press force and the nominal
/// law's secant stiffness at it.
#[derive(Debug, Clone)]
struct Sizing {
    options: CalibrateOptions,
    sensor_delay_ticks: usize,
    /// The loop's period, s.
    period: f64,
    /// The force each probe presses to, N.
    press: f64,
    /// The nominal law's secant stiffness at `press`, N/m.
    stiffness: f64,
    /// Probes per wall (the largest grid).
    probes: usize,
}

impl Sizing {
    /// The approach speed, m/s: the force overshoot over the loop's delay at most a quarter
    /// of the press force under the nominal law, at most `max_approach_speed`.
    fn approach_speed(&self, robot: Option<RobotResponse>) -> f64 {
        let hold = hold_time_of(robot, self.sensor_delay_ticks, self.period);
        self.options
            .max_approach_speed
            .min(0.25 * self.press / (self.stiffness * hold))
    }

    /// The most samples one probe records (from its approach to the end of its retreat),
    /// a tick each at most: `T_p / period + 64`, with the probe's longest time
    ///
    /// `T_p = (standoff + margin + 2·search_depth + probe_depth + retreat_distance) / v_a
    ///        + 2·τ_h + dwell_cycles / dwell_frequency + (v_a·τ_h + 2·margin) / move_speed`,
    ///
    /// `v_a` the approach speed and `τ_h` the loop's delay (the hold time): the approach's
    /// travel to the deepest search (from the standoff or the predicted plane plus the
    /// margin), the press to `probe_depth`, the hold and the oscillation of the dwell, the
    /// retreat out past the first contact at the moves' speed, its settling, and its slow
    /// backing out up to `retreat_distance`. A probe past it stops the procedure.
    fn samples_per_probe(&self, robot: Option<RobotResponse>) -> usize {
        let o = &self.options;
        let v = self.approach_speed(robot);
        let hold = hold_time_of(robot, self.sensor_delay_ticks, self.period);
        let seconds =
            (o.standoff + o.margin + 2.0 * o.search_depth + o.probe_depth + o.retreat_distance) / v
                + 2.0 * hold
                + o.dwell_cycles as f64 / o.dwell_frequency
                + (v * hold + 2.0 * o.margin) / o.move_speed;
        (seconds / self.period).ceil() as usize + 64
    }
}

/// The probes' logs of one wall: for each probe its samples, the tick of each sample's pose
/// and its fit window (ticks). Allocated once (on the fitting thread, when the robot's
/// response sizes them: [`Sizing::samples_per_probe`] samples per probe), then handed to each
/// wall's fit and back, never grown.
#[derive(Debug, Default)]
pub struct ProbeLogs {
    probes: Vec<Vec<ProbeSample>>,
    /// The tick of each probe's samples' poses.
    sample_ticks: Vec<Vec<usize>>,
    /// Each probe's samples that the law fit uses: from the robot's arrival at the pressed
    /// point (a loop delay after the dwell starts) to the last pose before the robot can
    /// answer the retreat ([`Procedure::mark_window_end`]), ticks (pose indices, the end
    /// exclusive).
    windows: Vec<(usize, usize)>,
    /// Samples each probe's log holds.
    capacity: usize,
}

impl ProbeLogs {
    /// Logs for `probes` probes of `capacity` samples each.
    fn new(probes: usize, capacity: usize) -> Self {
        ProbeLogs {
            probes: (0..probes).map(|_| Vec::with_capacity(capacity)).collect(),
            sample_ticks: (0..probes).map(|_| Vec::with_capacity(capacity)).collect(),
            windows: vec![(usize::MAX, usize::MAX); probes],
            capacity,
        }
    }

    /// Empties probe `j`'s log for its start; false when there is no such slot.
    fn start(&mut self, j: usize) -> bool {
        match (self.probes.get_mut(j), self.sample_ticks.get_mut(j)) {
            (Some(p), Some(t)) => {
                p.clear();
                t.clear();
                self.windows[j] = (usize::MAX, usize::MAX);
                true
            }
            _ => false,
        }
    }

    /// Logs a sample of probe `j` whose pose is of tick `tick`; false (nothing logged) when
    /// its log is full.
    fn push(&mut self, j: usize, sample: ProbeSample, tick: usize) -> bool {
        match (self.probes.get_mut(j), self.sample_ticks.get_mut(j)) {
            (Some(p), Some(t)) if p.len() < self.capacity => {
                p.push(sample);
                t.push(tick);
                true
            }
            _ => false,
        }
    }
}

/// A fit to run off the real-time loop's thread (it allocates and takes up to ~0.1 s).
pub enum FitJob {
    /// The robot's response from the excitation; sizes the probes' logs.
    Robot(RobotJob),
    /// A wall's surface and law from its probes.
    Wall(WallJob),
}

/// A fit's result, with the logs it hands back to the procedure.
pub enum FitDone {
    /// The robot's response (None: no delay could be fitted) and the probes' logs sized for
    /// it.
    Robot {
        /// The response.
        response: Option<RobotResponse>,
        /// The probes' logs.
        logs: Option<ProbeLogs>,
    },
    /// A wall's fit and its logs back, emptied of nothing (each probe's start clears its
    /// own).
    Wall {
        /// The fit.
        result: Result<SurfaceFit, FitError>,
        /// The logs.
        logs: ProbeLogs,
    },
}

/// The robot's response fit: the excitation's commanded and reported tip, m.
pub struct RobotJob {
    commanded: Vec<Vector3<f64>>,
    reported: Vec<Vector3<f64>>,
    /// Longest delay looked for, s.
    max_delay: f64,
    sizing: Sizing,
}

/// A wall's fit: each probe's samples with their poses' ticks and its fit window (ticks), and
/// what the fit needs.
pub struct WallJob {
    logs: ProbeLogs,
    /// The wall's probes (the first `probes` slots of the logs).
    probes: usize,
    /// The wall's nominal normal (unit, `t`).
    normal: Vector3<f64>,
    form: FitForm,
    /// Smallest force that counts as contact, N.
    detect_force: f64,
    /// The loop's period, s.
    period: f64,
}

impl FitJob {
    /// Runs the fit. Allocates and takes up to ~0.1 s: never in a real-time tick.
    pub fn run(self) -> FitDone {
        match self {
            FitJob::Robot(job) => {
                let response = fit_robot_response(
                    &job.commanded,
                    &job.reported,
                    job.sizing.period,
                    job.max_delay,
                );
                let logs = response.map(|r| {
                    ProbeLogs::new(job.sizing.probes, job.sizing.samples_per_probe(Some(r)))
                });
                FitDone::Robot { response, logs }
            }
            FitJob::Wall(job) => {
                let result = job.fit();
                FitDone::Wall {
                    result,
                    logs: job.logs,
                }
            }
        }
    }
}

impl WallJob {
    /// The wall's fit: each probe's positions smoothed ([`SMOOTHING`]), its window's samples,
    /// then [`fit_surface`].
    fn fit(&self) -> Result<SurfaceFit, FitError> {
        let logs = &self.logs;
        // the reported positions' white noise averaged down, probe by probe; the fit takes the
        // samples of each probe's window (the robot at the pressed point and oscillating)
        let probes: Vec<Vec<ProbeSample>> = logs
            .probes
            .iter()
            .zip(&logs.sample_ticks)
            .zip(&logs.windows)
            .take(self.probes)
            .map(|((p, ticks), &(from, to))| {
                let positions: Vec<_> = p.iter().map(|s| s.position).collect();
                // the samples' mean spacing, ticks (1 with new feedback at every tick; the
                // robot's cycle over the loop's period with slower feedback)
                let spacing = match (ticks.first(), ticks.last()) {
                    (Some(&a), Some(&b)) if ticks.len() > 1 => {
                        (b - a) as f64 / (ticks.len() - 1) as f64
                    }
                    _ => 1.0,
                };
                let half_width = ((SMOOTHING / (spacing * self.period)).round() as usize).max(1);
                let smoothed = smooth(&positions, half_width);
                // the window's ticks as sample indices
                let from = ticks.partition_point(|&t| t < from);
                let to = ticks.partition_point(|&t| t < to);
                p[from..to]
                    .iter()
                    .zip(&smoothed[from..to])
                    .map(|(s, &position)| ProbeSample { position, ..*s })
                    .collect()
            })
            .collect();
        fit_surface(&probes, &self.normal, self.form, self.detect_force)
    }
}

/// The farther-out of two points along a normal, at the first's place.
trait MaxByNormal {
    fn max_by_normal(&self, normal: &Vector3<f64>, other: &Vector3<f64>) -> Vector3<f64>;
}

impl MaxByNormal for Vector3<f64> {
    fn max_by_normal(&self, normal: &Vector3<f64>, other: &Vector3<f64>) -> Vector3<f64> {
        let lift = (other - self).dot(normal).max(0.0);
        self + normal * lift
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hilcontact_core::facility::FacilityLoop;
    use hilcontact_core::Scenario;

    /// paper-table1's front wall, damped (ζ ≈ 0.1, c = 1403 N·s/m), on the honest facility at
    /// an 80 ms robot delay (docs/calibration.md, "Measured, simulated").
    fn damped_wall() -> Scenario {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/paper-table1.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let mut s: Scenario = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        s.walls.truncate(1);
        s.contact.damping = 1403.0;
        let f = &mut s.facility;
        f.robot_delay = 0.08;
        f.sensor_delay = 0.005;
        f.sensor_noise = 0.2;
        f.robot_repeatability = 3e-5;
        f.mount_offset = [0.0003, -0.0004, 0.0];
        f.mount_rotation = [0.0, 0.3, 0.4];
        f.stiffness_error = 1.07;
        f.seed = 3;
        s
    }

    #[test]
    fn each_probe_s_fit_window_ends_before_the_retreat_moves_the_robot() {
        let plan = damped_wall().resolve().unwrap();
        let options = CalibrateOptions {
            points_per_side: 2,
            ..CalibrateOptions::default()
        };
        let mut procedure = Procedure::new(&plan, &options, 500.0).unwrap();
        let mut facility = FacilityLoop::new(&plan);
        let mut command = plan.nominal.relative_motion(&plan.initial);
        // up to the wall's fit job (the robot's response fitted inline)
        let job = loop {
            let m = facility.tick(&command);
            match procedure.step(&m) {
                Step::Command(c) => command = c,
                Step::Done => panic!("stopped: {:?}", procedure.error()),
            }
            match procedure.take_fit_job() {
                Some(FitJob::Wall(job)) => break job,
                Some(robot) => procedure.deliver_fit(robot.run()),
                None => {}
            }
        };
        let normal = job.normal;
        let oscillation = 2.0
            * std::f64::consts::PI
            * options.dwell_frequency
            * options.dwell_amplitude
            * procedure.press_depth();
        let logs = &job.logs;
        for (j, ((samples, ticks), &(from, to))) in logs
            .probes
            .iter()
            .zip(&logs.sample_ticks)
            .zip(&logs.windows)
            .take(job.probes)
            .enumerate()
        {
            let (from, to) = (
                ticks.partition_point(|&t| t < from),
                ticks.partition_point(|&t| t < to),
            );
            assert!(to - from > 500, "probe {j}: {} samples", to - from);
            // every sample of the window in contact (the retreat at move_speed, ten times the
            // oscillation's speed, takes the tip out of contact within ~10 ms: a window that
            // reached into it took samples at 0 N), and moving no faster than the oscillation
            // (plus the robot's repeatability noise)
            for s in &samples[from..to] {
                let f = s.force.dot(&normal);
                assert!(f > procedure.detect_force, "probe {j}: {f} N in the window");
                let v = s.velocity.dot(&normal);
                assert!(
                    v <= 1.5 * oscillation + 0.002,
                    "probe {j}: {v} m/s outwards in the window (the oscillation's peak {oscillation})"
                );
            }
        }
    }
}
