//! The loop thread's start-up, before the first tick (not real-time): streaming requested,
//! the first sensor record and robot feedback waited for, the start pose checked, the
//! sensor's offset measured. Nothing that could move the robot is sent before the start
//! pose has been checked.

use std::sync::atomic::Ordering;
use std::time::Duration;

use super::start::{check_start_distance, missing_peers};
use super::tick::Loop;
use crate::clock::now_ns;
use crate::devices::Wrench;
use crate::error::{Result, RtError};
use crate::offset::{OffsetMode, WrenchStats};
use crate::safety::CYCLE_WINDOW;

impl Loop {
    /// Start-up (not real-time): requests streaming, waits for the first record and feedback,
    /// checks the start pose. Nothing that could move the robot is sent before the check has
    /// passed: before the first feedback nothing at all, then only holds at the robot's own
    /// fed-back pose (at rest), which keep a controller's session alive without moving it.
    pub(super) fn connect(&mut self) -> Result<()> {
        self.sensor.start_streaming();
        let start = now_ns();
        let timeout_ns = (self.connect_timeout * 1e9) as u64;
        let mut last_request = start;
        loop {
            if self.shared.stop_requested.load(Ordering::Acquire) {
                return Err(RtError::Connect(
                    "stopped by the user while connecting".into(),
                ));
            }
            let now = now_ns();
            self.poll_links(now);
            if let Some(pose) = self.estimator.last_pose() {
                self.robot.hold(&pose, now_ns().saturating_sub(self.t0_ns));
            }
            let cycle = &self.estimator.cycle;
            let cycle_known = cycle.measured.is_some() || cycle.mismatch.is_some();
            if self.sensor.stats().accepted > 0 && self.estimator.has_feedback() && cycle_known {
                break;
            }
            if now - start > timeout_ns {
                let mut missing = missing_peers(
                    self.sensor.as_ref(),
                    self.robot.as_ref(),
                    self.estimator.has_feedback(),
                );
                if missing.is_empty() {
                    missing.push(format!(
                        "too few {} messages to measure the robot's cycle ({} steps of its time stamps)",
                        self.robot.name(),
                        CYCLE_WINDOW
                    ));
                }
                return Err(RtError::Connect(format!(
                    "{} within {} s (connect_timeout)",
                    missing.join(" and "),
                    self.connect_timeout
                )));
            }
            if self.sensor.stats().accepted == 0 && now - last_request > 200_000_000 {
                self.sensor.start_streaming();
                last_request = now;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        // the robot's cycle, from its own time stamps, must be the configured one
        if let Some(measured) = self.estimator.cycle.mismatch {
            self.hold(None);
            return Err(RtError::Connect(format!(
                "the {} robot's cycle measured from its time stamps is {:.1} ms, configured {:.1} ms (the robot's period option; cycle_tolerance {:.0} %): configure the same cycle on both sides",
                self.robot.name(),
                measured * 1e3,
                self.estimator.cycle.configured * 1e3,
                self.limits.cycle_tolerance * 1e2
            )));
        }
        // the robot must be where the scenario starts
        let actual = self
            .estimator
            .last_pose()
            .map_or(self.initial.position, |p| p.point(&self.rod));
        let distance = (actual - self.initial.point(&self.rod)).norm();
        if let Err(e) = check_start_distance(distance, self.start_tolerance) {
            self.hold(None);
            return Err(e);
        }
        if self.offset.mode == OffsetMode::Measure {
            if let Err(e) = self.measure_offset() {
                self.hold(None);
                return Err(e);
            }
        }
        // forget the start-up's sequence bookkeeping for the lateness counters
        self.sensor.stats_mut().late = 0;
        self.robot.stats_mut().late = 0;
        Ok(())
    }

    /// Averages the sensor's records over `offset.time` with the robot held at its own pose (rod
    /// free: the start pose was checked) and keeps the mean as the offset, or refuses
    /// ([`OffsetOptions::offset`]).
    pub(super) fn measure_offset(&mut self) -> Result<()> {
        let mut stats = WrenchStats::default();
        let start = now_ns();
        let end = start + (self.offset.time * 1e9) as u64;
        while now_ns() < end {
            if self.poll_links(now_ns()) {
                stats.push(&Wrench {
                    force: self.force,
                    moment: self.moment,
                });
            }
            if let Some(pose) = self.checked_pose() {
                self.robot.hold(&pose, now_ns().saturating_sub(self.t0_ns));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        self.sensor_offset = self.offset.offset(&stats)?;
        Ok(())
    }
}
