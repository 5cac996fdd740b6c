#![cfg(feature = "aravis")]
//! The Aravis driver over the real GigE Vision stack: an in-process Aravis GigE Vision simulator
//! on 127.0.0.1 serves frames the imaging model renders at the mock stage's position; DIC on two
//! captures recovers the commanded move; killing the camera mid-acquisition is reported as a
//! disconnect, never as a short frame list.
//!
//! Network safety: Aravis discovery broadcasts on every interface, so every test here runs in a
//! network namespace with loopback only. A test not yet isolated re-executes itself (this binary,
//! that one test) under `unshare -rn` and asserts the child passed.

use crate::common::folder_sink;

use ffdic::bench::{BenchHandle, BenchHardware, BenchLimits, ModelScene};
use ffdic::dic::{analyze, DicSettings};
use ffdic::experiment::{
    run_experiment, BenchGeometry, BenchTimeouts, ExperimentOutcome, ExperimentPlan,
    ExperimentRequest, MoveSpec, PatternSpec, SchemeSpec,
};
use ffdic::image::{Image, Roi};
use ffdic::model::{Camera as ModelCamera, ModelConfig, SpecklePattern};
use ffdic_aravis::{AravisCamera, FakeGvCamera, FillFn, FillRequest};
use ffdic_hw::{
    schemes_for, BinningDomain, BinningMode, Camera, CameraSettings, HardwareScheme, HwError,
    PixelFormat, ReductionCaps, SensorRoi, Stage, StagePosition, TriggerMode,
};
use ffdic_mocks::{new_bench, MockStage, Scene};
use folder_sink::FolderSink;
use std::process::Command;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Set in the re-executed child, so a child that still sees other interfaces fails instead of
/// recursing.
const NETNS_MARKER: &str = "FFDIC_ARAVIS_TEST_NETNS";

/// Interfaces of this process' network namespace.
fn interfaces() -> Vec<String> {
    std::fs::read_to_string("/proc/net/dev")
        .expect("read /proc/net/dev")
        .lines()
        .skip(2)
        .filter_map(|l| l.split(':').next())
        .map(|n| n.trim().to_string())
        .collect()
}

/// True when the caller is in a loopback-only namespace and should run the test body; otherwise
/// runs `name` in such a namespace, asserts it passed, and returns false.
fn isolated(name: &str) -> bool {
    let ifaces = interfaces();
    if ifaces.iter().all(|n| n == "lo") {
        return true;
    }
    assert!(
        std::env::var_os(NETNS_MARKER).is_none(),
        "re-executed for isolation but the namespace still has {ifaces:?}"
    );
    // The test's name in the binary: its module path without the crate's name.
    let module = module_path!().split_once("::").map_or("", |(_, m)| m);
    let full_name = format!("{module}::{name}");
    let name = full_name.as_str();
    let exe = std::env::current_exe().expect("test binary path");
    let out = Command::new("unshare")
        .args(["-rn", "sh", "-c", "ip link set lo up && exec \"$0\" \"$@\""])
        .arg(&exe)
        .args(["--exact", name, "--nocapture", "--test-threads=1"])
        .env(NETNS_MARKER, "1")
        .output()
        .expect("run unshare (util-linux) for a loopback-only network namespace");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("--- {name} in a loopback-only namespace ---\n{stdout}{stderr}");
    assert!(out.status.success(), "{name} failed in its namespace");
    // `--exact` with a wrong name runs nothing and succeeds: make sure the test really ran.
    assert!(
        stdout.contains("1 passed"),
        "{name} did not run in its namespace"
    );
    false
}

fn to_image(f: &ffdic_hw::Frame) -> Image {
    Image::from_vec(
        f.width,
        f.height,
        f.data.iter().map(|&v| v as f32).collect(),
    )
    .unwrap()
}

const SCALE_PX_PER_MM: f64 = 20.0;
const SENSOR: (u32, u32) = (512, 384);

