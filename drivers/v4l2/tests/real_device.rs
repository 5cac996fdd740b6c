//! Against a real V4L2 camera, when `FFDIC_V4L2_DEVICE` names its node:
//! `FFDIC_V4L2_DEVICE=/dev/video0 cargo test -p ffdic-v4l2 --test real_device -- --nocapture`.
//! Without it the test returns at once and says it was skipped.

use ffdic_hw::{Camera, CameraSettings};
use ffdic_v4l2::V4l2Camera;
use std::path::PathBuf;
use std::time::Duration;

#[test]
fn opens_applies_and_acquires_three_frames() {
    let Some(path) = std::env::var_os("FFDIC_V4L2_DEVICE") else {
        eprintln!("skipped: set FFDIC_V4L2_DEVICE=/dev/videoN to run against a real camera");
        return;
    };
    let mut cam = V4l2Camera::open(PathBuf::from(path)).expect("open the device");
    let info = cam.info().clone();
    assert!(info.sensor_width > 0 && info.sensor_height > 0, "{info:?}");
    // The deepest format the camera offers, at an exposure every camera has in range.
    let pixel_format = *info.pixel_formats.last().expect("a monochrome format");
    let wanted = CameraSettings {
        exposure_us: 10_000.0,
        gain_db: 0.0,
        pixel_format,
        ..CameraSettings::default()
    };
    let got = cam.apply(&wanted).expect("apply");
    assert_eq!(got.pixel_format, pixel_format);
    // Exposure comes back as the device value: whole 100 µs units.
    assert_eq!(got.exposure_us % 100.0, 0.0, "{got:?}");
    assert_eq!(cam.settings(), got);

    let format = cam.active_format();
    let before = cam.counters();
    let frames = cam
        .acquire(3, Duration::from_secs(5))
        .expect("acquire 3 frames");
    assert_eq!(frames.len(), 3);
    let max = (1u32 << pixel_format.bit_depth()) - 1;
    for f in &frames {
        assert_eq!((f.width, f.height), (format.width, format.height));
        assert_eq!(f.data.len(), f.width * f.height);
        assert_eq!(f.bit_depth, pixel_format.bit_depth());
        assert!(f.data.iter().all(|&v| u32::from(v) <= max));
    }
    assert!(frames.windows(2).all(|w| w[0].frame_id < w[1].frame_id));
    assert_eq!(cam.counters().completed, before.completed + 3);
    eprintln!(
        "{} {} {}x{} {:?}: mean of frame 0 = {:.1}, counters {:?}",
        info.vendor,
        info.model,
        format.width,
        format.height,
        format.format,
        frames[0].mean(),
        cam.counters()
    );
}
