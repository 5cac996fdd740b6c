//! `V4l2Camera`: one V4L2 video capture node behind `ffdic_hw::Camera`.
//!
//! Streaming runs only inside `acquire`: VIDIOC_STREAMON, collect, VIDIOC_STREAMOFF, so a frame
//! never predates the call (the bench moves the stage between calls; a running stream would hand
//! out frames exposed before the move). The mmap buffers live across calls and are released only
//! when the format changes, since VIDIOC_S_FMT fails with EBUSY while buffers are allocated
//! (V4L2 UAPI "Streaming I/O (Memory Mapping)" and VIDIOC_REQBUFS).
//!
//! What V4L2 cannot express is `Unsupported`, never approximated: software triggers, binning,
//! decimation and ROIs other than the full frame (cropping needs VIDIOC_S_SELECTION, not done).

use crate::config::V4l2Config;
use crate::controls::{
    exposure_from_device, exposure_to_device, gain_to_device, CID_EXPOSURE_ABSOLUTE,
    CID_EXPOSURE_AUTO, EXPOSURE_MANUAL,
};
use crate::device_controls::{self as controls, Controls};
use crate::error::map_io;
use crate::format::{fourcc_name, V4l2Format};
use crate::intake::{ActiveFormat, BadBuffer, BufferMeta, Intake, Taken};
use ffdic_hw::{
    Camera, CameraCounters, CameraInfo, CameraSettings, Frame, HwError, HwResult, PixelFormat,
    SensorRoi, TriggerMode,
};
use std::io;
use std::time::{Duration, Instant};
use v4l::buffer::Type;
use v4l::capability::Flags as CapFlags;
use v4l::framesize::FrameSizeEnum;
use v4l::io::mmap::Stream as MmapStream;
use v4l::io::traits::{CaptureStream, Stream as _};
use v4l::video::Capture;
use v4l::{Device, Format, FourCC};

pub struct V4l2Camera {
    config: V4l2Config,
    device: Device,
    /// The mmap buffers; `None` until the first acquire and after a format change.
    stream: Option<MmapStream<'static>>,
    info: CameraInfo,
    /// The formats the device offers that this driver decodes.
    offered: Vec<V4l2Format>,
    active: ActiveFormat,
    controls: Controls,
    settings: CameraSettings,
    intake: Intake,
}

impl V4l2Camera {
    /// Opens a node given by path (`"/dev/video0"`, defaults for the rest) or by a whole
    /// `&V4l2Config`.
    pub fn open(source: impl Into<V4l2Config>) -> HwResult<Self> {
        Self::with_config(source.into())
    }

