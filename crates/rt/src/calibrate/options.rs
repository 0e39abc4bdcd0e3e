//! The calibration procedure's options (`hilcontact calibrate --help`): probes, speeds and
//! bounds, in SI units.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// How the calibration probes the hardware.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrateOptions {
    /// Probes per side of each wall's square grid, plus one at its centre (1 to 9; 4: 17 probes).
    #[schemars(range(min = 1, max = 9))]
    pub points_per_side: u32,
    /// Distance between neighbouring probes, m (> 0, <= 1).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1.0))]
    pub probe_spacing: f64,
    /// How far outside the nominal plane each wall's first probe starts, m (> 0, <= 0.1).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.1))]
    pub standoff: f64,
    /// How far beyond its nominal plane a wall is searched before the procedure stops, m
    /// (> 0, <= 0.1).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.1))]
    pub search_depth: f64,
    /// How far outside the plane the earlier probes predict the later probes start, m (> 0,
    /// <= 0.1).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.1))]
    pub margin: f64,
    /// The force each probe presses to, N (0: a fifth of the force limit; else > 0, <= 1e5);
    /// at most half the force limit.
    #[schemars(range(min = 0.0, max = 1e5))]
    pub press_force: f64,
    /// How far past the first contact a probe may press, m (> 0, <= 0.1): deeper without
    /// reaching `press_force` stops the procedure.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.1))]
    pub probe_depth: f64,
    /// Smallest force that counts as contact, N (> 0, <= 1e4; raised to 6 times the sensor
    /// noise measured at start).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e4))]
    pub detect_force: f64,
    /// Fastest approach along a normal, m/s (> 0, <= 1; slower when the loop's delay needs it:
    /// the force overshoot over the delay stays below a quarter of `press_force`).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1.0))]
    pub max_approach_speed: f64,
    /// Speed of the moves between probes, in free space, m/s (> 0, <= 1).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1.0))]
    pub move_speed: f64,
    /// How far a stop backs the tip out along the wall's normal, m (> 0, <= 0.1).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.1))]
    pub retreat_distance: f64,
    /// Amplitude of the free-space excitation that measures the robot's delay, m (> 0, <= 0.05;
    /// at most 0.3 of the start tip's clearance from the walls).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.05))]
    pub excitation_amplitude: f64,
    /// Duration of the excitation, s (> 1, <= 60).
    #[schemars(extend("exclusiveMinimum" = 1.0), range(max = 60.0))]
    pub excitation_duration: f64,
    /// Longest robot delay looked for, s (> 0, <= 2).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 2.0))]
    pub max_delay: f64,
    /// Frequency of the oscillation at each probe's pressed point, Hz (> 0, <= 50): fast
    /// against the robot's repeatability drift.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 50.0))]
    pub dwell_frequency: f64,
    /// Cycles of that oscillation (0 to 100; 0: a dwell without oscillation).
    #[schemars(range(max = 100))]
    pub dwell_cycles: u32,
    /// Its amplitude, a share of the press depth (> 0, <= 0.5).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 0.5))]
    pub dwell_amplitude: f64,
    /// Largest distance of a commanded tip from the start tip, m (> 0, <= 10).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 10.0))]
    pub workspace: f64,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        CalibrateOptions {
            points_per_side: 4,
            probe_spacing: 0.02,
            standoff: 0.002,
            search_depth: 0.002,
            margin: 0.0003,
            press_force: 0.0,
            probe_depth: 0.003,
            detect_force: 1.0,
            max_approach_speed: 0.002,
            move_speed: 0.05,
            retreat_distance: 0.005,
            excitation_amplitude: 0.002,
            excitation_duration: 3.0,
            max_delay: 0.5,
            dwell_frequency: 8.0,
            dwell_cycles: 8,
            dwell_amplitude: 0.4,
            workspace: 0.3,
        }
    }
}

impl CalibrateOptions {
    /// The force each probe presses to, N, for the run's `force_limit`.
    pub fn press_force(&self, force_limit: f64) -> f64 {
        if self.press_force > 0.0 {
            self.press_force
        } else {
            0.2 * force_limit
        }
    }

    /// The measured force that stops the procedure, N: twice the press force, at most the
    /// force limit.
    pub fn abort_force(&self, force_limit: f64) -> f64 {
        (2.0 * self.press_force(force_limit)).min(force_limit)
    }

    /// Checks the options against the schema's ranges and each other; the message names the
    /// option.
    pub fn validate(&self, force_limit: f64) -> std::result::Result<(), String> {
        let mut issues = hilcontact_core::error::Issues::default();
        hilcontact_core::schema::check_ranges_of(
            self,
            &schemars::schema_for!(CalibrateOptions),
            "options",
            &mut issues,
        );
        if let Err(hilcontact_core::CoreError::InvalidScenario { key, message, .. }) =
            issues.finish()
        {
            return Err(format!("{key}: {message}"));
        }
        if !(force_limit > 0.0 && force_limit.is_finite()) {
            return Err(format!(
                "force_limit: must be a positive number, got {force_limit}"
            ));
        }
        if self.press_force(force_limit) > 0.5 * force_limit {
            return Err(format!(
                "press_force: {} N is more than half the force limit ({force_limit} N)",
                self.press_force(force_limit)
            ));
        }
        if self.detect_force >= self.press_force(force_limit) {
            return Err(format!(
                "detect_force: {} N must be below the press force ({} N)",
                self.detect_force,
                self.press_force(force_limit)
            ));
        }
        Ok(())
    }
}
