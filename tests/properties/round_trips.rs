//! 4. Round trips: a model through its TOML file, a dataset manifest through `dataset.json`.

use super::config;
use ffdic::dataset::{
    CameraInfo, DotProfile, Manifest, PatternInfo, Run, StageMove, MAX_EDGE_SOFTNESS_PX,
    MAX_PRINT_FEATURE_PX,
};
use ffdic::model::effects::{
    FillFactor, FixedPattern, IlluminationChange, LensDistortion, MotionBlur, PsfBlur,
    Quantization, Rotation, Scale, SensorNoise, StageError, StageMisalignment, TargetTilt,
    Vignetting,
};
use ffdic::model::{Effects, ModelConfig, Placement};
use ffdic_hw::{schemes_for, BinningDomain, BinningMode, HardwareScheme, ReductionCaps};
use proptest::num::f64 as float;
use proptest::prelude::*;
use serde_json::{Map, Value};
use std::path::Path;

/// Any finite f64: every binary exponent, subnormals and signed zeros, plus plain values.
fn finite() -> impl Strategy<Value = f64> + Clone {
    prop_oneof![
        -1e3f64..1e3,
        float::POSITIVE | float::NEGATIVE | float::NORMAL | float::SUBNORMAL | float::ZERO,
    ]
}

/// Finite and > 0.
fn positive() -> impl Strategy<Value = f64> + Clone {
    prop_oneof![
        1e-3f64..1e3,
        float::POSITIVE | float::NORMAL | float::SUBNORMAL
    ]
}

/// Finite and >= 0.
fn non_negative() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.0), positive()]
}

/// In (0, 1].
fn unit() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(1.0),
        (0.0f64..1.0).prop_filter("> 0", |v| *v > 0.0),
        float::POSITIVE | float::SUBNORMAL,
    ]
}

/// Any text: control characters, quotes, backslashes, newlines, any script.
fn text() -> impl Strategy<Value = String> {
    "(?s).{0,16}"
}

fn effects() -> impl Strategy<Value = Effects> {
    use prop::option::of;
    let geometry = (
        of(finite().prop_map(|angle_rad| StageMisalignment { angle_rad })),
        of((0.0f64..1e6).prop_map(|repeatability_um| StageError { repeatability_um })),
        of(finite().prop_map(|angle_rad| Rotation { angle_rad })),
        of(finite().prop_map(|ds| Scale { ds })),
        of(
            prop::array::uniform7(finite()).prop_map(|k| LensDistortion {
                k1: k[0],
                k2: k[1],
                p1: k[2],
                p2: k[3],
                centre_dx_px: k[4],
                centre_dy_px: k[5],
                norm_radius_px: k[6],
            }),
        ),
        of(non_negative().prop_map(|sigma_px| PsfBlur { sigma_px })),
        of((-0.3f64..0.3, -0.3f64..0.3, 1.0f64..1e4).prop_map(
            |(angle_about_y_rad, angle_about_x_rad, working_distance_mm)| TargetTilt {
                angle_about_y_rad,
                angle_about_x_rad,
                working_distance_mm,
            },
        )),
    );
    let sensor = (
        of((unit(), unit()).prop_map(|(fx, fy)| FillFactor { fx, fy })),
        of((positive(), non_negative(), positive()).prop_map(
            |(full_well_e, read_noise_e, gain)| SensorNoise {
                full_well_e,
                read_noise_e,
                gain,
            },
        )),
        of((finite(), finite()).prop_map(|(prnu, dsnu)| FixedPattern { prnu, dsnu })),
        of((1u32..=16).prop_map(|bits| Quantization { bits })),
        of(finite().prop_map(|v| Vignetting { v })),
        of((finite(), finite()).prop_map(|(gain, offset)| IlluminationChange { gain, offset })),
        of(
            (0.0f64..=50.0, finite()).prop_map(|(length_px, angle_rad)| MotionBlur {
                length_px,
                angle_rad,
            }),
        ),
    );
    // A user effect: its expressions come back as written, its value to the bit.
    let user = of(finite()).prop_map(|value| {
        value
            .map(|v| {
                let text = format!(
                    "u = \"c * x * tx\"\nv = \"c * (x^2 + y^2) * ty\"\n[params.c]\nvalue = {v:?}\nunit = \"1/px\"\nmin = -1e300\nmax = 1e300\n"
                );
                let e: ffdic::model::effects::UserEffect = toml::from_str(&text).unwrap();
                [("bow".to_string(), e)].into_iter().collect()
            })
            .unwrap_or_default()
    });
    (geometry, sensor, user).prop_map(|(g, s, user)| Effects {
        stage_misalignment: g.0,
        stage_error: g.1,
        rotation: g.2,
        scale: g.3,
        lens_distortion: g.4,
        psf_blur: g.5,
        target_tilt: g.6,
        fill_factor: s.0,
        sensor_noise: s.1,
        fixed_pattern: s.2,
        quantization: s.3,
        vignetting: s.4,
        illumination_change: s.5,
        motion_blur: s.6,
        user,
    })
}

