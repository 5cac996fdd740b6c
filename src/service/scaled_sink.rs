//! One part of a job as a whole job to the code that runs it: a calibration captures (the first
//! half of its progress), then diagnoses (the second), and each step reports 0 to 1 as it would
//! alone.

use crate::experiment::RunSink;
use crate::run_event::EventKind;
use serde_json::Value;
use std::path::PathBuf;

/// `inner`, with every progress p reported as `from + span·p`.
pub struct ScaledSink<'a> {
    pub inner: &'a dyn RunSink,
    pub from: f64,
    pub span: f64,
}

impl RunSink for ScaledSink<'_> {
    fn event(&self, kind: EventKind, progress: f64, message: &str, data: Value) {
        self.inner
            .event(kind, self.from + self.span * progress, message, data)
    }

    fn write(&self, rel: &str, bytes: &[u8]) -> Result<PathBuf, String> {
        self.inner.write(rel, bytes)
    }

    fn cancelled(&self) -> bool {
        self.inner.cancelled()
    }
}
