//! The engine on motions that are not a translation: rotations of 1–10°, uniform strains of
//! 1–10 %, a step in v and a blank region. Speckle is rendered analytically — Gaussian dots
//! integrated exactly over every pixel by the model's renderer, which shares no code with the
//! DIC engine — with the dots themselves moved (a rotated isotropic dot is still isotropic; a
//! stretched one is stretched along the axis), never an interpolated raster. Camera-like noise
//! (σ = 1 grey level on a 200-grey background, 0.5 %) is added to both images.
//!
//! Acceptance (issue 19): on an 800x800 ROI, ≥ 99 % of points valid, no valid point with an
//! error above 0.1 px, bias ≤ 0.01 px; across a step and a blank region no valid point with an
//! error above 0.5 px, and subsets wholly in the blank invalid.

use ffdic::dic::{analyze, DicResult, DicSettings, PoiStatus, ShapeFunction};
use ffdic::image::{Image, Roi};
use ffdic::model::{render_dots, SpeckleLayout};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const SIDE: usize = 1100;
const CENTRE: f64 = 550.0;
const NOISE_GREY: f64 = 1.0;

fn settings() -> DicSettings {
    DicSettings {
        step_px: 10,
        roi: Some(Roi::new(150, 150, 800, 800)),
        ..DicSettings::default()
    }
}

fn speckle(seed: u64) -> SpeckleLayout {
    SpeckleLayout::jittered(
        (-200.0, -200.0, SIDE as f64 + 200.0, SIDE as f64 + 200.0),
        5.0,
        1.3,
        90.0,
        0.3,
        seed,
    )
}

fn noisy(mut image: Image, seed: u64) -> Image {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, NOISE_GREY).unwrap();
    for v in image.data_mut() {
        *v += normal.sample(&mut rng) as f32;
    }
    image
}

fn render(layout: &SpeckleLayout) -> Image {
    render_dots(SIDE, SIDE, &layout.dots, 200.0, (1.0, 1.0))
}

/// Errors of the valid points against a truth u(X, Y), v(X, Y).
struct Errors {
    valid: usize,
    points: usize,
    worst_px: f64,
    bias_u_px: f64,
    bias_v_px: f64,
}

fn errors(result: &DicResult, truth: impl Fn(f64, f64) -> (f64, f64)) -> Errors {
    let (mut worst, mut su, mut sv, mut n) = (0.0f64, 0.0, 0.0, 0usize);
    for p in result.points.iter().filter(|p| p.status.is_valid()) {
        let (u, v) = truth(p.x, p.y);
        let (eu, ev) = (p.u - u, p.v - v);
        worst = worst.max(eu.abs()).max(ev.abs());
        su += eu;
        sv += ev;
        n += 1;
    }
    Errors {
        valid: n,
        points: result.points.len(),
        worst_px: worst,
        bias_u_px: su / n.max(1) as f64,
        bias_v_px: sv / n.max(1) as f64,
    }
}

fn check_affine(label: &str, map: impl Fn(f64, f64) -> (f64, f64), sigma_scale: (f64, f64)) {
    let layout = speckle(19);
    let reference = noisy(render(&layout), 1);
    let deformed = noisy(render(&layout.mapped(&map, sigma_scale)), 2);
    let result = analyze(&reference, &deformed, &settings(), None).unwrap();
    let e = errors(&result, |x, y| {
        let (xd, yd) = map(x, y);
        (xd - x, yd - y)
    });
    let fraction = e.valid as f64 / e.points as f64;
    println!(
        "{label}: {}/{} valid ({:.2} %), worst error of a valid point {:.4} px, bias u {:+.5} v {:+.5} px",
        e.valid,
        e.points,
        100.0 * fraction,
        e.worst_px,
        e.bias_u_px,
        e.bias_v_px
    );
    assert!(
        fraction >= 0.99,
        "{label}: only {:.2} % valid",
        100.0 * fraction
    );
    assert!(
        e.worst_px <= 0.1,
        "{label}: a valid point is {:.3} px off",
        e.worst_px
    );
    assert!(
        e.bias_u_px.abs() <= 0.01 && e.bias_v_px.abs() <= 0.01,
        "{label}: bias {:+.4}, {:+.4} px",
        e.bias_u_px,
        e.bias_v_px
    );
}

