//! One dequeued V4L2 buffer into one `Frame`, or the reason it is not one, with the stream's
//! counters. Pure: the camera feeds it what VIDIOC_DQBUF returned, tests feed it synthetic buffers.

use crate::format::V4l2Format;
use crate::sequence::SequenceTracker;
use crate::unpack::{unpack_format, UnpackError};
use ffdic_hw::{CameraCounters, Frame};
use std::time::SystemTime;

/// `V4L2_BUF_FLAG_ERROR`: "the buffer was dequeued successfully, although the data might have
/// been corrupted" (V4L2 UAPI "Buffer Flags").
pub const BUF_FLAG_ERROR: u32 = 0x0000_0040;
const BUF_FLAG_TIMESTAMP_MASK: u32 = 0x0000_e000;
const BUF_FLAG_TIMESTAMP_MONOTONIC: u32 = 0x0000_2000;

/// The negotiated image layout (VIDIOC_S_FMT's answer).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ActiveFormat {
    pub format: V4l2Format,
    pub width: usize,
    pub height: usize,
    pub bytes_per_line: usize,
}

impl ActiveFormat {
    /// Bytes a complete image occupies (`None` only for absurd sizes).
    pub fn image_bytes(&self) -> Option<usize> {
        self.format
            .image_bytes(self.width, self.height, self.bytes_per_line)
    }
}

/// The fields of `struct v4l2_buffer` that decide a frame's fate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BufferMeta {
    pub sequence: u32,
    pub flags: u32,
    pub bytes_used: u32,
    pub timestamp_sec: i64,
    pub timestamp_usec: i64,
}

impl BufferMeta {
    /// The capture time in ns of CLOCK_MONOTONIC, when the driver says that is what it gave.
    pub fn monotonic_ns(&self) -> Option<u64> {
        if self.flags & BUF_FLAG_TIMESTAMP_MASK != BUF_FLAG_TIMESTAMP_MONOTONIC {
            return None;
        }
        let sec = u64::try_from(self.timestamp_sec).ok()?;
        let usec = u64::try_from(self.timestamp_usec).ok()?;
        sec.checked_mul(1_000_000_000)?.checked_add(usec * 1_000)
    }
}

/// Why a buffer holds no usable frame. Each counts as a failed frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadBuffer {
    #[error("frame {sequence}: the driver flagged the buffer as corrupted (V4L2_BUF_FLAG_ERROR)")]
    ErrorFlag { sequence: u32 },
    #[error("frame {sequence}: {bytes_used} bytes used, a full image needs {need_bytes}")]
    Short {
        sequence: u32,
        bytes_used: usize,
        need_bytes: usize,
    },
    #[error(transparent)]
    Unpack(#[from] UnpackError),
}

/// What became of one buffer.
#[derive(Debug, Clone, PartialEq)]
pub enum Taken {
    Frame(Frame),
    /// Dropped on purpose after stream start (`discard_frames`).
    Discarded,
    Failed(BadBuffer),
}

/// Turns buffers into frames and keeps the counters the camera reports.
#[derive(Debug, Default)]
pub struct Intake {
    tracker: SequenceTracker,
    counters: CameraCounters,
    discard_left: u32,
}

impl Intake {
    pub fn new() -> Self {
        Self::default()
    }

    /// Call at every VIDIOC_STREAMON: drivers restart the sequence there, and the first
    /// `discard` frames after it are dropped.
    pub fn begin_session(&mut self, discard: u32) {
        self.tracker.begin_session();
        self.discard_left = discard;
    }

    /// Judges one dequeued buffer: `bytes` is the whole mapped buffer, `meta` what DQBUF said.
    pub fn take(&mut self, format: &ActiveFormat, bytes: &[u8], meta: &BufferMeta) -> Taken {
        // Every buffer, good or not, moves the sequence: only numbers never seen are missing.
        let seen = self.tracker.observe(meta.sequence);
        self.counters.failed += seen.missing;
        match self.judge(format, bytes, meta, seen.frame_id) {
            Ok(_) if self.discard_left > 0 => {
                self.discard_left -= 1;
                Taken::Discarded
            }
            Ok(frame) => {
                self.counters.completed += 1;
                Taken::Frame(frame)
            }
            Err(bad) => {
                self.counters.failed += 1;
                Taken::Failed(bad)
            }
        }
    }

    fn judge(
        &self,
        format: &ActiveFormat,
        bytes: &[u8],
        meta: &BufferMeta,
        frame_id: u64,
    ) -> Result<Frame, BadBuffer> {
        let sequence = meta.sequence;
        if meta.flags & BUF_FLAG_ERROR != 0 {
            return Err(BadBuffer::ErrorFlag { sequence });
        }
        // bytesused, not the buffer length, says how much the driver wrote: a truncated frame
        // in a full-size buffer would otherwise pass with stale data from an earlier frame.
        let bytes_used = (meta.bytes_used as usize).min(bytes.len());
        let need_bytes = format.image_bytes().unwrap_or(usize::MAX);
        if bytes_used < need_bytes {
            return Err(BadBuffer::Short {
                sequence,
                bytes_used,
                need_bytes,
            });
        }
        let data = unpack_format(
            format.format,
            &bytes[..bytes_used],
            format.width,
            format.height,
            format.bytes_per_line,
        )?;
        Ok(Frame {
            width: format.width,
            height: format.height,
            bit_depth: format.format.bit_depth(),
            data,
            frame_id,
            device_timestamp_ns: meta.monotonic_ns(),
            host_timestamp: SystemTime::now(),
        })
    }

