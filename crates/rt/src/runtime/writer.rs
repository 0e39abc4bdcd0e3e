//! The writer thread: drains the loop's ring buffer into the run folder and the run's outputs
//! ([`crate::output`]), and makes the loop's live events from its shared status. It keeps
//! normal scheduling, may allocate and block (a sink's file), and never slows the loop: a full
//! ring drops samples (counted), it never blocks the tick.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use hilcontact_core::Plan;

use super::status::SharedStatus;
use crate::error::{Result, RtError};
use crate::options::RuntimeOptions;
use crate::output::events::EventWatch;
use crate::output::run_folder::RunFolder;
use crate::output::{Outputs, RunInfo};
use crate::report::Sample;
use crate::safety::StopKind;

/// The run's outputs that `options` asks for (an MCAP recording with `mcap`, ...): each
/// created (or the start refused, naming it) before anything else is opened.
pub(super) fn open_outputs(plan: &Plan, options: &RuntimeOptions) -> Result<Outputs> {
    let value =
        serde_json::to_value(options).map_err(|e| RtError::io_other("options", e.to_string()))?;
    Outputs::open(plan, &RunInfo::new(plan, true), &value)
}

/// Starts the writer thread: it drains the loop's ring buffer every 5 ms into the run folder
/// and the outputs, with the loop's events (its counters that grew, the stop) after each
/// drain; once the loop has ended (the ring abandoned) and the ring is empty, it hands both
/// back. It keeps normal scheduling and never runs on the loop thread. `keep`: whether the
/// samples go into the run folder (a calibration keeps none: it writes no run folder).
pub(super) fn spawn_writer(
    mut consumer: rtrb::Consumer<Sample>,
    shared: Arc<SharedStatus>,
    mut run_folder: RunFolder,
    keep: bool,
    mut outputs: Outputs,
) -> Result<JoinHandle<(RunFolder, Outputs)>> {
    let mut events = EventWatch::new();
    std::thread::Builder::new()
        .name("hil-writer".into())
        .spawn(move || {
            loop {
                let abandoned = consumer.is_abandoned();
                // read before draining: every sample up to the stop is in the ring then
                let stop = StopKind::from_code(shared.stop_code.load(Ordering::Acquire));
                while let Ok(s) = consumer.pop() {
                    if keep {
                        run_folder.push(&s);
                    }
                    outputs.sample(&s);
                }
                if !outputs.is_empty() {
                    events.after_drain(&mut outputs, &shared.counters(), stop);
                }
                if abandoned {
                    break; // drained after the producer was dropped: complete
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            (run_folder, outputs)
        })
        .map_err(|e| RtError::io("writer thread", &e))
}