#[test]
fn rotations_of_1_to_10_degrees() {
    for degrees in [1.0f64, 3.0, 5.0, 7.0, 10.0] {
        let (c, s) = (degrees.to_radians().cos(), degrees.to_radians().sin());
        let rotate = move |x: f64, y: f64| {
            let (dx, dy) = (x - CENTRE, y - CENTRE);
            (CENTRE + c * dx - s * dy, CENTRE + s * dx + c * dy)
        };
        check_affine(&format!("rotation {degrees}°"), rotate, (1.0, 1.0));
    }
}

#[test]
fn uniform_strains_of_1_to_10_percent() {
    for (exx, eyy) in [
        (0.01, 0.0),
        (0.03, 0.0),
        (0.05, 0.0),
        (0.10, 0.0),
        (0.0, 0.10),
        (0.05, -0.02),
    ] {
        let stretch = move |x: f64, y: f64| {
            (
                CENTRE + (1.0 + exx) * (x - CENTRE),
                CENTRE + (1.0 + eyy) * (y - CENTRE),
            )
        };
        check_affine(
            &format!("strain exx {exx} eyy {eyy}"),
            stretch,
            (1.0 + exx, 1.0 + eyy),
        );
    }
}

#[test]
fn rotation_with_stretch_is_the_same_for_any_thread_count() {
    let (c, s) = (0.5f64.to_radians().cos(), 0.5f64.to_radians().sin());
    // 0.5° and a 1 % stretch along x: the dots become ellipses at 0.5°, which the renderer
    // cannot draw exactly, so this checks determinism, not accuracy.
    let map = move |x: f64, y: f64| {
        let (dx, dy) = (1.01 * (x - CENTRE), y - CENTRE);
        (CENTRE + c * dx - s * dy, CENTRE + s * dx + c * dy)
    };
    let layout = speckle(5);
    let reference = noisy(render(&layout), 3);
    let deformed = noisy(render(&layout.mapped(map, (1.01, 1.0))), 4);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| analyze(&reference, &deformed, &settings(), None).unwrap())
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.points.len(), two.points.len());
    for (a, b) in one.points.iter().zip(&two.points) {
        assert_eq!(a.status, b.status);
        assert!(a.u.to_bits() == b.u.to_bits() && a.v.to_bits() == b.v.to_bits());
    }
}

/// The step: material above `STEP_Y` stays, material below moves by `STEP_V` px in y.
const STEP_Y: usize = 600;
const STEP_V: f64 = -7.4;
/// The blank: a flat patch (background and noise only) of the specimen above the step.
const BLANK: Roi = Roi {
    x: 300,
    y: 250,
    width: 160,
    height: 160,
};

fn blank(mut image: Image) -> Image {
    for r in BLANK.y..BLANK.y + BLANK.height {
        for c in BLANK.x..BLANK.x + BLANK.width {
            image.set(c, r, 200.0);
        }
    }
    image
}

/// The reference and deformed frames of the step: the blank patch in both, the material below
/// `STEP_Y` moved by `STEP_V` in the deformed one, each with its own noise.
fn step_and_blank_frames() -> (Image, Image) {
    let layout = speckle(23);
    let reference = noisy(blank(render(&layout)), 5);
    let above = render(&layout);
    let below = render(&layout.mapped(|x, y| (x, y + STEP_V), (1.0, 1.0)));
    let mut deformed = blank(above);
    for r in STEP_Y..SIDE {
        for c in 0..SIDE {
            deformed.set(c, r, below.get(c, r));
        }
    }
    (reference, noisy(deformed, 6))
}

/// Prints every valid point more than 0.5 px from `truth`, for the failure's diagnosis.
fn print_wrong_valid_points(result: &DicResult, truth: impl Fn(f64, f64) -> (f64, f64)) {
    for p in result.points.iter().filter(|p| p.status.is_valid()) {
        let (u, v) = truth(p.x, p.y);
        if (p.u - u).abs().max((p.v - v).abs()) > 0.5 {
            println!(
                "  wrong valid point at ({}, {}): u {:.3} v {:.3} zncc {:.3} std {:.4} {:.4}",
                p.x, p.y, p.u, p.v, p.zncc, p.u_std_px, p.v_std_px
            );
        }
    }
}

