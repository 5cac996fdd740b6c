//! The forward model against independent physics: aperture MTF, photon transfer, and DIC on
//! simulated frames with every effect off.

use ffdic::dic::{analyze, DicSettings};
use ffdic::model::effects::{FillFactor, SensorNoise};
use ffdic::model::{
    render_dots, render_frame, Camera, DotShape, Effects, FrameSpec, GaussianDot, SpecklePattern,
};

/// sinc(x) = sin(πx)/(πx).
fn sinc(x: f64) -> f64 {
    if x == 0.0 {
        1.0
    } else {
        (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x)
    }
}

/// A camera of the tests' bench: 13 px/mm, the white at half the full scale, the principal
/// point at the centre.
fn camera_13_px_per_mm(width: usize, height: usize) -> Camera {
    Camera {
        width,
        height,
        scale_px_per_mm: 13.0,
        exposure_level: 0.5,
        principal_dx_px: 0.0,
        principal_dy_px: 0.0,
    }
}

#[test]
fn uniform_scene_renders_uniform_for_any_aperture() {
    for (fx, fy) in [(1.0, 1.0), (0.5, 1.0), (0.25, 0.5), (0.1, 0.1)] {
        let img = render_dots::<GaussianDot>(64, 48, &[], 1234.0, (fx, fy));
        assert!(img.data().iter().all(|&v| v == 1234.0));
        // Dots far outside the frame change nothing either.
        let far = GaussianDot {
            x_px: -500.0,
            y_px: 20.0,
            sigma_x_px: 2.0,
            sigma_y_px: 2.0,
            depth: 500.0,
        };
        let img = render_dots(64, 48, &[far], 1234.0, (fx, fy));
        assert!(img.data().iter().all(|&v| (v - 1234.0).abs() < 1e-3));
    }
}

/// Amplitude of the component of frequency k/n cycles per px along a row.
fn fundamental(row: &[f32], k: usize) -> f64 {
    let n = row.len() as f64;
    let (mut re, mut im) = (0.0, 0.0);
    for (i, &v) in row.iter().enumerate() {
        let ph = 2.0 * std::f64::consts::PI * k as f64 * i as f64 / n;
        re += v as f64 * ph.cos();
        im += v as f64 * ph.sin();
    }
    2.0 * (re * re + im * im).sqrt() / n
}

#[test]
fn sinusoidal_target_contrast_follows_the_aperture_mtf() {
    // A grating of vertical Gaussian lines, period 8 px: its fundamental (1/8 cycle/px) is a
    // sinusoid whose rendered amplitude must scale as sinc(fx·f) with the aperture fx.
    let period = 8.0;
    let width = 256usize;
    let lines: Vec<GaussianDot> = (-4..(width as i32 / 8 + 4))
        .map(|k| GaussianDot {
            x_px: k as f64 * period + 0.3,
            y_px: 2.0,
            sigma_x_px: 1.2,
            sigma_y_px: 1e5,
            depth: 100.0,
        })
        .collect();
    let amp = |fx: f64| {
        let img = render_dots(width, 4, &lines, 1000.0, (fx, 1.0));
        fundamental(img.row(2), width / 8)
    };
    let f = 1.0 / period;
    // The point-sampled amplitude (aperture → 0) is the scene's own sinusoid.
    let point = amp(1e-6);
    for fx in [1.0, 0.75, 0.5, 0.25] {
        let expect = sinc(fx * f);
        let got = amp(fx) / point;
        assert!(
            (got / expect - 1.0).abs() < 0.01,
            "fx={fx}: {got} vs sinc {expect}"
        );
    }
}

