use crate::bench::{Motion, SharedBench};
use ffdic_hw::{HwError, HwResult, Stage, StageInfo, StagePosition};
use std::time::{Duration, Instant};

/// The mock stage's step, mm (0.1 µm: a microstepping stage's): it lands on whole steps, as a
/// stage driven in device units does.
pub const RESOLUTION_MM: f64 = 1e-4;

/// Faults to inject into the mock stage.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageFaults {
    /// Every call fails as if the cable were pulled.
    pub disconnected: bool,
    /// The controller stops answering: calls time out.
    pub silent: bool,
}

/// A translation stage with travel speed, settling time, homing required after power-up and
/// travel limits.
pub struct MockStage {
    info: StageInfo,
    bench: SharedBench,
    speed_mm_per_s: f64,
    settle: Duration,
    homed: bool,
    pub faults: StageFaults,
}

impl MockStage {
    pub fn new(bench: SharedBench, speed_mm_per_s: f64, settle: Duration) -> Self {
        Self {
            info: StageInfo {
                model: "ffdic mock XY stage".into(),
                axes: 2,
                travel_x_mm: (-25.0, 25.0),
                travel_y_mm: (-25.0, 25.0),
                resolution_mm: RESOLUTION_MM,
            },
            bench,
            speed_mm_per_s,
            settle,
            homed: false,
            faults: StageFaults::default(),
        }
    }

    fn check(&self, what: &str) -> HwResult<()> {
        if self.faults.disconnected {
            return Err(HwError::Disconnected(format!("mock stage during {what}")));
        }
        if self.faults.silent {
            return Err(HwError::Timeout {
                what: format!("mock stage {what}"),
                after_ms: 0,
            });
        }
        Ok(())
    }
}

impl Stage for MockStage {
    fn info(&self) -> &StageInfo {
        &self.info
    }

    fn home(&mut self, _timeout: Duration) -> HwResult<()> {
        self.check("home")?;
        let mut b = self.bench.lock().expect("bench lock");
        b.motion = None;
        b.resting = StagePosition::default();
        self.homed = true;
        Ok(())
    }

    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()> {
        self.check("move")?;
        if !self.homed {
            return Err(HwError::NotReferenced(
                "stage not referenced: home it first".into(),
            ));
        }
        for (what, v, (lo, hi)) in [
            ("x_mm", target.x_mm, self.info.travel_x_mm),
            ("y_mm", target.y_mm, self.info.travel_y_mm),
        ] {
            if !(v >= lo && v <= hi) {
                return Err(HwError::OutOfRange {
                    what: what.into(),
                    value: v,
                    min: lo,
                    max: hi,
                });
            }
        }
        let target = StagePosition {
            x_mm: self.info.on_grid(target.x_mm),
            y_mm: self.info.on_grid(target.y_mm),
        };
        let now = Instant::now();
        let mut b = self.bench.lock().expect("bench lock");
        let start = b.position_at(now);
        let dist = ((target.x_mm - start.x_mm).powi(2) + (target.y_mm - start.y_mm).powi(2)).sqrt();
        let travel = Duration::from_secs_f64(dist / self.speed_mm_per_s);
        b.motion = Some(Motion {
            start,
            target,
            t0: now,
            t1: now + travel,
        });
        Ok(())
    }

    fn position(&mut self) -> HwResult<StagePosition> {
        self.check("position")?;
        Ok(self
            .bench
            .lock()
            .expect("bench lock")
            .position_at(Instant::now()))
    }

    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition> {
        self.check("wait")?;
        let arrival = self
            .bench
            .lock()
            .expect("bench lock")
            .motion
            .map(|m| m.t1 + self.settle);
        if let Some(t) = arrival {
            let now = Instant::now();
            if t > now {
                if t - now > timeout {
                    std::thread::sleep(timeout);
                    return Err(HwError::Timeout {
                        what: "stage settling".into(),
                        after_ms: timeout.as_millis() as u64,
                    });
                }
                std::thread::sleep(t - now);
            }
        }
        let mut b = self.bench.lock().expect("bench lock");
        let p = b.position_at(Instant::now());
        b.motion = None;
        b.resting = p;
        Ok(p)
    }

    fn stop(&mut self) -> HwResult<()> {
        self.check("stop")?;
        let mut b = self.bench.lock().expect("bench lock");
        let p = b.position_at(Instant::now());
        b.motion = None;
        b.resting = p;
        Ok(())
    }
}
