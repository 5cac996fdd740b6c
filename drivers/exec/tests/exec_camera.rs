//! The exec camera against commands that do what a renderer does (copy a frame chosen by the
//! bench state) and what a broken one does: fail, write nothing, write the wrong size, hang.

use ffdic_exec::{ExecBench, ExecCamera, ExecCameraConfig, Mount};
use ffdic_hw::{Camera, CameraSettings, HwError, StagePosition};
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn write_tiff(path: &Path, width: u32, height: u32, seed: u16) -> Vec<u16> {
    let data: Vec<u16> = (0..width * height)
        .map(|i| (i as u16).wrapping_mul(2654).wrapping_add(seed))
        .collect();
    let file = std::fs::File::create(path).unwrap();
    let mut enc = tiff::encoder::TiffEncoder::new(file).unwrap();
    enc.write_image::<tiff::encoder::colortype::Gray16>(width, height, &data)
        .unwrap();
    data
}

struct Bench {
    position: Arc<Mutex<StagePosition>>,
    mount: Arc<Mutex<Mount>>,
}

fn camera(script: &str, timeout_ms: u64, dir: &Path) -> (ExecCamera, Bench) {
    let position = Arc::new(Mutex::new(StagePosition::default()));
    let mount = Arc::new(Mutex::new(Mount::default()));
    let seen = position.clone();
    let config = ExecCameraConfig {
        command: vec![
            "sh".into(),
            "-c".into(),
            format!("cd '{}' && {script}", dir.display()),
        ],
        width: 64,
        height: 48,
        bit_depth: 16,
        timeout_ms,
    };
    let bench = ExecBench {
        position: Box::new(move || *seen.lock().unwrap()),
        mount: mount.clone(),
    };
    (
        ExecCamera::open(config, bench).unwrap(),
        Bench { position, mount },
    )
}

#[test]
fn a_frame_is_the_file_the_command_wrote_for_the_bench_state() {
    let dir = tempfile::tempdir().unwrap();
    let at_origin = write_tiff(&dir.path().join("x0.tif"), 64, 48, 1);
    let moved = write_tiff(&dir.path().join("x2.5.tif"), 64, 48, 7);
    let (mut cam, bench) = camera(
        "echo \"$FFDIC_X_MM $FFDIC_Y_MM $FFDIC_TARGET $FFDIC_FRAME $FFDIC_EXPOSURE_US $FFDIC_WIDTH\" >> env.log; \
         case $FFDIC_X_MM in 0.0) cp x0.tif \"$FFDIC_OUT\";; *) cp x$FFDIC_X_MM.tif \"$FFDIC_OUT\";; esac",
        10_000,
        dir.path(),
    );
    cam.apply(&CameraSettings {
        exposure_us: 2500.0,
        ..cam.settings()
    })
    .unwrap();
    *bench.mount.lock().unwrap() = Mount {
        label: "a".into(),
        generation: 1,
    };
    let first = cam.acquire(2, Duration::from_secs(10)).unwrap();
    assert_eq!(first[0].data, at_origin);
    assert_eq!(
        (first[1].width, first[1].height, first[1].bit_depth),
        (64, 48, 16)
    );
    *bench.position.lock().unwrap() = StagePosition {
        x_mm: 2.5,
        y_mm: 0.0,
    };
    assert_eq!(
        cam.acquire(1, Duration::from_secs(10)).unwrap()[0].data,
        moved
    );
    // A new mount starts the frame count again.
    *bench.mount.lock().unwrap() = Mount {
        label: "b".into(),
        generation: 2,
    };
    cam.acquire(1, Duration::from_secs(10)).unwrap();
    let log = std::fs::read_to_string(dir.path().join("env.log")).unwrap();
    assert_eq!(
        log.lines().collect::<Vec<_>>(),
        [
            "0.0 0.0 a 0 2500.0 64",
            "0.0 0.0 a 1 2500.0 64",
            "2.5 0.0 a 2 2500.0 64",
            "2.5 0.0 b 0 2500.0 64"
        ]
    );
    assert_eq!(cam.counters().completed, 4);
}

/// Each failure names what went wrong, and the camera delivers again afterwards.
#[test]
fn a_failing_silent_wrong_or_hanging_command_fails_the_capture_clearly() {
    let dir = tempfile::tempdir().unwrap();
    write_tiff(&dir.path().join("good.tif"), 64, 48, 3);
    write_tiff(&dir.path().join("small.tif"), 32, 32, 3);
    let (mut cam, _bench) = camera(
        "case $(cat mode) in \
           fail) echo 'no light source found' >&2; exit 3;; \
           silent) exit 0;; \
           small) cp small.tif \"$FFDIC_OUT\";; \
           hang) sleep 20;; \
           linger) cp good.tif \"$FFDIC_OUT\"; sleep 5 & ;; \
           *) cp good.tif \"$FFDIC_OUT\";; esac",
        400,
        dir.path(),
    );
    let run = |cam: &mut ExecCamera, mode: &str| {
        std::fs::write(dir.path().join("mode"), mode).unwrap();
        cam.acquire(1, Duration::from_secs(30))
    };
    let err = run(&mut cam, "fail").unwrap_err().to_string();
    assert!(
        err.contains("no light source found") && err.contains('3'),
        "{err}"
    );
    let err = run(&mut cam, "silent").unwrap_err().to_string();
    assert!(err.contains("wrote no frame"), "{err}");
    let err = run(&mut cam, "small").unwrap_err().to_string();
    assert!(err.contains("32x32") && err.contains("64x48"), "{err}");
    let started = Instant::now();
    let err = run(&mut cam, "hang").unwrap_err();
    assert!(
        matches!(err, HwError::Timeout { after_ms: 400, .. }),
        "{err}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "the hung command was not stopped"
    );
    assert_eq!(run(&mut cam, "good").unwrap().len(), 1);
    // A command that exits leaving a child behind (holding its stderr) is not waited for.
    let started = Instant::now();
    assert_eq!(run(&mut cam, "linger").unwrap().len(), 1);
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "waited for the child"
    );
    assert_eq!(cam.counters().failed, 4);
}
