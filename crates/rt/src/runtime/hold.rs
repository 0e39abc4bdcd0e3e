//! The loop thread after a stop: the robot backed away from a contact after a force or
//! moment stop ([`Loop::retreat`]), then commanded to hold for `hold_time` ([`Loop::hold`]),
//! paced as the ticks were (the clock, or the robot's packets).

use nalgebra::Vector3;

use hilcontact_core::world::RelativeMotion;

use super::tick::Loop;
use crate::clock::{now_ns, sleep_until_ns};
use crate::devices::Pacing;
use crate::safety::hold_target;

impl Loop {
    /// Waits for the next period of a stop's stream: the clock's period `i` after `start`, or
    /// the robot's next packet (at most two periods); then polls the links.
    pub(super) fn next_stop_period(&mut self, start: u64, i: u64) {
        match self.pacing {
            Pacing::Clock => sleep_until_ns(start + i * self.period_ns),
            Pacing::Robot => {
                let n = self
                    .robot
                    .wait(now_ns() + 2 * self.cycle_ns(), &mut self.estimator);
                self.robot_arrived(n, now_ns());
            }
        }
        self.poll_links(now_ns());
    }

    /// The robot's pose as far as it can be trusted: its last fed-back pose if plausible, else
    /// the last command ([`hold_target`]).
    pub(super) fn checked_pose(&self) -> Option<RelativeMotion> {
        hold_target(
            &self.limits,
            self.estimator.last_pose(),
            self.last_command,
            &self.tracking,
            &self.rod,
            &self.start_tip,
        )
    }

    /// Streams the hold command for `hold_time` (one per period on the clock, or one per robot
    /// packet): `at` (the end of a retreat) if given, else the last fed-back pose at rest if it
    /// is plausible, else the last command ([`hold_target`]).
    pub(super) fn hold(&mut self, at: Option<RelativeMotion>) {
        let Some(pose) = at.or_else(|| self.checked_pose()) else {
            return;
        };
        let cycle = self.cycle_ns() as f64 * 1e-9;
        let periods = (self.hold_time / cycle).ceil() as u64;
        let start = now_ns();
        for i in 0..periods.max(1) {
            self.next_stop_period(start, i);
            self.robot.hold(&pose, now_ns().saturating_sub(self.t0_ns));
        }
    }

    /// After a force or moment stop: backs the robot away, at `limits.retreat_speed`, from its
    /// (checked) pose to the last pose where the measured force was below
    /// [`CONTACT_FREE_FORCE`], at most `limits.retreat_distance` away, so that the stop releases
    /// the contact instead of holding the rod pressed; returns where it ended (the hold that
    /// follows holds there, not at the delayed feedback). Nothing is sent, and None returned,
    /// when either pose is unknown or not plausible.
    pub(super) fn retreat(&mut self) -> Option<RelativeMotion> {
        let (Some(from), Some(free)) = (self.checked_pose(), self.last_free) else {
            return None;
        };
        let (a, b) = (from.point(&self.rod), free.point(&self.rod));
        let inside = (b - self.start_tip).norm() <= self.limits.workspace;
        let distance = (b - a).norm();
        if !inside || distance <= 1e-6 {
            return None;
        }
        // never farther than retreat_distance: along the same line
        let reach = (self.limits.retreat_distance / distance).min(1.0);
        let speed = self.limits.retreat_speed;
        let cycle = self.cycle_ns() as f64 * 1e-9;
        let periods = (distance * reach / (speed * cycle)).ceil() as u64;
        let velocity = (free.position - from.position) * (reach / (periods as f64 * cycle));
        let start = now_ns();
        let mut command = from;
        for i in 1..=periods {
            self.next_stop_period(start, i - 1);
            let s = reach * i as f64 / periods as f64;
            command = RelativeMotion {
                position: from.position.lerp(&free.position, s),
                orientation: from.orientation.slerp(&free.orientation, s),
                velocity,
                angular_velocity: Vector3::zeros(),
            };
            self.robot
                .send(&command, now_ns().saturating_sub(self.t0_ns));
        }
        let end = RelativeMotion {
            velocity: Vector3::zeros(),
            ..command
        };
        self.last_command = Some(end);
        Some(end)
    }
}