#[test]
fn a_step_and_a_blank_region_mark_no_wrong_point_valid() {
    let (reference, deformed) = step_and_blank_frames();
    for subset_px in [41, 21] {
        let s = DicSettings {
            subset_px,
            ..settings()
        };
        let result = analyze(&reference, &deformed, &s, None).unwrap();
        // Below the line in the reference (Y ≥ STEP_Y + STEP_V... the material that stays
        // visible) moves by STEP_V; above it, nothing moves.
        let truth = |_x: f64, y: f64| {
            if y + 0.5 > STEP_Y as f64 {
                (0.0, STEP_V)
            } else {
                (0.0, 0.0)
            }
        };
        let e = errors(&result, truth);
        print_wrong_valid_points(&result, truth);
        // Wholly blank after the pre-filter (σ 0.7 px reaches ≈ 3σ) and the cubic B-spline
        // (two samples either side): texture leaks that far into the patch.
        let half = s.half_subset() as f64 + 4.0;
        let in_blank = |x: f64, y: f64| {
            x - half >= BLANK.x as f64
                && x + half < (BLANK.x + BLANK.width) as f64
                && y - half >= BLANK.y as f64
                && y + half < (BLANK.y + BLANK.height) as f64
        };
        let blank_points: Vec<_> = result
            .points
            .iter()
            .filter(|p| in_blank(p.x, p.y))
            .collect();
        for p in blank_points.iter().filter(|p| p.status.is_valid()) {
            println!(
                "  valid blank point at ({}, {}): u {:.3} v {:.3} zncc {:.3} std {:.4} {:.4}",
                p.x, p.y, p.u, p.v, p.zncc, p.u_std_px, p.v_std_px
            );
        }
        let half = s.half_subset() as f64;
        let far = |x: f64, y: f64| {
            let clear_of_blank = x + half < BLANK.x as f64
                || x - half >= (BLANK.x + BLANK.width) as f64
                || y + half < BLANK.y as f64
                || y - half >= (BLANK.y + BLANK.height) as f64;
            // Below the line, material within |STEP_V| of it is hidden in the deformed image.
            clear_of_blank && (y + half < STEP_Y as f64 || y - half > STEP_Y as f64 - STEP_V)
        };
        let far_points: Vec<_> = result.points.iter().filter(|p| far(p.x, p.y)).collect();
        let far_valid = far_points.iter().filter(|p| p.status.is_valid()).count();
        let mut statuses = std::collections::BTreeMap::new();
        for p in &result.points {
            *statuses.entry(p.status.as_str()).or_insert(0usize) += 1;
        }
        println!(
            "subset {subset_px}: {}/{} valid, worst valid error {:.4} px, {} points wholly in the blank, \
             {far_valid}/{} valid away from step and blank; statuses {statuses:?}",
            e.valid,
            e.points,
            e.worst_px,
            blank_points.len(),
            far_points.len()
        );
        assert!(
            e.worst_px <= 0.5,
            "subset {subset_px}: a valid point is {:.3} px off",
            e.worst_px
        );
        assert!(!blank_points.is_empty());
        assert!(
            blank_points.iter().all(|p| !p.status.is_valid()),
            "subset {subset_px}: a point wholly in the blank is valid"
        );
        assert!(
            blank_points.iter().all(|p| matches!(
                p.status,
                PoiStatus::NoTexture | PoiStatus::LowCorrelation | PoiStatus::NoContrast
            )),
            "subset {subset_px}: blank points should fail for lack of texture"
        );
        assert!(
            far_valid as f64 >= 0.99 * far_points.len() as f64,
            "subset {subset_px}: only {far_valid}/{} valid away from the step and the blank",
            far_points.len()
        );
    }
}

