//! What a sweep keeps of each run: one row of numbers ([`RunSummary`], its columns
//! [`RunSummary::COLUMNS`] with their units), computed from a run's [`Metrics`]. The sweep
//! itself (the grid, the parallel runs, the results file) is `hilcontact.sweep` in Python,
//! which runs the rows through the bindings' `simulate_batch`.

use serde::Serialize;

use crate::metrics::Metrics;
use crate::stop::Status;

/// One column of a table the core produces: name, unit, meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Column {
    /// Column name.
    pub name: &'static str,
    /// SI unit ("" for counts and ratios, "1" for fractions).
    pub unit: &'static str,
    /// What it holds.
    pub doc: &'static str,
}

/// A run in one row: what a sweep keeps of each run ([`RunSummary::COLUMNS`] in order,
/// after `status`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RunSummary {
    /// The run's status.
    pub status: Status,
    /// The numbers, in the order of [`RunSummary::COLUMNS`] (NaN where a run has none).
    pub values: [f64; RunSummary::COLUMNS.len()],
}

impl RunSummary {
    /// The numeric columns of a run's row, after `status`.
    pub const COLUMNS: [Column; 16] = [
        Column {
            name: "diverged_at",
            unit: "s",
            doc: "time the run diverged (NaN if it did not)",
        },
        Column {
            name: "collisions",
            unit: "",
            doc: "HIL collisions",
        },
        Column {
            name: "reference_collisions",
            unit: "",
            doc: "reference collisions",
        },
        Column {
            name: "lost_collisions",
            unit: "",
            doc: "reference collisions the run lost",
        },
        Column {
            name: "extra_collisions",
            unit: "",
            doc: "HIL collisions without a reference collision",
        },
        Column {
            name: "mean_cov",
            unit: "",
            doc: "mean CoV",
        },
        Column {
            name: "worst_cov",
            unit: "",
            doc: "the CoV farthest from 1",
        },
        Column {
            name: "mean_cof",
            unit: "",
            doc: "mean CoF",
        },
        Column {
            name: "worst_cof",
            unit: "",
            doc: "the CoF farthest from 1",
        },
        Column {
            name: "worst_velocity_error",
            unit: "1",
            doc: "largest rebound velocity error |v - v_ref| / |v_ref|",
        },
        Column {
            name: "worst_angular_velocity_error",
            unit: "1",
            doc: "largest angular velocity error |w - w_ref| / |w_ref|",
        },
        Column {
            name: "worst_impulse_ratio",
            unit: "",
            doc: "the impulse ratio farthest from 1",
        },
        Column {
            name: "worst_angular_impulse_ratio",
            unit: "",
            doc: "the angular impulse ratio farthest from 1",
        },
        Column {
            name: "stiffness_error",
            unit: "1",
            doc: "mean |k_hat / k - 1|",
        },
        Column {
            name: "damping_error",
            unit: "N s/m",
            doc: "mean |c_hat - c|",
        },
        Column {
            name: "energy_ratio",
            unit: "",
            doc: "final energy / the reference's",
        },
    ];

    /// The row of a run's metrics.
    pub fn of(m: &Metrics) -> Self {
        let id = m.identification.as_ref();
        let s = &m.summary;
        RunSummary {
            status: m.status,
            values: [
                m.diverged_at.unwrap_or(f64::NAN),
                s.collisions as f64,
                m.reference_collisions.len() as f64,
                m.lost_collisions.len() as f64,
                m.extra_collisions.len() as f64,
                s.mean_cov,
                s.worst_cov,
                s.mean_cof,
                s.worst_cof,
                s.worst_velocity_error,
                s.worst_angular_velocity_error,
                s.worst_impulse_ratio,
                s.worst_angular_impulse_ratio,
                id.map_or(f64::NAN, |i| i.stiffness_error),
                id.map_or(f64::NAN, |i| i.damping_error),
                m.energy.r#final / m.energy.reference_final,
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn run_summary_has_a_value_per_column() {
        let names: Vec<&str> = RunSummary::COLUMNS.iter().map(|c| c.name).collect();
        let mut sorted = names.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), names.len(), "duplicate column names");
    }
}