/// A JSON value for the fields a manifest keeps without knowing them, floats from `number`.
fn json_value(
    number: impl Strategy<Value = f64> + Clone + 'static,
) -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::from),
        any::<u64>().prop_map(Value::from),
        number.prop_map(Value::from),
        text().prop_map(Value::String),
    ];
    leaf.prop_recursive(2, 8, 3, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..3).prop_map(Value::Array),
            prop::collection::btree_map(text(), inner, 0..3)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

/// Unknown fields beside known ones: the `x_` prefix keeps them off every known name.
fn extra(
    number: impl Strategy<Value = f64> + Clone + 'static,
) -> impl Strategy<Value = Map<String, Value>> {
    prop::collection::btree_map("x_[a-z0-9_]{0,8}", json_value(number), 0..3)
        .prop_map(|m| m.into_iter().collect())
}

/// A name that stays inside the dataset folder (letters and digits of any script first, so
/// never `.` or `..`; no separators, no control characters).
fn file_name() -> impl Strategy<Value = String> {
    r"[\w][\w .,()+-]{0,15}"
}

fn run(number: impl Strategy<Value = f64> + Clone + 'static) -> impl Strategy<Value = Run> {
    // Sizes positive, softness at least 0, contrast in (0, 1]: what `validate` accepts.
    let size = number
        .clone()
        .prop_map(f64::abs)
        .prop_filter("a size is positive", |v| *v > 0.0);
    let print = (
        prop::option::of(prop_oneof![
            Just(DotProfile::Gaussian),
            Just(DotProfile::Disk)
        ]),
        prop::option::of((1u32..=1000).prop_map(|k| k as f64 / 1000.0)),
        prop::option::of(number.clone().prop_map(f64::abs)),
        prop::option::of(prop::collection::vec(
            [number.clone(), number.clone()],
            0..4,
        )),
        prop::option::of(prop_oneof![
            Just(Placement::JitteredGrid),
            Just(Placement::Poisson)
        ]),
    );
    let pattern = (
        text(),
        prop::option::of(size.clone()),
        prop::option::of(size),
        print,
        extra(number.clone()),
    )
        .prop_map(
            |(
                label,
                dot_diameter_mm,
                dot_spacing_mm,
                (profile, contrast, edge_softness_mm, mtf, placement),
                extra,
            )| PatternInfo {
                label,
                dot_diameter_mm,
                dot_spacing_mm,
                profile,
                contrast,
                edge_softness_mm,
                mtf,
                placement,
                extra,
            },
        );
    (
        (text(), prop::option::of(pattern), file_name(), file_name()),
        (number.clone(), number.clone()),
        prop::collection::vec(file_name(), 0..3),
        prop::option::of(number.clone()),
        (prop::option::of(text()), capture_mode()),
        extra(number),
    )
        .prop_map(
            |(
                (id, pattern, reference, deformed),
                (dx_mm, dy_mm),
                repeat,
                exposure_us,
                (repeat_of, (capture, twin_of)),
                extra,
            )| Run {
                id,
                pattern,
                reference,
                deformed,
                stage: StageMove { dx_mm, dy_mm },
                repeat,
                exposure_us,
                repeat_of,
                capture,
                twin_of,
                extra,
            },
        )
}

/// A hardware capture mode (any scheme a camera with every reduction offers); no twin, which
/// must name an earlier run (`Manifest::validate`, unit-tested in `dataset::manifest`).
fn capture_mode() -> impl Strategy<Value = (Option<HardwareScheme>, Option<String>)> {
    let caps = ReductionCaps {
        binning_max: (4, 4),
        binning_mode: Some(BinningMode::Sum),
        binning_domain: BinningDomain::Charge,
        decimation_max: (4, 4),
    };
    (
        prop::option::of(prop::sample::select(schemes_for(&caps))),
        Just(None),
    )
}