/// The paper's bench sensor (shot and read noise, 16-bit ADC) looking at print `b` on the mock
/// stage, SENSOR px at SCALE_PX_PER_MM.
fn bench_scene() -> Arc<ModelScene> {
    let model_camera = ModelCamera {
        width: SENSOR.0 as usize,
        height: SENSOR.1 as usize,
        scale_px_per_mm: SCALE_PX_PER_MM,
        exposure_level: 0.5,
        principal_dx_px: 0.0,
        principal_dy_px: 0.0,
    };
    let bench_model = ModelConfig::from_toml(
        "name = \"bench\"\n[effects.sensor_noise]\nfull_well_e = 30000.0\nread_noise_e = 1.5\ngain = 0.46\n[effects.quantization]\nbits = 16\n",
        std::path::Path::new("inline"),
    )
    .unwrap();
    Arc::new(
        ModelScene::new(
            model_camera,
            bench_model,
            &SpecklePattern::preset("b").unwrap(),
            2.0,
            5,
        )
        .unwrap(),
    )
}

/// Full resolution, 16 bit, the scene's size as the region.
fn scene_settings() -> CameraSettings {
    CameraSettings {
        exposure_us: 8000.0,
        pixel_format: PixelFormat::Mono16,
        roi: Some(SensorRoi {
            x: 64,
            y: 32,
            width: SENSOR.0,
            height: SENSOR.1,
        }),
        ..CameraSettings::default()
    }
}

/// The read-out the simulator is set to, as a hardware scheme (None at full resolution); a
/// combination no scheme names is None too and the frame goes out black.
fn read_out_of(request: &FillRequest) -> Result<Option<HardwareScheme>, ()> {
    if (request.binning, request.decimation) == ((1, 1), (1, 1)) {
        return Ok(None);
    }
    let caps = ReductionCaps {
        binning_max: (4, 4),
        binning_mode: Some(if request.binning_average {
            BinningMode::Average
        } else {
            BinningMode::Sum
        }),
        binning_domain: BinningDomain::Unknown,
        decimation_max: (4, 4),
    };
    schemes_for(&caps)
        .into_iter()
        .find(|s| s.settings() == (request.binning, request.decimation))
        .map(Some)
        .ok_or(())
}

/// The simulator renders what the sensor sees where the stage is when the frame is made, read
/// out as the camera is set (binning, decimation); a frame of any other size goes out black
/// (the region not yet set to the scene's).
fn scene_fill(scene: Arc<ModelScene>, bench: ffdic_mocks::SharedBench) -> FillFn {
    let frame_index = Arc::new(AtomicU64::new(0));
    Arc::new(move |request: &FillRequest| {
        let (w, h) = (request.width, request.height);
        let Ok(readout) = read_out_of(request) else {
            return vec![0; w * h];
        };
        if (w, h) != ffdic_mocks::output_size(scene.size(), readout.as_ref()) {
            return vec![0; w * h];
        }
        let at = bench.lock().unwrap().position_at(Instant::now());
        let i = frame_index.fetch_add(1, Ordering::SeqCst);
        scene.render(at, request.exposure_us, 16, i, readout.as_ref())
    })
}

