//! Dropped frames from V4L2 buffer sequence numbers.
//!
//! `v4l2_buffer.sequence` counts frames (V4L2 UAPI "struct v4l2_buffer"): a driver that had no
//! free buffer when a frame arrived drops it and the next buffer's sequence skips a number. The
//! field is a u32 and wraps; drivers restart it at VIDIOC_STREAMON.

/// What one sequence number says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Observation {
    /// The sequence unwrapped to 64 bits since the baseline (`frame_id` of the frame).
    pub frame_id: u64,
    /// Frames the device counted but never delivered, between the previous buffer and this one.
    pub missing: u64,
    /// The sequence did not move forward (repeat, or a driver restart): taken as a new baseline
    /// rather than as ~4 billion lost frames.
    pub restarted: bool,
}

/// Counts gaps in successive sequence numbers. The first number of a session sets the baseline.
#[derive(Clone, Debug, Default)]
pub struct SequenceTracker {
    last: Option<u32>,
    frame_id: u64,
    missing_total: u64,
}

/// Forward steps larger than this are read as the sequence going backwards: half the u32 range,
/// as in serial-number arithmetic (RFC 1982). No device drops 2^31 frames between two buffers.
const MAX_FORWARD_STEP: u32 = 1 << 31;

impl SequenceTracker {
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the baseline: the next number starts a new session (call at STREAMON, where
    /// drivers restart the count). Totals are kept.
    pub fn begin_session(&mut self) {
        self.last = None;
    }

    /// Takes the sequence number of the next dequeued buffer, good or failed.
    pub fn observe(&mut self, sequence: u32) -> Observation {
        let Some(last) = self.last else {
            self.last = Some(sequence);
            self.frame_id = u64::from(sequence);
            return Observation {
                frame_id: self.frame_id,
                missing: 0,
                restarted: false,
            };
        };
        self.last = Some(sequence);
        let step = sequence.wrapping_sub(last);
        if step == 0 || step >= MAX_FORWARD_STEP {
            self.frame_id = u64::from(sequence);
            return Observation {
                frame_id: self.frame_id,
                missing: 0,
                restarted: true,
            };
        }
        let missing = u64::from(step - 1);
        self.missing_total += missing;
        self.frame_id += u64::from(step);
        Observation {
            frame_id: self.frame_id,
            missing,
            restarted: false,
        }
    }

    /// Frames missing in all sessions so far.
    pub fn missing_total(&self) -> u64 {
        self.missing_total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn missing_of(seq: &[u32]) -> Vec<u64> {
        let mut t = SequenceTracker::new();
        seq.iter().map(|&s| t.observe(s).missing).collect()
    }

    #[test]
    fn first_frame_sets_the_baseline() {
        let mut t = SequenceTracker::new();
        let o = t.observe(1000);
        assert_eq!((o.frame_id, o.missing, o.restarted), (1000, 0, false));
        assert_eq!(t.observe(1001).missing, 0);
        assert_eq!(t.missing_total(), 0);
    }

    #[test]
    fn gaps_count_the_skipped_numbers() {
        assert_eq!(missing_of(&[0, 1, 2, 5, 6, 8]), vec![0, 0, 0, 2, 0, 1]);
        let mut t = SequenceTracker::new();
        for s in [0, 1, 2, 5, 6, 8] {
            t.observe(s);
        }
        assert_eq!(t.missing_total(), 3);
    }

    #[test]
    fn wrap_around_is_a_step_not_a_gap() {
        assert_eq!(
            missing_of(&[u32::MAX - 1, u32::MAX, 0, 1]),
            vec![0, 0, 0, 0]
        );
        // MAX-1 → 1 skips MAX and 0.
        assert_eq!(missing_of(&[u32::MAX - 1, 1]), vec![0, 2]);
        let mut t = SequenceTracker::new();
        t.observe(u32::MAX);
        let o = t.observe(2);
        assert_eq!(o.frame_id, u64::from(u32::MAX) + 3);
        assert_eq!(o.missing, 2);
    }

    #[test]
    fn going_backwards_or_repeating_is_a_restart() {
        let mut t = SequenceTracker::new();
        t.observe(500);
        let o = t.observe(0);
        assert!(o.restarted);
        assert_eq!((o.missing, o.frame_id), (0, 0));
        assert!(t.observe(0).restarted);
        assert_eq!(t.observe(3).missing, 2);
        assert_eq!(t.missing_total(), 2);
    }

    #[test]
    fn sessions_restart_the_baseline_and_keep_totals() {
        let mut t = SequenceTracker::new();
        t.observe(0);
        t.observe(4);
        t.begin_session();
        let o = t.observe(100);
        assert_eq!((o.missing, o.restarted, o.frame_id), (0, false, 100));
        assert_eq!(t.missing_total(), 3);
    }
}