/// A valid manifest whose floats come from `number` (positive ones from `positive_number`).
fn manifest(
    number: impl Strategy<Value = f64> + Clone + 'static,
    positive_number: impl Strategy<Value = f64> + Clone,
) -> impl Strategy<Value = Manifest> {
    let camera = (
        any::<usize>(),
        any::<usize>(),
        any::<u8>(),
        extra(number.clone()),
    )
        .prop_map(|(width, height, bit_depth, extra)| CameraInfo {
            width,
            height,
            bit_depth,
            extra,
        });
    (
        text(),
        positive_number.clone(),
        prop::option::of(camera),
        prop::option::of(positive_number),
        prop::collection::vec(run(number.clone()), 1..4),
        extra(number),
    )
        .prop_map(
            |(name, scale_px_per_mm, camera, stage_repeatability_um, runs, extra)| {
                let mut m = Manifest::new(&name, scale_px_per_mm);
                m.camera = camera;
                m.stage_repeatability_um = stage_repeatability_um;
                // Sizes no print has at this scale are refused by `validate`: left out.
                let mut runs = runs;
                for p in runs.iter_mut().filter_map(|r| r.pattern.as_mut()) {
                    let fits = |mm: &f64, max_px: f64| mm * scale_px_per_mm <= max_px;
                    p.dot_diameter_mm = p.dot_diameter_mm.filter(|d| fits(d, MAX_PRINT_FEATURE_PX));
                    p.dot_spacing_mm = p.dot_spacing_mm.filter(|d| fits(d, MAX_PRINT_FEATURE_PX));
                    p.edge_softness_mm =
                        p.edge_softness_mm.filter(|s| fits(s, MAX_EDGE_SOFTNESS_PX));
                }
                m.runs = runs;
                m.extra = extra;
                m
            },
        )
}

/// Numbers as a person or an instrument writes them: up to 9 significant digits, 0 to 6
/// decimals (26.0, 0.24, -5.125).
fn decimal() -> impl Strategy<Value = f64> + Clone {
    (-999_999_999i64..=999_999_999, 0i32..=6).prop_map(|(m, k)| m as f64 / 10f64.powi(k))
}

fn positive_decimal() -> impl Strategy<Value = f64> + Clone {
    (1i64..=999_999_999, 0i32..=6).prop_map(|(m, k)| m as f64 / 10f64.powi(k))
}

/// Writes, reads back, compares; also checks the written file is what `read` accepts.
fn check_manifest(m: Manifest) -> Result<(), TestCaseError> {
    prop_assert_eq!(
        m.validate(),
        Ok(()),
        "the generator made an invalid manifest"
    );
    let dir = tempfile::tempdir().expect("a temporary folder");
    m.write(dir.path()).expect("written");
    let back = Manifest::read(dir.path()).expect("read back");
    prop_assert_eq!(back, m);
    Ok(())
}

proptest! {
    #![proptest_config(config(64))]

    /// `from_toml(to_toml(m)) == m` for every valid model: all thirteen effects on or off,
    /// parameters anywhere in their valid ranges (any finite value where none is stated),
    /// names and descriptions with any characters.
    #[test]
    fn model_round_trips_through_toml(
        name in text(),
        description in text(),
        effects in effects(),
    ) {
        let model = ModelConfig { name, description, effects };
        prop_assert!(model.validate().is_ok(), "the generator made an invalid model");
        let text = model.to_toml();
        let back = ModelConfig::from_toml(&text, Path::new("generated.toml"))
            .map_err(|e| TestCaseError::fail(format!("{e}\n--- written:\n{text}")))?;
        prop_assert_eq!(back, model, "--- written:\n{}", text);
    }

    /// `read(write(m)) == m` for valid manifests with the numbers people write, unknown fields
    /// at every level included. `read` checks names and numbers only: no frame file need exist.
    #[test]
    fn manifest_round_trips_through_dataset_json(m in manifest(decimal(), positive_decimal())) {
        check_manifest(m)?;
    }

    /// The same with any finite float (computed stage moves, calibrated scales, unknown
    /// fields holding computed values). serde_json without its `float_roundtrip` feature parsed
    /// a 16–17 digit float one ulp off about one time in ten (55.393536131272924 read back as
    /// 55.39353613127293); the crate enables the feature, and this test holds it to that.
    #[test]
    fn manifest_round_trips_any_finite_float(m in manifest(finite(), positive())) {
        check_manifest(m)?;
    }
}