#[test]
fn dic_recovers_a_stage_move_through_gige_vision() {
    if !isolated("dic_recovers_a_stage_move_through_gige_vision") {
        return;
    }
    let scene = bench_scene();
    let bench = new_bench();
    let mut stage = MockStage::new(bench.clone(), 50.0, Duration::from_millis(5));
    stage.home(Duration::from_secs(1)).unwrap();
    let fill = scene_fill(scene, bench.clone());
    let fake = FakeGvCamera::start("FFDIC-DIC", fill).expect("start the GigE Vision simulator");
    let mut camera = AravisCamera::open(fake.address()).expect("open the camera by address");
    assert_eq!(camera.info().serial, "FFDIC-DIC");
    assert!(camera.info().pixel_formats.contains(&PixelFormat::Mono16));

    let wanted = scene_settings();
    let applied = camera.apply(&wanted).unwrap();
    assert_eq!(
        applied, wanted,
        "the simulator takes these settings as they are"
    );

    let timeout = Duration::from_secs(5);
    let reference = camera.acquire(1, timeout).unwrap().remove(0);
    assert_eq!((reference.width, reference.height), (512, 384));
    assert_eq!(reference.bit_depth, 16);
    assert!(
        reference.mean() > 10_000.0,
        "a speckle frame, not a black one: mean {}",
        reference.mean()
    );

    // 0.3617 mm x, -0.0843 mm y at 20 px/mm: 7.234 px and -1.686 px, integer plus sub-pixel.
    let (dx_mm, dy_mm) = (0.3617, -0.0843);
    stage
        .move_absolute(StagePosition {
            x_mm: dx_mm,
            y_mm: dy_mm,
        })
        .unwrap();
    stage.wait_settled(Duration::from_secs(2)).unwrap();
    let moved = camera.acquire(1, timeout).unwrap().remove(0);
    assert_ne!(moved.frame_id, reference.frame_id);

    let settings = DicSettings {
        roi: Some(Roi::new(96, 72, 320, 240)),
        ..DicSettings::default()
    };
    let r = analyze(&to_image(&reference), &to_image(&moved), &settings, None).unwrap();
    let (u, v) = (dx_mm * SCALE_PX_PER_MM, dy_mm * SCALE_PX_PER_MM);
    println!(
        "commanded ({u:.4}, {v:.4}) px, recovered ({:.4}, {:.4}) px over {} points",
        r.summary.u.mean, r.summary.v.mean, r.summary.valid
    );
    assert_eq!(r.summary.valid, r.summary.points);
    assert!(r.summary.points > 50);
    assert!(
        (r.summary.u.mean - u).abs() < 0.01,
        "u {} vs {u}",
        r.summary.u.mean
    );
    assert!(
        (r.summary.v.mean - v).abs() < 0.01,
        "v {} vs {v}",
        r.summary.v.mean
    );
    let c = camera.counters();
    assert_eq!((c.completed, c.failed, c.missing_packets), (2, 0, 0));
}

/// A test image whose every sample is known: high byte from the row, low byte from the column.
fn pattern(x: usize, y: usize) -> u16 {
    ((((y * 7 + x) % 256) << 8) | ((x * 3 + y) % 256)) as u16
}

fn pattern_fill() -> FillFn {
    Arc::new(|r: &FillRequest| {
        (0..r.height)
            .flat_map(|y| (0..r.width).map(move |x| pattern(x, y)))
            .collect()
    })
}

#[test]
fn features_fall_back_and_samples_arrive_exactly() {
    if !isolated("features_fall_back_and_samples_arrive_exactly") {
        return;
    }
    let fake = FakeGvCamera::start("FFDIC-FEAT", pattern_fill()).unwrap();
    let mut camera = AravisCamera::open(fake.address()).unwrap();
    let info = camera.info().clone();
    assert_eq!((info.sensor_width, info.sensor_height), (2048, 2048));
    assert!(!info.hardware_decimation);
    // The simulator stores BinningHorizontal/Vertical (up to 16) but has no BinningMode.
    assert!(info.hardware_binning);
    let names: Vec<_> = camera
        .hardware_schemes()
        .into_iter()
        .map(|s| s.name)
        .collect();
    assert_eq!(
        names,
        ["hw:bin2x2-vendor", "hw:bin3x3-vendor", "hw:bin4x4-vendor"]
    );

    // ExposureTimeAbs stands in for ExposureTime; ROI values round down to the increments.
    let wanted = CameraSettings {
        exposure_us: 2500.0,
        gain_db: 0.0,
        pixel_format: PixelFormat::Mono16,
        roi: Some(SensorRoi {
            x: 10,
            y: 20,
            width: 96,
            height: 64,
        }),
        ..CameraSettings::default()
    };
    let applied = camera.apply(&wanted).unwrap();
    assert_eq!(applied.exposure_us, 2500.0);
    assert_eq!(applied.roi, wanted.roi);
    let frames = camera.acquire(3, Duration::from_secs(5)).unwrap();
    assert_eq!(frames.len(), 3);
    for f in &frames {
        assert_eq!((f.width, f.height, f.bit_depth), (96, 64, 16));
        let expected: Vec<u16> = (0..64)
            .flat_map(|y| (0..96).map(move |x| pattern(x, y)))
            .collect();
        assert_eq!(f.data, expected, "Mono16 samples arrive bit for bit");
    }
    assert!(frames.windows(2).all(|w| w[1].frame_id > w[0].frame_id));

    // Mono8 carries the top byte; software trigger: the driver fires one trigger per frame.
    let mono8 = CameraSettings {
        pixel_format: PixelFormat::Mono8,
        trigger: TriggerMode::Software,
        ..wanted.clone()
    };
    assert_eq!(
        camera.apply(&mono8).unwrap().pixel_format,
        PixelFormat::Mono8
    );
    let frames = camera.acquire(2, Duration::from_secs(5)).unwrap();
    for f in &frames {
        assert_eq!(f.bit_depth, 8);
        assert_eq!(f.data[0], pattern(0, 0) >> 8);
        assert_eq!(f.data[5 * 96 + 7], pattern(7, 5) >> 8);
    }
    camera.software_trigger().unwrap();

    // What the simulator cannot do is refused, by kind, without changing what it does.
    let too_long = CameraSettings {
        exposure_us: 2e7,
        ..wanted.clone()
    };
    assert!(matches!(
        camera.apply(&too_long),
        Err(HwError::OutOfRange { .. })
    ));
    let gain = CameraSettings {
        gain_db: 6.0,
        ..wanted.clone()
    };
    assert!(matches!(camera.apply(&gain), Err(HwError::Unsupported(_))));
    let mono12 = CameraSettings {
        pixel_format: PixelFormat::Mono12,
        ..wanted.clone()
    };
    assert!(matches!(
        camera.apply(&mono12),
        Err(HwError::Unsupported(_))
    ));
    let decimated = CameraSettings {
        decimation: (2, 2),
        ..wanted.clone()
    };
    assert!(matches!(
        camera.apply(&decimated),
        Err(HwError::Unsupported(_))
    ));
    let c = camera.counters();
    assert_eq!((c.completed, c.failed), (5, 0));
}

