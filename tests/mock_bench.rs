//! The mock bench end to end: the stage moves the target, the camera renders through the model
//! what the sensor sees there, DIC recovers the commanded move.

use ffdic::bench::ModelScene;
use ffdic::dic::{analyze, DicSettings};
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

/// A mock camera with the sensor's own 2x2 averaging binning in `domain` and decimation by 2,
/// on a bench whose truth is `model_toml`, looking at preset `b`.
fn reducing_camera(
    model_toml: &str,
    size: (usize, usize),
    exposure_level: f64,
    domain: ffdic_hw::BinningDomain,
) -> (MockCamera<ModelScene>, MockStage) {
    let model_camera = ModelCamera {
        width: size.0,
        height: size.1,
        scale_px_per_mm: 20.0,
        exposure_level,
        principal_dx_px: 0.0,
        principal_dy_px: 0.0,
    };
    let bench_model = ModelConfig::from_toml(model_toml, std::path::Path::new("inline")).unwrap();
    let pattern = SpecklePattern::preset("b").unwrap();
    let scene = ModelScene::new(model_camera, bench_model, &pattern, 2.0, 5).unwrap();
    let bench = new_bench();
    let mut stage = MockStage::new(bench.clone(), 50.0, Duration::from_millis(5));
    stage.home(Duration::from_secs(1)).unwrap();
    let caps = ffdic_hw::ReductionCaps {
        binning_max: (2, 2),
        binning_mode: Some(ffdic_hw::BinningMode::Average),
        binning_domain: domain,
        decimation_max: (2, 2),
    };
    (MockCamera::new(scene, bench).with_reduction(caps), stage)
}

/// Selects the hardware scheme `name` (or full resolution) and grabs one frame.
fn grab_in(camera: &mut MockCamera<ModelScene>, name: Option<&str>) -> Image {
    let base = ffdic_hw::CameraSettings::default();
    let settings = match name {
        Some(n) => {
            let scheme = camera
                .info()
                .hardware_schemes
                .iter()
                .find(|s| s.name == n)
                .unwrap_or_else(|| panic!("{n} not offered"))
                .clone();
            scheme.applied_to(&base)
        }
        None => base,
    };
    let applied = camera.apply(&settings).unwrap();
    assert_eq!(
        (applied.binning, applied.decimation),
        (settings.binning, settings.decimation)
    );
    to_image(&camera.acquire(1, Duration::from_secs(5)).unwrap()[0])
}

/// The temporal noise variance per pixel (DN²) of two frames of the same scene: half the
/// variance of their difference (the scene cancels), and the frames' mean signal (DN).
fn temporal_variance(a: &Image, b: &Image) -> (f64, f64) {
    let n = a.data().len() as f64;
    let d: Vec<f64> = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(&x, &y)| x as f64 - y as f64)
        .collect();
    let mean_d = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean_d).powi(2)).sum::<f64>() / (n - 1.0) / 2.0;
    let signal = a.data().iter().map(|&v| v as f64).sum::<f64>() / n;
    (var, signal)
}

/// The mock sensor's read-out against photon transfer written out here (EMVA 1288; Janesick,
/// *Photon Transfer*, 2007), not taken from the model: a pixel of mean signal S DN at conversion
/// gain g e⁻/DN and read noise σ e⁻ has a temporal variance S/g + (σ/g)² + 1/12 DN² (shot,
/// read, rounding). A 2x2 block averaged digitally carries a quarter of the four pixels' sum:
/// S/(4g) + (σ/g)²/4 + (1/12)/4 + 1/12 (each pixel's ADC, then the average rounded); averaged
/// after charge binning, the block is read once: S/(4g) + (σ/g)²/16 + 1/12; a decimated pixel
/// is one sensor pixel. A bench in low light with a large read noise (σ = 30 e⁻ at S ≈ 1100 e⁻)
/// tells the domains apart by a factor 1.5. Each figure comes from ≥ 20,000 output pixels of a
/// difference of two frames, so its relative standard error is ≤ 1 %; the 5 % bound holds 5σ.
/// (The darkest speckle pixels clip at 0 DN — the model has no pedestal — which lowers the
/// measured variance of full-resolution pixels by about 1.5 %.)
#[test]
fn binned_and_decimated_read_noise_follows_photon_transfer() {
    let (gain, read_e) = (1.0, 30.0);
    let model = format!(
        "name = \"dim\"\n[effects.sensor_noise]\nfull_well_e = 60000.0\nread_noise_e = {read_e}\ngain = {gain}\n[effects.quantization]\nbits = 16\n"
    );
    let q = 1.0 / 12.0;
    for domain in [
        ffdic_hw::BinningDomain::Digital,
        ffdic_hw::BinningDomain::Charge,
    ] {
        let (mut camera, _stage) = reducing_camera(&model, (320, 256), 0.03, domain);
        let cases: [(Option<&str>, f64, f64, f64); 3] = [
            (None, 1.0, 1.0, q),
            (
                Some("hw:bin2x2-average"),
                4.0,
                if domain == ffdic_hw::BinningDomain::Charge {
                    16.0
                } else {
                    4.0
                },
                if domain == ffdic_hw::BinningDomain::Charge {
                    q
                } else {
                    q / 4.0 + q
                },
            ),
            (Some("hw:dec2x2"), 1.0, 1.0, q),
        ];
        for (scheme, shot_div, read_div, rounding) in cases {
            let (a, b) = (grab_in(&mut camera, scheme), grab_in(&mut camera, scheme));
            let (var, signal) = temporal_variance(&a, &b);
            let predicted =
                signal / gain / shot_div + (read_e / gain).powi(2) / read_div + rounding;
            assert!(
                (var / predicted - 1.0).abs() < 0.05,
                "{domain:?} {scheme:?}: variance {var:.2} DN², photon transfer {predicted:.2} (signal {signal:.1} DN)"
            );
        }
    }
}