#[test]
fn noise_variance_follows_the_photon_transfer_line() {
    let gain_e_per_dn = 0.5;
    let effects = Effects {
        sensor_noise: Some(SensorNoise {
            full_well_e: 30000.0,
            read_noise_e: 2.0,
            gain: gain_e_per_dn,
        }),
        ..Effects::default()
    };
    let (mut means, mut vars) = (Vec::new(), Vec::new());
    for level in [0.05, 0.15, 0.3, 0.45] {
        let camera = Camera {
            width: 200,
            height: 200,
            scale_px_per_mm: 10.0,
            exposure_level: level,
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        };
        let frame = |seed| FrameSpec {
            stage_dx_mm: 0.0,
            stage_dy_mm: 0.0,
            moved: false,
            seed,
        };
        let a = render_frame(&camera, &effects, &[], &frame(1));
        let b = render_frame(&camera, &effects, &[], &frame(2));
        // Half the variance of the difference of two frames: free of any fixed pattern.
        let n = a.data().len() as f64;
        let mean = a
            .data()
            .iter()
            .chain(b.data())
            .map(|&v| v as f64)
            .sum::<f64>()
            / (2.0 * n);
        let diff: Vec<f64> = a
            .data()
            .iter()
            .zip(b.data())
            .map(|(x, y)| (x - y) as f64)
            .collect();
        let dm = diff.iter().sum::<f64>() / n;
        let var = diff.iter().map(|d| (d - dm).powi(2)).sum::<f64>() / (n - 1.0) / 2.0;
        means.push(mean);
        vars.push(var);
    }
    // Least-squares slope of variance against mean.
    let k = means.len() as f64;
    let (mx, my) = (means.iter().sum::<f64>() / k, vars.iter().sum::<f64>() / k);
    let sxy: f64 = means
        .iter()
        .zip(&vars)
        .map(|(x, y)| (x - mx) * (y - my))
        .sum();
    let sxx: f64 = means.iter().map(|x| (x - mx).powi(2)).sum();
    let slope = sxy / sxx;
    let expect = 1.0 / gain_e_per_dn;
    assert!(
        (slope / expect - 1.0).abs() < 0.05,
        "slope {slope} vs 1/gain {expect}"
    );
}

fn dic_settings() -> DicSettings {
    DicSettings {
        roi: Some(ffdic::image::Roi::new(150, 110, 300, 220)),
        ..DicSettings::default()
    }
}

#[test]
fn every_effect_off_dic_recovers_the_commanded_translation() {
    let camera = camera_13_px_per_mm(640, 480);
    let pattern = SpecklePattern::preset("b").unwrap();
    let dots = pattern.dots(camera.field_mm(8.0), 7).unwrap();
    let effects = Effects::default();
    let reference = render_frame(
        &camera,
        &effects,
        &dots,
        &FrameSpec {
            stage_dx_mm: 0.0,
            stage_dy_mm: 0.0,
            moved: false,
            seed: 1,
        },
    );
    for (dx_mm, dy_mm) in [(0.0123, 0.0), (0.0, -0.031), (5.0, 0.031)] {
        let moved = render_frame(
            &camera,
            &effects,
            &dots,
            &FrameSpec {
                stage_dx_mm: dx_mm,
                stage_dy_mm: dy_mm,
                moved: true,
                seed: 2,
            },
        );
        let r = analyze(&reference, &moved, &dic_settings(), None).unwrap();
        let (u, v) = (dx_mm * 13.0, dy_mm * 13.0);
        assert_eq!(r.summary.valid, r.summary.points);
        assert!(
            (r.summary.u.mean - u).abs() <= 0.005,
            "({dx_mm},{dy_mm}): u {} vs {u}",
            r.summary.u.mean
        );
        assert!(
            (r.summary.v.mean - v).abs() <= 0.005,
            "({dx_mm},{dy_mm}): v {} vs {v}",
            r.summary.v.mean
        );
    }
}

#[test]
fn fill_factor_lowers_contrast_but_not_the_mean() {
    let camera = camera_13_px_per_mm(300, 200);
    let dots = SpecklePattern::preset("b")
        .unwrap()
        .dots(camera.field_mm(2.0), 3)
        .unwrap();
    let frame = FrameSpec {
        stage_dx_mm: 0.0,
        stage_dy_mm: 0.0,
        moved: false,
        seed: 0,
    };
    let full = render_frame(&camera, &Effects::default(), &dots, &frame);
    let e = Effects {
        fill_factor: Some(FillFactor { fx: 0.5, fy: 0.5 }),
        ..Effects::default()
    };
    let quarter = render_frame(&camera, &e, &dots, &frame);
    let (m1, s1) = full.mean_std();
    let (m2, s2) = quarter.mean_std();
    assert!((m1 - m2).abs() / m1 < 0.002, "mean {m1} vs {m2}");
    // A smaller aperture averages less: the speckle keeps more contrast.
    assert!(s2 > s1, "std {s2} should exceed {s1}");
}