#[test]
fn killed_camera_is_a_disconnect_not_a_short_frame_list() {
    if !isolated("killed_camera_is_a_disconnect_not_a_short_frame_list") {
        return;
    }
    let fake = FakeGvCamera::start("FFDIC-KILL", pattern_fill()).unwrap();
    let mut camera = AravisCamera::open(fake.address()).unwrap();
    let small = CameraSettings {
        roi: Some(SensorRoi {
            x: 0,
            y: 0,
            width: 64,
            height: 48,
        }),
        ..CameraSettings::default()
    };
    camera.apply(&small).unwrap();
    assert_eq!(camera.acquire(2, Duration::from_secs(5)).unwrap().len(), 2);

    // Unplug the camera while `acquire` waits for far more frames than it can deliver (25 fps).
    let killer = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(400));
        fake.stop();
        Instant::now()
    });
    let before = camera.counters().completed;
    let first = camera.acquire(10_000, Duration::from_secs(1));
    let killed_at = killer.join().unwrap();
    let delivered_meanwhile = camera.counters().completed - before;
    assert!(
        delivered_meanwhile >= 3,
        "frames flowed before the kill ({delivered_meanwhile})"
    );
    // An error, not a short list: `acquire` has no Ok with fewer frames than asked.
    let mut outcome = first.map(|f| f.len());
    while let Err(HwError::Timeout { .. }) = outcome {
        assert!(killed_at.elapsed() < Duration::from_secs(10));
        outcome = camera.acquire(1, Duration::from_secs(1)).map(|f| f.len());
    }
    let latency = killed_at.elapsed();
    println!("disconnect reported {latency:?} after the kill: {outcome:?}");
    assert!(
        matches!(outcome, Err(HwError::Disconnected(_))),
        "{outcome:?}"
    );
    assert!(latency < Duration::from_secs(10), "{latency:?}");

    // Every later call fails fast with the same kind, until reopened.
    let t = Instant::now();
    assert!(matches!(
        camera.acquire(1, Duration::from_secs(1)),
        Err(HwError::Disconnected(_))
    ));
    assert!(matches!(
        camera.apply(&small),
        Err(HwError::Disconnected(_))
    ));
    assert!(t.elapsed() < Duration::from_millis(100));

    // The camera comes back (same serial, same address): reopen restores the settings.
    let fake = FakeGvCamera::start("FFDIC-KILL", pattern_fill()).unwrap();
    let t = Instant::now();
    let restored = camera.reopen().unwrap();
    println!("reopened in {:?}", t.elapsed());
    assert_eq!(restored.roi, small.roi);
    let frames = camera.acquire(2, Duration::from_secs(5)).unwrap();
    assert_eq!((frames[1].width, frames[1].height), (64, 48));
    assert_eq!(frames[1].data[64 + 5], pattern(5, 1));
    // The camera before the simulator: Aravis leaves control on drop, which needs an answer.
    drop(camera);
    drop(fake);
}

