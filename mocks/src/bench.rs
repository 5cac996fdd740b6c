use ffdic_hw::StagePosition;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// A move under way: from `start` to `target`, leaving at `t0` and arriving at `t1`.
#[derive(Clone, Copy, Debug)]
pub struct Motion {
    pub start: StagePosition,
    pub target: StagePosition,
    pub t0: Instant,
    pub t1: Instant,
}

/// The physical state the mock stage changes and the mock camera sees.
#[derive(Debug)]
pub struct BenchState {
    pub motion: Option<Motion>,
    pub resting: StagePosition,
}

impl BenchState {
    /// Where the target is now (linear motion between start and target).
    pub fn position_at(&self, now: Instant) -> StagePosition {
        match self.motion {
            Some(m) if now < m.t1 => {
                let span = (m.t1 - m.t0).as_secs_f64().max(1e-9);
                let f = ((now - m.t0).as_secs_f64() / span).clamp(0.0, 1.0);
                StagePosition {
                    x_mm: m.start.x_mm + f * (m.target.x_mm - m.start.x_mm),
                    y_mm: m.start.y_mm + f * (m.target.y_mm - m.start.y_mm),
                }
            }
            Some(m) => m.target,
            None => self.resting,
        }
    }
}

/// Bench state shared by a mock stage and a mock camera.
pub type SharedBench = Arc<Mutex<BenchState>>;

pub fn new_bench() -> SharedBench {
    Arc::new(Mutex::new(BenchState {
        motion: None,
        resting: StagePosition::default(),
    }))
}