    /// Opens the node, checks it can stream a monochrome format, and sets the full sensor size
    /// in the current format (or the deepest one offered when the current one is not
    /// monochrome). Exposure and gain are left as they are until the first `apply`.
    pub fn with_config(config: V4l2Config) -> HwResult<Self> {
        config.validate()?;
        let path = config.device.display().to_string();
        let device =
            Device::with_path(&config.device).map_err(|e| map_io(&format!("open {path}"), &e))?;
        let caps = device.query_caps().map_err(|e| {
            map_io(
                &format!("VIDIOC_QUERYCAP on {path} (not a V4L2 device?)"),
                &e,
            )
        })?;
        // device_caps of this node (V4L2 UAPI VIDIOC_QUERYCAP): a multi-planar-only or
        // output-only node cannot be streamed with single-planar capture buffers.
        if !caps
            .capabilities
            .contains(CapFlags::VIDEO_CAPTURE | CapFlags::STREAMING)
        {
            return Err(HwError::Unsupported(format!(
                "{path} ({}) is not a single-planar video capture node with streaming I/O",
                caps.card
            )));
        }
        let all_codes: Vec<u32> = device
            .enum_formats()
            .map_err(|e| map_io("VIDIOC_ENUM_FMT", &e))?
            .iter()
            .map(|d| u32::from(d.fourcc))
            .collect();
        let offered: Vec<V4l2Format> = all_codes
            .iter()
            .filter_map(|&c| V4l2Format::from_fourcc(c))
            .collect();
        if offered.is_empty() {
            let names: Vec<String> = all_codes.iter().map(|&c| fourcc_name(c)).collect();
            return Err(HwError::Unsupported(format!(
                "{path} offers none of GREY, Y10, Y12, Y16, Y10P, Y12P (it offers: {})",
                names.join(", ")
            )));
        }
        let current = device.format().map_err(|e| map_io("VIDIOC_G_FMT", &e))?;
        let (sensor_width, sensor_height) =
            largest_frame_size(&device, &offered).unwrap_or((current.width, current.height));
        let mut pixel_formats: Vec<PixelFormat> = Vec::new();
        for f in &offered {
            if !pixel_formats.contains(&f.pixel_format()) {
                pixel_formats.push(f.pixel_format());
            }
        }
        pixel_formats.sort_by_key(|p| p.bit_depth());
        let info = CameraInfo {
            // V4L2 names the driver and the card, not a vendor or a serial number; bus_info
            // (e.g. "usb-0000:00:14.0-2") is the closest thing to an identity it gives.
            vendor: caps.driver.clone(),
            model: caps.card.clone(),
            serial: caps.bus.clone(),
            sensor_width,
            sensor_height,
            pixel_formats,
            hardware_binning: false,
            hardware_decimation: false,
            hardware_schemes: Vec::new(),
            // V4L2 reports the control's range per control query; exposure is optional there.
            exposure_range_us: None,
        };
        let start_format = V4l2Format::from_fourcc(u32::from(current.fourcc))
            .filter(|f| offered.contains(f))
            .or_else(|| offered.iter().copied().max_by_key(|f| f.bit_depth()))
            .expect("offered is not empty");
        let mut cam = Self {
            config,
            device,
            stream: None,
            info,
            offered,
            active: ActiveFormat {
                format: start_format,
                width: 0,
                height: 0,
                bytes_per_line: 0,
            },
            controls: Controls::default(),
            settings: CameraSettings::default(),
            intake: Intake::new(),
        };
        cam.set_format(start_format)?;
        cam.settings = cam.read_settings()?;
        Ok(cam)
    }

    /// The negotiated layout of the frames `acquire` returns.
    pub fn active_format(&self) -> ActiveFormat {
        self.active
    }

    pub fn config(&self) -> &V4l2Config {
        &self.config
    }

    /// VIDIOC_S_FMT at the full sensor size; refreshes the control ranges (they can depend on
    /// the sensor mode).
    fn set_format(&mut self, format: V4l2Format) -> HwResult<()> {
        // Buffers of the old format must go first: S_FMT is EBUSY while any are allocated.
        self.stream = None;
        let want = Format::new(
            self.info.sensor_width,
            self.info.sensor_height,
            FourCC::from(format.fourcc()),
        );
        let got = self
            .device
            .set_format(&want)
            .map_err(|e| map_io(&format!("VIDIOC_S_FMT {format}"), &e))?;
        // S_FMT may substitute another format rather than fail (V4L2 UAPI VIDIOC_G_FMT: "drivers
        // should not return an error code unless the type field is invalid").
        let got_code = u32::from(got.fourcc);
        if got_code != format.fourcc() {
            return Err(HwError::Unsupported(format!(
                "asked {} for {format}, it set {}",
                self.info.model,
                fourcc_name(got_code)
            )));
        }
        let active = ActiveFormat {
            format,
            width: got.width as usize,
            height: got.height as usize,
            bytes_per_line: got.stride as usize,
        };
        let line_bytes = format.line_bytes(active.width).unwrap_or(usize::MAX);
        if active.bytes_per_line < line_bytes {
            return Err(HwError::Protocol(format!(
                "driver reports {} bytes per line for a {} px {format} line of {line_bytes} bytes",
                active.bytes_per_line, active.width
            )));
        }
        self.active = active;
        self.settings.pixel_format = format.pixel_format();
        self.controls =
            Controls::discover(&self.device).map_err(|e| map_io("VIDIOC_QUERY_EXT_CTRL", &e))?;
        Ok(())
    }

