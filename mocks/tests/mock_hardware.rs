//! The mock stage and camera behave like hardware: travel takes time, homing is required, limits
//! hold, faults surface as the typed errors the daemon maps to HTTP statuses.

use ffdic_hw::{Camera, CameraSettings, HardwareScheme, HwError, Stage, StagePosition};
use ffdic_mocks::{new_bench, MockCamera, MockStage, Scene};
use std::time::{Duration, Instant};

/// A scene whose every pixel holds the stage x position in µm: what the camera saw is readable.
struct PositionScene;

impl Scene for PositionScene {
    fn size(&self) -> (usize, usize) {
        (4, 3)
    }
    fn render(
        &self,
        p: StagePosition,
        _: f64,
        _: u8,
        _: u64,
        _: Option<&HardwareScheme>,
    ) -> Vec<u16> {
        vec![(p.x_mm * 1000.0).round() as u16; 12]
    }
}

#[test]
fn stage_needs_homing_respects_limits_and_takes_time() {
    let bench = new_bench();
    let mut stage = MockStage::new(bench, 20.0, Duration::from_millis(20));
    let target = StagePosition {
        x_mm: 1.0,
        y_mm: 0.0,
    };
    assert!(matches!(
        stage.move_absolute(target),
        Err(HwError::NotReferenced(_))
    ));
    stage.home(Duration::from_secs(1)).unwrap();
    assert!(matches!(
        stage.move_absolute(StagePosition {
            x_mm: 40.0,
            y_mm: 0.0
        }),
        Err(HwError::OutOfRange { .. })
    ));
    let t0 = Instant::now();
    stage.move_absolute(target).unwrap();
    let p = stage.wait_settled(Duration::from_secs(2)).unwrap();
    // 1 mm at 20 mm/s is 50 ms, plus 20 ms settling.
    assert!(t0.elapsed() >= Duration::from_millis(65));
    assert!((p.x_mm - 1.0).abs() < 1e-9 && p.y_mm == 0.0);
    stage.move_relative(0.5, -0.25).unwrap();
    let p = stage.wait_settled(Duration::from_secs(2)).unwrap();
    assert!((p.x_mm - 1.5).abs() < 1e-9 && (p.y_mm + 0.25).abs() < 1e-9);
    stage
        .move_absolute(StagePosition {
            x_mm: 20.0,
            y_mm: 0.0,
        })
        .unwrap();
    assert!(matches!(
        stage.wait_settled(Duration::from_millis(10)),
        Err(HwError::Timeout { .. })
    ));
    stage.faults.disconnected = true;
    assert!(matches!(stage.position(), Err(HwError::Disconnected(_))));
}

#[test]
fn camera_sees_the_stage_position_and_reports_faults() {
    let bench = new_bench();
    let mut stage = MockStage::new(bench.clone(), 100.0, Duration::ZERO);
    let mut camera = MockCamera::new(PositionScene, bench);
    stage.home(Duration::from_secs(1)).unwrap();
    stage
        .move_absolute(StagePosition {
            x_mm: 2.0,
            y_mm: 0.0,
        })
        .unwrap();
    stage.wait_settled(Duration::from_secs(1)).unwrap();
    let frames = camera.acquire(2, Duration::from_secs(1)).unwrap();
    assert_eq!(frames[0].data[0], 2000);
    assert_eq!((frames[0].frame_id, frames[1].frame_id), (0, 1));

    camera.faults.missing_packets_every = Some(2);
    let frames = camera.acquire(2, Duration::from_secs(1)).unwrap();
    assert_eq!(
        frames.len(),
        2,
        "frames with missing packets are dropped, not returned"
    );
    assert!(camera.counters().failed >= 1 && camera.counters().missing_packets >= 3);

    camera.faults.missing_packets_every = None;
    camera.faults.disconnect_after_frames = Some(camera.counters().completed + 1);
    assert!(matches!(
        camera.acquire(3, Duration::from_secs(1)),
        Err(HwError::Disconnected(_))
    ));
    camera.faults = Default::default();
    camera.faults.stalled = true;
    assert!(matches!(
        camera.acquire(1, Duration::from_millis(5)),
        Err(HwError::Timeout { .. })
    ));
}

#[test]
fn camera_settings_are_checked() {
    let mut camera = MockCamera::new(PositionScene, new_bench());
    let bad = CameraSettings {
        exposure_us: 1.0,
        ..CameraSettings::default()
    };
    assert!(matches!(
        camera.apply(&bad),
        Err(HwError::OutOfRange { .. })
    ));
    let ok = CameraSettings {
        exposure_us: 2000.0,
        gain_db: 6.0,
        ..CameraSettings::default()
    };
    assert_eq!(camera.apply(&ok).unwrap(), ok);
    assert_eq!(camera.settings(), ok);
}