/// The complex 2D Fourier coefficient of `img` at (kx / width, ky / height) cycles per px,
/// divided by the pixel count (k = 0, 0 is the mean).
fn coefficient(img: &ffdic::image::Image, kx: usize, ky: usize) -> (f64, f64) {
    let (w, h) = (img.width(), img.height());
    let (mut re, mut im) = (0.0, 0.0);
    for y in 0..h {
        for (x, &v) in img.row(y).iter().enumerate() {
            let ph = 2.0
                * std::f64::consts::PI
                * (kx as f64 * x as f64 / w as f64 + ky as f64 * y as f64 / h as f64);
            re += v as f64 * ph.cos();
            im -= v as f64 * ph.sin();
        }
    }
    let n = (w * h) as f64;
    (re / n, im / n)
}

/// A lens blur against its closed form: a Gaussian PSF of σ multiplies every spatial frequency
/// f of the optical image by exp(−2π²σ²f²) and leaves the mean (f = 0) alone — it spreads the
/// dots' darkening, it does not add to it. Checked on a lattice of dots (period 8 px) through
/// the model's whole renderer, pixel aperture included (the same with and without the blur).
#[test]
fn a_lens_blur_follows_the_gaussian_transfer_function_and_keeps_the_mean() {
    use ffdic::model::effects::PsfBlur;
    use ffdic::model::TargetDot;
    let camera = Camera {
        width: 128,
        height: 64,
        scale_px_per_mm: 10.0,
        exposure_level: 0.5,
        principal_dx_px: 0.0,
        principal_dy_px: 0.0,
    };
    // Dots every 0.8 mm = 8 px, σ 0.12 mm = 1.2 px, over the field and beyond its edges.
    let dots: Vec<TargetDot> = (-12..=12)
        .flat_map(|i| {
            (-8..=8).map(move |j| TargetDot {
                x_mm: 0.8 * i as f64,
                y_mm: 0.8 * j as f64,
                shape: DotShape::Gaussian { sigma_mm: 0.12 },
                depth: 0.6,
            })
        })
        .collect();
    let frame = FrameSpec {
        stage_dx_mm: 0.0,
        stage_dy_mm: 0.0,
        moved: false,
        seed: 1,
    };
    let sharp = render_frame(&camera, &Effects::default(), &dots, &frame);
    for sigma_px in [0.6, 1.27, 2.0] {
        let effects = Effects {
            psf_blur: Some(PsfBlur { sigma_px }),
            ..Effects::default()
        };
        let blurred = render_frame(&camera, &effects, &dots, &frame);
        let (m0, m1) = (coefficient(&sharp, 0, 0).0, coefficient(&blurred, 0, 0).0);
        assert!(
            (m1 / m0 - 1.0).abs() < 1e-4,
            "σ {sigma_px}: mean {m1} against {m0} without the blur"
        );
        // (16, 0) and (0, 8): one cycle per 8 px along x and along y; (16, 8) diagonally.
        for (kx, ky) in [(16, 0), (0, 8), (16, 8)] {
            let f2 = (kx as f64 / 128.0).powi(2) + (ky as f64 / 64.0).powi(2);
            let (a, b) = (coefficient(&sharp, kx, ky), coefficient(&blurred, kx, ky));
            let ratio = b.0.hypot(b.1) / a.0.hypot(a.1);
            let expect = (-2.0 * std::f64::consts::PI.powi(2) * sigma_px * sigma_px * f2).exp();
            assert!(
                (ratio / expect - 1.0).abs() < 0.01,
                "σ {sigma_px}, f² {f2}: transfer {ratio} against exp(−2π²σ²f²) = {expect}"
            );
        }
    }
}