/// Issue 17: on the mock bench (the paper's sensor), the camera's own 2x2 averaging binning and
/// the synthesised ff100 of full-resolution frames of the same pattern and move give the same
/// DIC error within the noise: the standard deviations of u and v differ by less than three
/// standard errors of their difference (each from the block bootstrap's 95 % interval), and so
/// do the mean displacements (standard error σ/√(independent blocks)).
#[test]
fn hardware_average_binning_matches_the_synthesised_ff100_within_the_noise() {
    let model = "name = \"bench\"\n[effects.sensor_noise]\nfull_well_e = 30000.0\nread_noise_e = 1.5\ngain = 0.46\n[effects.quantization]\nbits = 16\n";
    let (mut camera, mut stage) =
        reducing_camera(model, (640, 512), 0.5, ffdic_hw::BinningDomain::Digital);
    let reference_full = grab_in(&mut camera, None);
    let reference_hw = grab_in(&mut camera, Some("hw:bin2x2-average"));
    stage
        .move_absolute(StagePosition {
            x_mm: 0.5137,
            y_mm: 0.0,
        })
        .unwrap();
    stage.wait_settled(Duration::from_secs(2)).unwrap();
    let moved_full = grab_in(&mut camera, None);
    let moved_hw = grab_in(&mut camera, Some("hw:bin2x2-average"));
    let ff100 = ffdic::reduce::Scheme::preset("ff100").unwrap();
    let reduce = |i: &Image| ffdic::reduce::reduce(i, &ff100).unwrap();
    let s = DicSettings {
        subset_px: 21,
        step_px: 8,
        ..DicSettings::default()
    };
    let synthesised = analyze(&reduce(&reference_full), &reduce(&moved_full), &s, None).unwrap();
    let hardware = analyze(&reference_hw, &moved_hw, &s, None).unwrap();
    let se = |st: &ffdic::dic::Stats| (st.std_ci95[1] - st.std_ci95[0]) / (2.0 * 1.96);
    for (axis, a, b) in [
        ("u", &synthesised.summary.u, &hardware.summary.u),
        ("v", &synthesised.summary.v, &hardware.summary.v),
    ] {
        let (se_a, se_b) = (se(a), se(b));
        assert!(se_a > 0.0 && se_b > 0.0, "{axis}: intervals {a:?} {b:?}");
        let se_diff = (se_a * se_a + se_b * se_b).sqrt();
        assert!(
            (a.std - b.std).abs() < 3.0 * se_diff,
            "{axis} std: synthesised {:.5} ± {se_a:.5}, hardware {:.5} ± {se_b:.5} px",
            a.std,
            b.std
        );
        // Blocks of the bootstrap are the independent units: the mean's standard error is
        // about the std's spread over them.
        let blocks = (a.count as f64 / 16.0).max(1.0);
        let se_mean = (a.std.powi(2) + b.std.powi(2)).sqrt() / blocks.sqrt();
        assert!(
            (a.mean - b.mean).abs() < 3.0 * se_mean,
            "{axis} mean: synthesised {:.5}, hardware {:.5} px (se {se_mean:.5})",
            a.mean,
            b.mean
        );
    }
}
