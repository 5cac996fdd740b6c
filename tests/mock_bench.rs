//! The mock bench end to end: the stage moves the target, the camera renders through the model
//! what the sensor sees there, DIC recovers the commanded move.

use ffdic::dic::{analyze, DicSettings};
use ffdic::experiment::ModelScene;
use ffdic::image::{Image, Roi};
use ffdic::model::{Camera as ModelCamera, ModelConfig, SpecklePattern};
use ffdic_hw::{Camera, Stage, StagePosition};
use ffdic_mocks::{new_bench, MockCamera, MockStage};
use std::time::Duration;

fn to_image(f: &ffdic_hw::Frame) -> Image {
    Image::from_vec(
        f.width,
        f.height,
        f.data.iter().map(|&v| v as f32).collect(),
    )
    .unwrap()
}

#[test]
fn commanded_move_is_recovered_through_mock_hardware() {
    let model_camera = ModelCamera {
        width: 480,
        height: 360,
        scale_px_per_mm: 20.0,
        exposure_level: 0.5,
        principal_dx_px: 0.0,
        principal_dy_px: 0.0,
    };
    let bench_model = ModelConfig::from_toml(
        "name = \"bench\"\n[effects.sensor_noise]\nfull_well_e = 30000.0\nread_noise_e = 1.5\ngain = 0.46\n[effects.quantization]\nbits = 16\n",
        std::path::Path::new("inline"),
    )
    .unwrap();
    let scene = ModelScene::new(
        model_camera,
        bench_model,
        &SpecklePattern::preset("b").unwrap(),
        2.0,
        5,
    )
    .unwrap();
    let bench = new_bench();
    let mut stage = MockStage::new(bench.clone(), 50.0, Duration::from_millis(5));
    let mut camera = MockCamera::new(scene, bench);
    stage.home(Duration::from_secs(1)).unwrap();
    let reference = to_image(&camera.acquire(1, Duration::from_secs(5)).unwrap()[0]);
    stage
        .move_absolute(StagePosition {
            x_mm: 0.5237,
            y_mm: -0.0210,
        })
        .unwrap();
    stage.wait_settled(Duration::from_secs(2)).unwrap();
    let moved = to_image(&camera.acquire(1, Duration::from_secs(5)).unwrap()[0]);
    let s = DicSettings {
        roi: Some(Roi::new(120, 90, 240, 180)),
        ..DicSettings::default()
    };
    let r = analyze(&reference, &moved, &s, None).unwrap();
    let (u, v) = (0.5237 * 20.0, -0.0210 * 20.0);
    assert_eq!(r.summary.valid, r.summary.points);
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
}