/// The effects that act between the reference and a moved frame (`EffectId::leaves_the_reference`)
/// leave the reference frame as the model without them renders it, pixel for pixel: a diagnosis
/// keeps the print calibrated against the reference for a candidate among them instead of
/// refitting it. Rendered, not assumed: every such effect is set, on a print whose frames move.
/// Pattern b on a 160x120 camera at 13 px/mm, rendered with `effects` at the stage's origin or
/// moved 2 mm along x.
fn render_b(effects: &Effects, moved: bool) -> ffdic::image::Image {
    let camera = camera_13_px_per_mm(160, 120);
    let dots = SpecklePattern::preset("b")
        .unwrap()
        .dots(camera.field_mm(8.0), 11)
        .unwrap();
    let frame = FrameSpec {
        stage_dx_mm: if moved { 2.0 } else { 0.0 },
        stage_dy_mm: 0.0,
        moved,
        seed: 5,
    };
    render_frame(&camera, effects, &dots, &frame)
}

#[test]
fn effects_between_frames_leave_the_reference_frame_unchanged() {
    use ffdic::model::effects::{
        IlluminationChange, MotionBlur, PsfBlur, Rotation, Scale, StageError, StageMisalignment,
        Vignetting,
    };
    use ffdic::model::EffectId;
    let render = |effects: &Effects, moved: bool| render_b(effects, moved).data().to_vec();
    let between = Effects {
        stage_misalignment: Some(StageMisalignment { angle_rad: 0.01 }),
        stage_error: Some(StageError {
            repeatability_um: 20.0,
        }),
        rotation: Some(Rotation { angle_rad: 0.01 }),
        scale: Some(Scale { ds: 0.01 }),
        illumination_change: Some(IlluminationChange {
            gain: 1.2,
            offset: 300.0,
        }),
        motion_blur: Some(MotionBlur {
            length_px: 3.0,
            angle_rad: 0.3,
        }),
        ..Effects::default()
    };
    let set: Vec<EffectId> = between.enabled();
    assert!(set.iter().all(|e| e.leaves_the_reference()), "{set:?}");
    assert_eq!(
        EffectId::ALL
            .iter()
            .filter(|e| e.leaves_the_reference())
            .count(),
        set.len(),
        "every effect that leaves the reference is set here"
    );
    assert_eq!(between.reference_part(), Effects::default());
    assert_eq!(render(&between, false), render(&Effects::default(), false));
    // The same effects do change a moved frame, and effects on the reference are kept: the
    // comparison can fail.
    assert_ne!(render(&between, true), render(&Effects::default(), true));
    let optics = Effects {
        psf_blur: Some(PsfBlur { sigma_px: 0.8 }),
        vignetting: Some(Vignetting { v: 0.1 }),
        ..between.clone()
    };
    assert_eq!(
        optics.reference_part().enabled(),
        [EffectId::PsfBlur, EffectId::Vignetting]
    );
    assert_ne!(render(&optics, false), render(&Effects::default(), false));
}

/// What the residual of `frames`' mean leaves after the best line through `clean` (a gain and
/// an offset): its RMS, DN.
fn rms_beside_line(frames: &[Vec<f32>], clean: &[f32]) -> f64 {
    let n = clean.len() as f64;
    let mean: Vec<f64> = (0..clean.len())
        .map(|i| frames.iter().map(|f| f[i] as f64).sum::<f64>() / frames.len() as f64)
        .collect();
    let (mx, my) = (
        clean.iter().map(|&v| v as f64).sum::<f64>() / n,
        mean.iter().sum::<f64>() / n,
    );
    let sxy: f64 = clean
        .iter()
        .zip(&mean)
        .map(|(&x, &y)| (x as f64 - mx) * (y - my))
        .sum();
    let sxx: f64 = clean.iter().map(|&x| (x as f64 - mx).powi(2)).sum();
    let gain = sxy / sxx;
    let ss: f64 = clean
        .iter()
        .zip(&mean)
        .map(|(&x, &y)| (y - my - gain * (x as f64 - mx)).powi(2))
        .sum();
    (ss / n).sqrt()
}