    pub fn counters(&self) -> CameraCounters {
        self.counters
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const Y12P_4X2: ActiveFormat = ActiveFormat {
        format: V4l2Format::Y12P,
        width: 4,
        height: 2,
        bytes_per_line: 8,
    };

    /// 4x2 Y12P, stride 8: 4095, 0x123, 0x800, 1 / 0, 0, 0x010, 0x01F (see unpack's tests).
    const BYTES: [u8; 16] = [
        0xFF, 0x12, 0x3F, 0x80, 0x00, 0x10, 0x55, 0x55, //
        0x00, 0x00, 0x00, 0x01, 0x01, 0xF0, 0x55, 0x55,
    ];

    fn meta(sequence: u32) -> BufferMeta {
        BufferMeta {
            sequence,
            flags: BUF_FLAG_TIMESTAMP_MONOTONIC,
            bytes_used: 16,
            timestamp_sec: 12,
            timestamp_usec: 345_678,
        }
    }

    #[test]
    fn a_good_buffer_is_a_frame() {
        let mut intake = Intake::new();
        let Taken::Frame(f) = intake.take(&Y12P_4X2, &BYTES, &meta(7)) else {
            panic!("not a frame");
        };
        assert_eq!((f.width, f.height, f.bit_depth, f.frame_id), (4, 2, 12, 7));
        assert_eq!(f.data, vec![4095, 0x123, 0x800, 1, 0, 0, 0x010, 0x01F]);
        assert_eq!(f.device_timestamp_ns, Some(12_345_678_000));
        assert_eq!(intake.counters().completed, 1);
        assert_eq!(intake.counters().failed, 0);
    }

    #[test]
    fn error_flag_and_short_bytesused_fail_without_a_frame() {
        let mut intake = Intake::new();
        let mut m = meta(0);
        m.flags |= BUF_FLAG_ERROR;
        assert_eq!(
            intake.take(&Y12P_4X2, &BYTES, &m),
            Taken::Failed(BadBuffer::ErrorFlag { sequence: 0 })
        );
        // The image needs 8 + 6 = 14 bytes; 13 used is short even in a 16-byte buffer.
        let mut m = meta(1);
        m.bytes_used = 13;
        assert!(matches!(
            intake.take(&Y12P_4X2, &BYTES, &m),
            Taken::Failed(BadBuffer::Short {
                bytes_used: 13,
                need_bytes: 14,
                ..
            })
        ));
        // bytesused larger than the mapping is capped by the mapping.
        let mut m = meta(2);
        m.bytes_used = 1 << 20;
        assert!(matches!(
            intake.take(&Y12P_4X2, &BYTES[..10], &m),
            Taken::Failed(BadBuffer::Short { bytes_used: 10, .. })
        ));
        // 14 bytes is enough: the last line needs no padding.
        let mut m = meta(3);
        m.bytes_used = 14;
        assert!(matches!(
            intake.take(&Y12P_4X2, &BYTES, &m),
            Taken::Frame(_)
        ));
        let c = intake.counters();
        assert_eq!((c.completed, c.failed, c.missing_packets), (1, 3, 0));
    }

    #[test]
    fn sequence_gaps_count_as_failed_frames() {
        let mut intake = Intake::new();
        for s in [10, 11, 14, 15] {
            assert!(matches!(
                intake.take(&Y12P_4X2, &BYTES, &meta(s)),
                Taken::Frame(_)
            ));
        }
        let c = intake.counters();
        assert_eq!((c.completed, c.failed), (4, 2));
    }

    #[test]
    fn sessions_discard_their_first_frames_and_restart_the_sequence() {
        let mut intake = Intake::new();
        intake.take(&Y12P_4X2, &BYTES, &meta(40));
        intake.begin_session(2);
        assert_eq!(intake.take(&Y12P_4X2, &BYTES, &meta(0)), Taken::Discarded);
        assert_eq!(intake.take(&Y12P_4X2, &BYTES, &meta(1)), Taken::Discarded);
        let Taken::Frame(f) = intake.take(&Y12P_4X2, &BYTES, &meta(2)) else {
            panic!("not a frame");
        };
        assert_eq!(f.frame_id, 2);
        let c = intake.counters();
        assert_eq!((c.completed, c.failed), (2, 0));
    }

    #[test]
    fn timestamps_only_when_monotonic() {
        let mut m = meta(0);
        m.flags = 0; // V4L2_BUF_FLAG_TIMESTAMP_UNKNOWN
        assert_eq!(m.monotonic_ns(), None);
        m.flags = 0x4000; // V4L2_BUF_FLAG_TIMESTAMP_COPY: the application's, not the sensor's
        assert_eq!(m.monotonic_ns(), None);
        m.flags = BUF_FLAG_TIMESTAMP_MONOTONIC;
        m.timestamp_sec = -1;
        assert_eq!(m.monotonic_ns(), None);
    }
}
