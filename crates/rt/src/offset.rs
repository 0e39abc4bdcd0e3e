//! The sensor's offset at start: what an F/T sensor reads with the rod in free space (gravity
//! of the rod and tool, temperature drift, a bias taken in another pose). The runtime measures
//! it before the run, while nothing is commanded, and subtracts it from every record
//! ([`OffsetMode::Measure`], the default); an offset larger than the configured bounds refuses
//! the start (the rod may be touching something, or the sensor is wrong), with the offset and
//! how to fix it. `hilcontact check` reports the same statistics.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use hilcontact_core::Plan;

use crate::devices::Wrench;
use crate::error::{Result, RtError};

/// How the runtime handles the sensor's offset at start.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum OffsetMode {
    /// Average the wrench over `offset.time` at start (rod free, nothing commanded) and subtract
    /// it from every record; refuse the start when it exceeds `offset.max_force` or
    /// `offset.max_moment`.
    #[default]
    Measure,
    /// Use the sensor's readings as they come, nothing measured or checked (the sensor was
    /// biased by the user, or by the RDT link's `bias` option).
    Off,
}

/// Options of the sensor's offset at start (`[offset]`; CLI `--offset`, `--offset-time`,
/// `--max-offset-force`, `--max-offset-moment`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct OffsetOptions {
    /// Measure and subtract the offset, or not.
    pub mode: OffsetMode,
    /// How long the wrench is averaged at start, s (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub time: f64,
    /// Largest force offset accepted, N (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub max_force: f64,
    /// Largest moment offset accepted, N·m (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub max_moment: f64,
}

impl Default for OffsetOptions {
    fn default() -> Self {
        OffsetOptions {
            mode: OffsetMode::Measure,
            time: 0.2,
            max_force: 50.0,
            max_moment: 10.0,
        }
    }
}

impl OffsetOptions {
    /// Checks that the numbers are positive.
    pub fn validate(&self) -> Result<()> {
        for (key, v) in [
            ("offset.time", self.time),
            ("offset.max_force", self.max_force),
            ("offset.max_moment", self.max_moment),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RtError::option(
                    key,
                    format!("must be a positive number, got {v}"),
                ));
            }
        }
        Ok(())
    }

    /// Refuses to measure the offset of a scenario that starts in contact (mode
    /// [`OffsetMode::Measure`]): the rod is not free at start.
    pub fn check_start(&self, plan: &Plan) -> Result<()> {
        if self.mode == OffsetMode::Measure
            && plan.nominal.contact(&plan.initial).force.norm() > 0.0
        {
            return Err(RtError::option(
                "offset.mode",
                "the scenario starts in contact, so the sensor's offset cannot be measured at start: bias the sensor with the rod free and set offset.mode = \"off\" (--offset off)",
            ));
        }
        Ok(())
    }

    /// The offset to subtract (mode [`OffsetMode::Measure`]), or the refusal: `stats` measured
    /// with the rod free.
    pub fn offset(&self, stats: &WrenchStats) -> Result<Wrench> {
        let mean = stats.mean();
        let (f, m) = (mean.force.norm(), mean.moment.norm());
        if stats.count() == 0 || !(f.is_finite() && m.is_finite()) {
            return Err(RtError::Connect(
                "no usable sensor record to measure the sensor's offset".into(),
            ));
        }
        if f > self.max_force || m > self.max_moment {
            return Err(RtError::Connect(format!(
                "the sensor reads F = ({:.1}, {:.1}, {:.1}) N, M = ({:.2}, {:.2}, {:.2}) N·m with the rod free \
                 (|F| {f:.1} N, |M| {m:.2} N·m; offset.max_force {:.1} N, offset.max_moment {:.2} N·m): \
                 make sure the rod touches nothing, then bias the sensor (its web page, or --bias), \
                 or raise the bounds (--max-offset-force, --max-offset-moment)",
                mean.force.x, mean.force.y, mean.force.z,
                mean.moment.x, mean.moment.y, mean.moment.z,
                self.max_force, self.max_moment
            )));
        }
        Ok(mean)
    }
}

/// Running mean and standard deviation of wrenches, per axis (no allocation).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WrenchStats {
    n: u64,
    sum: [Vector3<f64>; 2],
    sum_sq: [Vector3<f64>; 2],
}

impl WrenchStats {
    /// Adds one wrench.
    pub fn push(&mut self, w: &Wrench) {
        self.n += 1;
        for (i, v) in [w.force, w.moment].iter().enumerate() {
            self.sum[i] += v;
            self.sum_sq[i] += v.component_mul(v);
        }
    }

    /// Wrenches added.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// The mean wrench (N, N·m); zero when empty.
    pub fn mean(&self) -> Wrench {
        let n = self.n.max(1) as f64;
        Wrench {
            force: self.sum[0] / n,
            moment: self.sum[1] / n,
        }
    }

    /// The standard deviation per axis (N, N·m); zero when empty.
    pub fn std(&self) -> Wrench {
        let n = self.n.max(1) as f64;
        let sd = |i: usize| {
            let mean = self.sum[i] / n;
            (self.sum_sq[i] / n - mean.component_mul(&mean)).map(|v| v.max(0.0).sqrt())
        };
        Wrench {
            force: sd(0),
            moment: sd(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wrench(f: [f64; 3], m: [f64; 3]) -> Wrench {
        Wrench {
            force: Vector3::from(f),
            moment: Vector3::from(m),
        }
    }

    #[test]
    fn mean_and_std_per_axis() {
        let mut s = WrenchStats::default();
        for sign in [-1.0, 1.0, -1.0, 1.0] {
            s.push(&wrench(
                [3.0 + sign, -2.0, 20.0],
                [0.1, 0.0, 0.0 + 0.5 * sign],
            ));
        }
        let (mean, std) = (s.mean(), s.std());
        assert_eq!(s.count(), 4);
        assert!((mean.force - Vector3::new(3.0, -2.0, 20.0)).norm() < 1e-12);
        assert!((std.force - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-9);
        assert!((std.moment - Vector3::new(0.0, 0.0, 0.5)).norm() < 1e-9);
    }

    #[test]
    fn the_offset_is_measured_or_refused_with_the_values() {
        let o = OffsetOptions::default();
        let mut s = WrenchStats::default();
        s.push(&wrench([3.0, -2.0, 20.0], [0.1, 0.2, 0.3]));
        let offset = o.offset(&s).unwrap();
        assert_eq!(offset.force, Vector3::new(3.0, -2.0, 20.0));
        let mut pressed = WrenchStats::default();
        pressed.push(&wrench([0.0, 0.0, 80.0], [0.0; 3]));
        let e = o.offset(&pressed).unwrap_err().to_string();
        assert!(e.contains("80.0 N") && e.contains("--bias"), "{e}");
        assert!(o.offset(&WrenchStats::default()).is_err());
        assert!(OffsetOptions { time: 0.0, ..o }.validate().is_err());
    }
}
