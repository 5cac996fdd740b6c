//! The physics every simulated controller shares: one axis that travels at a constant speed,
//! settles, must be homed after power-up, keeps to its travel and stops on a limit switch.

use crate::bench::{Motion, SharedBench};
use ffdic_hw::StagePosition;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LimitSide {
    Negative,
    Positive,
}

/// One movement: from, to, leaving at `t0`, arriving at `t1`, still until `t1 + settle`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Leg {
    pub from_mm: f64,
    pub to_mm: f64,
    pub t0: Instant,
    pub t1: Instant,
    pub homing: bool,
    /// The leg ends early on this limit switch.
    pub hits: Option<LimitSide>,
}

/// Why a controller refuses a move.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Refusal {
    NotHomed,
    OutOfTravel,
}

#[derive(Debug)]
pub(crate) struct SimAxis {
    pub address: u8,
    pub travel_mm: (f64, f64),
    pub speed_mm_per_s: f64,
    pub settle: Duration,
    pub homed: bool,
    /// A limit switch trips here (fault injection), inside the travel.
    pub switch_mm: Option<f64>,
    /// The axis rests on a limit switch it ran into.
    pub at_limit: Option<LimitSide>,
    rest_mm: f64,
    leg: Option<Leg>,
}

impl SimAxis {
    pub fn new(
        address: u8,
        travel_mm: (f64, f64),
        speed_mm_per_s: f64,
        settle: Duration,
        power_up_mm: f64,
    ) -> Self {
        Self {
            address,
            travel_mm,
            speed_mm_per_s,
            settle,
            homed: false,
            switch_mm: None,
            at_limit: None,
            rest_mm: power_up_mm,
            leg: None,
        }
    }

    pub fn position_mm(&self, now: Instant) -> f64 {
        match self.leg {
            Some(l) if now < l.t1 => {
                let span = (l.t1 - l.t0).as_secs_f64().max(1e-12);
                let f = ((now - l.t0).as_secs_f64() / span).clamp(0.0, 1.0);
                l.from_mm + f * (l.to_mm - l.from_mm)
            }
            Some(l) => l.to_mm,
            None => self.rest_mm,
        }
    }

    /// The leg under way (moving or settling), if any.
    pub fn leg(&self) -> Option<Leg> {
        self.leg
    }

    /// Where the axis will come to rest and when it arrives there.
    pub fn destination(&self, now: Instant) -> (f64, Instant) {
        match self.leg {
            Some(l) => (l.to_mm, l.t1.max(now)),
            None => (self.rest_mm, now),
        }
    }

    /// Ends the leg once it has settled; returns it so a controller can announce completion.
    pub fn finish(&mut self, now: Instant) -> Option<Leg> {
        let l = self.leg?;
        if now < l.t1 + self.settle {
            return None;
        }
        self.leg = None;
        self.rest_mm = l.to_mm;
        if l.homing {
            self.homed = true;
        }
        self.at_limit = l.hits;
        Some(l)
    }

    pub fn start_move(&mut self, target_mm: f64, now: Instant) -> Result<(), Refusal> {
        self.finish(now);
        if !self.homed || self.leg.is_some_and(|l| l.homing) {
            return Err(Refusal::NotHomed);
        }
        let (lo, hi) = self.travel_mm;
        if !(target_mm >= lo && target_mm <= hi) {
            return Err(Refusal::OutOfTravel);
        }
        let from_mm = self.position_mm(now);
        let (mut to_mm, mut hits) = (target_mm, None);
        if let Some(s) = self.switch_mm {
            if from_mm <= s && s < target_mm {
                (to_mm, hits) = (s, Some(LimitSide::Positive));
            } else if target_mm < s && s <= from_mm {
                (to_mm, hits) = (s, Some(LimitSide::Negative));
            }
        }
        self.begin(from_mm, to_mm, now, false, hits);
        Ok(())
    }

    /// Homing runs to the reference at 0 mm; the axis is homed once it has settled there.
    pub fn start_home(&mut self, now: Instant) {
        let from_mm = self.position_mm(now);
        self.homed = false;
        self.begin(from_mm, 0.0, now, true, None);
    }

    /// Stops at once where the axis is; returns whether it was under way. A stopped homing run
    /// leaves the axis unreferenced.
    pub fn stop(&mut self, now: Instant) -> bool {
        let was = self.leg.is_some();
        self.rest_mm = self.position_mm(now);
        self.leg = None;
        was
    }

    fn begin(
        &mut self,
        from_mm: f64,
        to_mm: f64,
        now: Instant,
        homing: bool,
        hits: Option<LimitSide>,
    ) {
        let travel = Duration::from_secs_f64((to_mm - from_mm).abs() / self.speed_mm_per_s);
        self.at_limit = None;
        self.leg = Some(Leg {
            from_mm,
            to_mm,
            t0: now,
            t1: now + travel,
            homing,
            hits,
        });
    }
}

/// Tells a shared bench where the simulated axes are heading, so a mock camera sees the motion.
/// The bench holds one straight-line motion: exact for one axis moving, an approximation when
/// both move with different arrival times (re-based on every call, so the error stays small).
pub(crate) fn sync_bench(bench: &SharedBench, axes: &[SimAxis], now: Instant) {
    let mut b = bench.lock().expect("bench lock");
    let current = b.position_at(now);
    let mut start = current;
    let mut target = current;
    let mut arrival = now;
    for (i, axis) in axes.iter().enumerate().take(2) {
        let (to_mm, t1) = axis.destination(now);
        let at_mm = axis.position_mm(now);
        arrival = arrival.max(t1);
        if i == 0 {
            (start.x_mm, target.x_mm) = (at_mm, to_mm);
        } else {
            (start.y_mm, target.y_mm) = (at_mm, to_mm);
        }
    }
    if arrival > now {
        b.motion = Some(Motion {
            start,
            target,
            t0: now,
            t1: arrival,
        });
    } else {
        b.motion = None;
        b.resting = StagePosition {
            x_mm: target.x_mm,
            y_mm: target.y_mm,
        };
    }
}