/// An effect that only adds noise (of those [`EffectId::keeps_the_print`] holds) leaves the light
/// as it was: the mean of its frames over seeds is the noiseless frame up to a gain and an offset
/// (the sensor's DN scale), with a residual that falls as 1/√seeds. That is what lets a noise
/// candidate's comparison keep the calibrated print (`SceneFrom::Rematch`). A blur changes the
/// light: its residual stays.
#[test]
fn effects_that_only_add_noise_leave_the_light_as_it_was() {
    use ffdic::model::effects::PsfBlur;
    use ffdic::model::EffectId;
    let camera = camera_13_px_per_mm(160, 120);
    let dots = SpecklePattern::preset("b")
        .unwrap()
        .dots(camera.field_mm(2.0), 11)
        .unwrap();
    let render = |effects: &Effects, seed: u64| {
        let frame = FrameSpec {
            stage_dx_mm: 0.0,
            stage_dy_mm: 0.0,
            moved: false,
            seed,
        };
        render_frame(&camera, effects, &dots, &frame)
            .data()
            .to_vec()
    };
    let clean = render(&Effects::default(), 1);
    let noise = Effects {
        sensor_noise: Some(SensorNoise {
            full_well_e: 30000.0,
            read_noise_e: 5.0,
            gain: 0.5,
        }),
        ..Effects::default()
    };
    assert!(noise.enabled().iter().all(|e| e.keeps_the_print()));
    assert_eq!(noise.print_image(), Effects::default());
    assert_ne!(noise.reference_part(), Effects::default());
    let residual = |effects: &Effects, seeds: u64| {
        let frames: Vec<Vec<f32>> = (0..seeds).map(|s| render(effects, 100 + s)).collect();
        rms_beside_line(&frames, &clean)
    };
    let (one, sixteen) = (residual(&noise, 1), residual(&noise, 16));
    // Pure noise: 1/4 after 16 seeds (0.25 ± the estimate's scatter over 19,200 pixels).
    assert!(one > 1.0, "the noise is there: {one} DN");
    assert!((sixteen / one - 0.25).abs() < 0.05, "{sixteen} / {one}");
    // A blur on top is light changed: its residual does not average away.
    let blurred = Effects {
        psf_blur: Some(PsfBlur { sigma_px: 1.0 }),
        ..noise.clone()
    };
    assert_ne!(blurred.print_image(), Effects::default());
    let (one, sixteen) = (residual(&blurred, 1), residual(&blurred, 16));
    assert!(sixteen / one > 0.5, "{sixteen} / {one}");
    assert!(!EffectId::PsfBlur.keeps_the_print());
}

/// A user's intensity effect multiplies the moved frame's irradiance by 1 + its expression at
/// each pixel (px from the image centre) and leaves the reference as it was.
#[test]
fn a_user_intensity_effect_lights_the_moved_frame_only() {
    let render = render_b;
    let mut lamp = Effects::default();
    lamp.user.insert(
        "lamp".into(),
        toml::from_str(
            "intensity = \"ax * x + ay * y\"\n[params.ax]\nvalue = 1e-3\nmin = -1.0\nmax = 1.0\n[params.ay]\nvalue = -5e-4\nmin = -1.0\nmax = 1.0\n",
        )
        .unwrap(),
    );
    assert_eq!(lamp.reference_part(), Effects::default());
    let none = Effects::default();
    assert_eq!(
        render(&lamp, false).data(),
        render(&none, false).data(),
        "the reference is lit as before"
    );
    let (with, without) = (render(&lamp, true), render(&none, true));
    let (cx, cy) = (79.5, 59.5);
    for (row, col) in [(0, 0), (10, 150), (60, 80), (119, 3), (119, 159)] {
        let expected = 1.0 + 1e-3 * (col as f64 - cx) - 5e-4 * (row as f64 - cy);
        let ratio = f64::from(with.get(col, row)) / f64::from(without.get(col, row));
        assert!(
            (ratio - expected).abs() < 1e-5,
            "({col}, {row}): {ratio} against {expected}"
        );
    }
}