/// The camera offers the hardware schemes, and the driver sets decimation on it and reads it
/// back: a frame of half the size each way, rendered. Leaves the camera at full resolution.
fn check_decimation_is_applied_and_read_back(camera: &mut AravisCamera) {
    let info = camera.info().clone();
    assert!(info.hardware_binning && info.hardware_decimation);
    let names: Vec<String> = info
        .hardware_schemes
        .iter()
        .map(|s| s.name.clone())
        .collect();
    for wanted in ["hw:bin2x2-average", "hw:dec2-bin2-average", "hw:dec2x2"] {
        assert!(names.iter().any(|n| n == wanted), "{wanted} in {names:?}");
    }
    let full_resolution = scene_settings();
    camera.apply(&full_resolution).unwrap();
    // The driver sets decimation on the camera and reads it back.
    let dec = info
        .hardware_schemes
        .iter()
        .find(|s| s.name == "hw:dec2x2")
        .unwrap();
    let applied = camera.apply(&dec.applied_to(&full_resolution)).unwrap();
    assert_eq!((applied.binning, applied.decimation), ((1, 1), (2, 2)));
    assert_eq!(applied.roi, full_resolution.roi);
    let frame = camera.acquire(1, Duration::from_secs(5)).unwrap().remove(0);
    assert_eq!((frame.width, frame.height), (256, 192));
    assert!(
        frame.mean() > 10_000.0,
        "a rendered frame: {}",
        frame.mean()
    );
    camera.apply(&full_resolution).unwrap();
}

/// One move of pattern b in two full-resolution schemes and the two hardware schemes that are
/// their twins, planned within the limits of the bench that offers `hardware_schemes`.
fn hardware_scheme_plan(hardware_schemes: Vec<HardwareScheme>) -> ExperimentPlan {
    let limits = BenchLimits {
        scale_px_per_mm: SCALE_PX_PER_MM,
        target_field_mm: None,
        travel_x_mm: Some((-5.0, 5.0)),
        travel_y_mm: Some((-5.0, 5.0)),
        stage_resolution_mm: None,
        exposure_us: (10.0, 1e6),
        hardware_schemes,
    };
    let request = ExperimentRequest {
        name: "gige-hardware-schemes".into(),
        patterns: vec![PatternSpec::Preset("b".into())],
        moves: vec![MoveSpec {
            id: "m1".into(),
            dx_mm: 0.3617,
            dy_mm: -0.0843,
        }],
        step_series: Vec::new(),
        static_frames: 0,
        schemes: ["ff100", "ff25", "hw:bin2x2-average", "hw:dec2x2"]
            .into_iter()
            .map(|s| SchemeSpec::Preset(s.into()))
            .collect(),
        dic: DicSettings {
            subset_px: 21,
            step_px: 8,
            ..DicSettings::default()
        },
        ..ExperimentRequest::default()
    };
    request.plan(&limits).expect("a valid plan")
}