    /// What the device uses now, as far as V4L2 can say.
    fn read_settings(&self) -> HwResult<CameraSettings> {
        let exposure_us = match self.controls.exposure {
            Some(_) => exposure_from_device(
                controls::read(&self.device, CID_EXPOSURE_ABSOLUTE)
                    .map_err(|e| map_io("read V4L2_CID_EXPOSURE_ABSOLUTE", &e))?,
            ),
            None => self.settings.exposure_us,
        };
        // Without a calibration the gain's dB are unknown; 0 dB is what `apply` would set.
        let gain_db = match (self.controls.gain, &self.config.gain) {
            (Some((id, _)), Some(cal)) => cal.from_device(
                controls::read(&self.device, id).map_err(|e| map_io("read gain", &e))?,
            ),
            _ => 0.0,
        };
        Ok(CameraSettings {
            exposure_us,
            gain_db,
            pixel_format: self.active.format.pixel_format(),
            roi: None,
            binning: (1, 1),
            decimation: (1, 1),
            trigger: TriggerMode::FreeRun,
        })
    }

    fn check_geometry(&self, s: &CameraSettings) -> HwResult<()> {
        if s.trigger != TriggerMode::FreeRun {
            return Err(HwError::Unsupported(
                "software trigger: V4L2 capture streams free-running".into(),
            ));
        }
        if s.binning != (1, 1) || s.decimation != (1, 1) {
            return Err(HwError::Unsupported(format!(
                "binning {:?} / decimation {:?}: V4L2 has no standard control for them",
                s.binning, s.decimation
            )));
        }
        let full = SensorRoi {
            x: 0,
            y: 0,
            width: self.active.width as u32,
            height: self.active.height as u32,
        };
        match s.roi {
            Some(roi) if roi != full => Err(HwError::Unsupported(format!(
                "ROI {roi:?}: cropping (VIDIOC_S_SELECTION) is not implemented; \
                 the V4L2 driver delivers the full {}x{} frame",
                full.width, full.height
            ))),
            _ => Ok(()),
        }
    }

    fn apply_exposure(&self, exposure_us: f64) -> HwResult<f64> {
        let Some(range) = self.controls.exposure else {
            return Err(HwError::Unsupported(
                "exposure: the device has no settable V4L2_CID_EXPOSURE_ABSOLUTE".into(),
            ));
        };
        let value = exposure_to_device(exposure_us, &range)?;
        if self.controls.exposure_auto.is_some() {
            // EXPOSURE_ABSOLUTE is ignored (and overwritten) while auto exposure runs.
            let mode = controls::set_and_read(&self.device, CID_EXPOSURE_AUTO, EXPOSURE_MANUAL)
                .map_err(|e| map_io("V4L2_CID_EXPOSURE_AUTO = manual", &e))?;
            if mode != EXPOSURE_MANUAL {
                return Err(HwError::Unsupported(format!(
                    "manual exposure: V4L2_CID_EXPOSURE_AUTO stays at {mode}"
                )));
            }
        }
        let got = controls::set_and_read(&self.device, CID_EXPOSURE_ABSOLUTE, value)
            .map_err(|e| map_io("V4L2_CID_EXPOSURE_ABSOLUTE", &e))?;
        Ok(exposure_from_device(got))
    }

    fn apply_gain(&self, gain_db: f64) -> HwResult<f64> {
        let Some((id, range)) = self.controls.gain else {
            return if gain_db == 0.0 {
                Ok(0.0)
            } else {
                Err(HwError::Unsupported(format!(
                    "gain_db = {gain_db}: the device has no settable gain control"
                )))
            };
        };
        let calibration = self.config.gain;
        let (value, _) = gain_to_device(gain_db, &range, calibration.as_ref())?;
        let got = controls::set_and_read(&self.device, id, value)
            .map_err(|e| map_io(&format!("gain control 0x{id:08x}"), &e))?;
        Ok(calibration.map_or(0.0, |c| c.from_device(got)))
    }