#[test]
fn a_rotation_sequence_beyond_one_subset_is_followed_by_moving_the_reference() {
    // 0° to 50° in steps of 10° about the image centre: from about 30° a first-order subset
    // of the first frame no longer holds (a gradient beyond 0.5 is refused as implausible),
    // so the reference must move on, and the displacements accumulate through it.
    let layout = speckle(31);
    let reference = noisy(render(&layout), 10);
    let angles: Vec<f64> = (1..=5).map(|k| 10.0 * k as f64).collect();
    let rotate = |degrees: f64| {
        let (c, s) = (degrees.to_radians().cos(), degrees.to_radians().sin());
        move |x: f64, y: f64| {
            let (dx, dy) = (x - CENTRE, y - CENTRE);
            (CENTRE + c * dx - s * dy, CENTRE + s * dx + c * dy)
        }
    };
    let frames: Vec<Image> = angles
        .iter()
        .enumerate()
        .map(|(k, &a)| noisy(render(&layout.mapped(rotate(a), (1.0, 1.0))), 11 + k as u64))
        .collect();
    let s = DicSettings {
        roi: Some(Roi::new(350, 350, 400, 400)),
        ..settings()
    };
    let results = ffdic::dic::analyze_sequence(&reference, frames, &s, |_| {}).unwrap();
    assert_eq!(results.len(), angles.len());
    for (frame, &degrees) in results.iter().zip(&angles) {
        let map = rotate(degrees);
        let e = errors(&frame.result, |x, y| {
            let (xd, yd) = map(x, y);
            (xd - x, yd - y)
        });
        println!(
            "{degrees}°: reference frame {}, {}/{} valid, worst {:.4} px, bias {:+.5} {:+.5} px",
            frame.reference_index, e.valid, e.points, e.worst_px, e.bias_u_px, e.bias_v_px
        );
        assert!(
            e.valid as f64 >= 0.95 * e.points as f64,
            "{degrees}°: {}/{} valid",
            e.valid,
            e.points
        );
        assert!(
            e.worst_px <= 0.1,
            "{degrees}°: a valid point is {:.3} px off",
            e.worst_px
        );
    }
    assert_eq!(results[0].reference_index, 0);
    assert!(
        results.last().unwrap().reference_index > 0,
        "the reference never moved"
    );
}

#[test]
fn a_quadratic_field_needs_the_second_order_shape_function() {
    // u = a(X − c)², v = a(Y − c)²: the gradient changes across every subset. Each dot moves
    // with the field and is stretched by the local (diagonal) Jacobian; the field's curvature
    // within one dot (a·σ² ≈ 2e-4 px) is below anything measured here.
    const A: f64 = 1e-4;
    let layout = speckle(41);
    let moved = SpeckleLayout {
        dots: layout
            .dots
            .iter()
            .map(|d| ffdic::model::GaussianDot {
                x_px: d.x_px + A * (d.x_px - CENTRE).powi(2),
                y_px: d.y_px + A * (d.y_px - CENTRE).powi(2),
                sigma_x_px: d.sigma_x_px * (1.0 + 2.0 * A * (d.x_px - CENTRE)),
                sigma_y_px: d.sigma_y_px * (1.0 + 2.0 * A * (d.y_px - CENTRE)),
                depth: d.depth,
            })
            .collect(),
    };
    let reference = noisy(render(&layout), 20);
    let deformed = noisy(render(&moved), 21);
    let truth = |x: f64, y: f64| (A * (x - CENTRE).powi(2), A * (y - CENTRE).powi(2));
    let mut worst = Vec::new();
    for shape in [ShapeFunction::Affine, ShapeFunction::Quadratic] {
        let s = DicSettings {
            shape,
            step_px: 20,
            ..settings()
        };
        let result = analyze(&reference, &deformed, &s, None).unwrap();
        let e = errors(&result, truth);
        println!(
            "{shape:?}: {}/{} valid, worst {:.4} px, bias u {:+.5} v {:+.5} px",
            e.valid, e.points, e.worst_px, e.bias_u_px, e.bias_v_px
        );
        assert!(e.valid as f64 >= 0.99 * e.points as f64, "{shape:?}");
        worst.push((e.worst_px, e.bias_u_px.abs().max(e.bias_v_px.abs())));
    }
    // First order: the subset's mean of a·Δx² (a·(41² − 1)/12 = 0.014 px) appears as a bias.
    let (affine, quadratic) = (worst[0], worst[1]);
    assert!(
        affine.1 > 0.005,
        "the first-order bias should show: {affine:?}"
    );
    assert!(quadratic.1 <= 0.002, "second order bias {quadratic:?}");
    assert!(quadratic.0 <= 0.02, "second order worst {quadratic:?}");
}