/// Rows: every scheme of the one move, the hardware ones recovering the commanded move in
/// their own pixels (half the full-resolution px) as well as their synthesised twins do.
fn check_hardware_rows_match_their_twins(outcome: &ExperimentOutcome) {
    let row = |scheme: &str| {
        outcome
            .rows
            .iter()
            .find(|r| r.scheme == scheme)
            .unwrap_or_else(|| panic!("a {scheme} row in {:?}", outcome.rows))
    };
    let (u, v) = (
        0.3617 * SCALE_PX_PER_MM / 2.0,
        -0.0843 * SCALE_PX_PER_MM / 2.0,
    );
    for (hw, twin) in [("hw:bin2x2-average", "ff100"), ("hw:dec2x2", "ff25")] {
        let (h, t) = (&row(hw).summary, &row(twin).summary);
        println!(
            "{hw}: u {:.4} ± {:.4}, v {:.4} ± {:.4}; {twin}: u {:.4} ± {:.4}, v {:.4} ± {:.4} (commanded {u:.4}, {v:.4})",
            h.u.mean, h.u.std, h.v.mean, h.v.std, t.u.mean, t.u.std, t.v.mean, t.v.std
        );
        println!(
            "{hw}: {} of {} points valid; {twin}: {} of {}",
            h.valid, h.points, t.valid, t.points
        );
        // Points whose subset the move carries out of the frame fail on either side.
        assert!(
            h.valid as f64 >= 0.9 * h.points as f64,
            "{hw}: {} of {} points valid",
            h.valid,
            h.points
        );
        for (axis, got, want) in [("u", h.u.mean, u), ("v", h.v.mean, v)] {
            assert!((got - want).abs() < 0.02, "{hw} {axis}: {got} vs {want}");
        }
        // And as their twins do, within the noise: the blocks of the bootstrap (16 points) are
        // the independent units of a mean.
        let blocks = (h.valid as f64 / 16.0).max(1.0);
        for (axis, a, b) in [("u", &h.u, &t.u), ("v", &h.v, &t.v)] {
            let se = (a.std.powi(2) + b.std.powi(2)).sqrt() / blocks.sqrt();
            assert!(
                (a.mean - b.mean).abs() < 3.0 * se,
                "{hw} {axis}: {} vs {twin} {} (se {se})",
                a.mean,
                b.mean
            );
        }
    }
}

/// Issue 17: a camera with SFNC decimation and an averaging binning mode (the simulator's
/// description extended) offers the hardware schemes; an experiment naming two of them runs end
/// to end over GigE Vision — every read-out applied and read back through the driver, frames of
/// the binned and decimated size, rows beside their synthesised twins — and leaves the camera
/// at full resolution.
#[test]
fn a_hardware_scheme_experiment_runs_through_gige_vision() {
    if !isolated("a_hardware_scheme_experiment_runs_through_gige_vision") {
        return;
    }
    let mock_bench = new_bench();
    let mut stage = MockStage::new(mock_bench.clone(), 50.0, Duration::from_millis(5));
    stage.home(Duration::from_secs(1)).unwrap();
    let fake = FakeGvCamera::start_sfnc("FFDIC-HW", scene_fill(bench_scene(), mock_bench))
        .expect("start the GigE Vision simulator with SFNC features");
    let mut camera = AravisCamera::open(fake.address()).expect("open the camera by address");
    check_decimation_is_applied_and_read_back(&mut camera);

    let bench = BenchHandle::spawn(
        BenchHardware {
            camera: Box::new(camera),
            stage: Some(Box::new(stage)),
            targets: None,
        },
        Duration::from_secs(30),
    );
    let status = bench.status().unwrap();
    let plan = hardware_scheme_plan(status.camera.info.hardware_schemes.clone());
    let dir = tempfile::tempdir().unwrap();
    let sink = FolderSink::new(dir.path());
    let lease = bench.hold("gige-hw").unwrap();
    let outcome = run_experiment(
        &plan,
        &bench,
        &lease,
        BenchGeometry::scale(SCALE_PX_PER_MM),
        BenchTimeouts::default(),
        &sink,
    )
    .unwrap_or_else(|e| panic!("{e}; events {:?}", sink.events.lock().unwrap()));
    drop(lease);

    // Frames in each read-out, each run with its capture mode and twin.
    for (stem, size) in [
        ("b_ref", (512, 384)),
        ("hw-bin2x2-average_b_ref", (256, 192)),
        ("hw-dec2x2_b_m1", (256, 192)),
    ] {
        let path = outcome.frames_dir.join(format!("{stem}.tif"));
        let (image, _) = ffdic::image::read_tiff(&path).unwrap();
        assert_eq!((image.width(), image.height()), size, "{stem}");
    }
    let runs = &outcome.manifest.runs;
    let hw: Vec<_> = runs.iter().filter(|r| r.capture.is_some()).collect();
    assert_eq!(hw.len(), 2, "{runs:?}");
    for r in &hw {
        let twin = r.twin_of.as_deref().expect("a twin");
        assert!(runs.iter().any(|t| t.id == twin && t.capture.is_none()));
    }
    check_hardware_rows_match_their_twins(&outcome);
    // Restored: the camera reads out at full resolution again.
    let after = bench.status().unwrap().camera.settings;
    assert_eq!((after.binning, after.decimation), ((1, 1), (1, 1)));
    drop(bench);
    drop(fake);
}