    /// Collects `count` good frames from a started stream.
    fn collect(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>> {
        if self.stream.is_none() {
            let stream = MmapStream::with_buffers(
                &self.device,
                Type::VideoCapture,
                // validate() keeps buffers within 1..=32.
                self.config.buffers as u32,
            )
            .map_err(|e| map_io("VIDIOC_REQBUFS / mmap", &e))?;
            self.stream = Some(stream);
        }
        let Self {
            stream,
            intake,
            active,
            config,
            ..
        } = self;
        let stream = stream.as_mut().expect("created above");
        intake.begin_session(config.discard_frames);
        let mut frames = Vec::with_capacity(count);
        let mut since = Instant::now();
        let mut last_failure: Option<BadBuffer> = None;
        while frames.len() < count {
            let remaining = timeout.saturating_sub(since.elapsed());
            if remaining.is_zero() {
                return Err(timeout_error(frames.len(), count, timeout, &last_failure));
            }
            // poll(2) takes an i32 of ms (v4l's set_timeout panics above that); round up so a
            // sub-millisecond remainder is not a zero-timeout poll.
            let remaining_ms = remaining.as_micros().div_ceil(1000).min(i32::MAX as u128);
            stream.set_timeout(Duration::from_millis(remaining_ms as u64));
            // First call: VIDIOC_QBUF of every buffer and VIDIOC_STREAMON; then QBUF of the
            // previous buffer, poll, VIDIOC_DQBUF.
            match CaptureStream::next(stream) {
                Ok((bytes, meta)) => {
                    let meta = BufferMeta {
                        sequence: meta.sequence,
                        flags: meta.flags.into(),
                        bytes_used: meta.bytesused,
                        timestamp_sec: meta.timestamp.sec,
                        timestamp_usec: meta.timestamp.usec,
                    };
                    match intake.take(active, bytes, &meta) {
                        Taken::Frame(frame) => {
                            frames.push(frame);
                            since = Instant::now();
                        }
                        Taken::Discarded => since = Instant::now(),
                        Taken::Failed(bad) => last_failure = Some(bad),
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::TimedOut => {
                    return Err(timeout_error(frames.len(), count, timeout, &last_failure));
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {
                    // A signal hit poll after the buffer was re-queued: v4l's stream cannot
                    // resume that, so restart it (STREAMOFF returns every buffer).
                    stream.stop().map_err(|e| map_io("VIDIOC_STREAMOFF", &e))?;
                    intake.begin_session(config.discard_frames);
                }
                Err(e) => return Err(map_io("VIDIOC_DQBUF", &e)),
            }
        }
        Ok(frames)
    }
}

fn timeout_error(
    got: usize,
    count: usize,
    timeout: Duration,
    last_failure: &Option<BadBuffer>,
) -> HwError {
    let why = last_failure
        .as_ref()
        .map(|b| format!(" (last bad buffer: {b})"))
        .unwrap_or_default();
    HwError::Timeout {
        what: format!("V4L2 frame {} of {count}{why}", got + 1),
        after_ms: timeout.as_millis() as u64,
    }
}

/// The largest frame any of `formats` offers (VIDIOC_ENUM_FRAMESIZES), by area.
fn largest_frame_size(device: &Device, formats: &[V4l2Format]) -> Option<(u32, u32)> {
    formats
        .iter()
        .filter_map(|f| device.enum_framesizes(FourCC::from(f.fourcc())).ok())
        .flatten()
        .map(|s| match s.size {
            FrameSizeEnum::Discrete(d) => (d.width, d.height),
            FrameSizeEnum::Stepwise(s) => (s.max_width, s.max_height),
        })
        .max_by_key(|&(w, h)| u64::from(w) * u64::from(h))
}

impl Camera for V4l2Camera {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn settings(&self) -> CameraSettings {
        self.settings.clone()
    }

    /// Applies in this order, and what succeeded stays applied when a later step fails:
    /// pixel format (VIDIOC_S_FMT, only when it changes), exposure, gain.
    fn apply(&mut self, settings: &CameraSettings) -> HwResult<CameraSettings> {
        self.check_geometry(settings)?;
        let format = V4l2Format::choose(
            settings.pixel_format,
            &self.offered,
            self.config.preferred_fourcc,
        )
        .ok_or_else(|| {
            HwError::Unsupported(format!(
                "pixel format {:?}: the device offers {:?}",
                settings.pixel_format, self.info.pixel_formats
            ))
        })?;
        if format != self.active.format {
            self.set_format(format)?;
        }
        self.settings.exposure_us = self.apply_exposure(settings.exposure_us)?;
        self.settings.gain_db = self.apply_gain(settings.gain_db)?;
        self.settings.roi = None;
        Ok(self.settings.clone())
    }

    /// Starts the stream, collects `count` good frames, each within `timeout` of the previous
    /// one (failed buffers do not reset the clock), and stops the stream.
    fn acquire(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>> {
        if count == 0 {
            return Ok(Vec::new());
        }
        let collected = self.collect(count, timeout);
        let stopped = match self.stream.as_mut() {
            Some(stream) => stream.stop().map_err(|e| map_io("VIDIOC_STREAMOFF", &e)),
            None => Ok(()),
        };
        let frames = collected?;
        stopped?;
        Ok(frames)
    }

    fn software_trigger(&mut self) -> HwResult<()> {
        Err(HwError::Unsupported(
            "software trigger: V4L2 capture streams free-running".into(),
        ))
    }

    /// Failed frames include those missing from the sequence numbers; V4L2 has no packets, so
    /// `missing_packets` stays 0.
    fn counters(&self) -> CameraCounters {
        self.intake.counters()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_node_is_disconnected() {
        let path = "/dev/ffdic-no-such-video-node";
        assert!(!std::path::Path::new(path).exists());
        let e = V4l2Camera::open(path).err().expect("opened a missing node");
        assert!(
            matches!(e, HwError::Disconnected(ref m) if m.contains(path)),
            "{e:?}"
        );
    }

    #[test]
    fn a_file_that_is_not_a_v4l2_node_is_unsupported() {
        // /dev/null opens read-write but answers VIDIOC_QUERYCAP with ENOTTY.
        let e = V4l2Camera::open("/dev/null")
            .err()
            .expect("opened /dev/null");
        assert!(
            matches!(e, HwError::Unsupported(ref m) if m.contains("QUERYCAP")),
            "{e:?}"
        );
    }

    #[test]
    fn a_bad_config_is_rejected_before_opening() {
        let mut config = V4l2Config::new("/dev/null");
        config.buffers = 0;
        // By reference, as the daemon passes it: the config is checked before /dev/null is
        // touched (which would give Unsupported).
        assert!(matches!(
            V4l2Camera::open(&config),
            Err(HwError::OutOfRange { .. })
        ));
        let empty = V4l2Config {
            buffers: 4,
            ..Default::default()
        };
        assert!(matches!(
            V4l2Camera::with_config(empty),
            Err(HwError::Protocol(ref m)) if m.contains("empty")
        ));
    }

    #[test]
    fn timeouts_name_the_frame_and_the_last_bad_buffer() {
        let bad = Some(BadBuffer::ErrorFlag { sequence: 9 });
        let e = timeout_error(2, 3, Duration::from_millis(250), &bad);
        let HwError::Timeout { what, after_ms } = e else {
            panic!("not a timeout")
        };
        assert_eq!(after_ms, 250);
        assert!(
            what.contains("frame 3 of 3") && what.contains("V4L2_BUF_FLAG_ERROR"),
            "{what}"
        );
    }
}
