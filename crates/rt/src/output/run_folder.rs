//! The run-folder writer of a real-time run: keeps every tick's [`Sample`] in memory (room for
//! the whole run reserved before it starts, so that the writer thread does not allocate while
//! the loop runs), and builds from them, once the run has ended, what the run folder holds:
//! the time series, the ideal reference and the metrics ([`crate::report::build_output`];
//! Python writes them out as `timeseries.parquet`, `reference.parquet`, `metrics.json`).
//!
//! It is not one of the [`super::Sink`]s: every real-time run has it, the writer thread feeds it
//! first and holds it apart, and its metrics are what the sinks' end events and reports go
//! into.

use hilcontact_core::Plan;

use crate::error::Result;
use crate::report::{build_output, HilOutput, RunOutcome, Sample};

/// Most samples reserved at the start: 2^20 ticks (17 min at 1 kHz); a longer run grows the
/// log as it goes rather than reserving it all at the start.
const RESERVED_SAMPLES: usize = 1 << 20;

/// The samples of a real-time run, in tick order.
#[derive(Debug, Default)]
pub struct RunFolder {
    samples: Vec<Sample>,
}

impl RunFolder {
    /// Room for a run of `ticks` ticks (up to 2^20 reserved at the start).
    pub fn new(ticks: u64) -> Self {
        RunFolder {
            samples: Vec::with_capacity((ticks as usize).min(RESERVED_SAMPLES) + 1),
        }
    }

    /// Keeps one tick's sample (no allocation within the reserved room).
    pub fn push(&mut self, s: &Sample) {
        self.samples.push(*s);
    }

    /// The samples so far.
    pub fn samples(&self) -> &[Sample] {
        &self.samples
    }

    /// The run's time series, reference and metrics (`options`: the run's options, reported
    /// in `metrics.json` `realtime.options`).
    pub fn build(
        &self,
        plan: &Plan,
        options: &impl serde::Serialize,
        outcome: &RunOutcome,
    ) -> Result<HilOutput> {
        build_output(plan, options, &self.samples, outcome)
    }
}
