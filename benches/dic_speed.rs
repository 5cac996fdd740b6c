//! POI/s of the DIC engine on 1280x1080 analytically rendered speckle pairs with camera-like
//! noise (σ = 0.5 % of full scale, as the paper's camera), subset 41, end to end: pre-filter,
//! B-spline coefficients, gradients, the global guess, seeds, propagation, validation and
//! strains. Two motions: a translation (64.3, 0.4) px, and a 1 % stretch along x with a 0.5°
//! rotation about the image centre. Noise-free renders flatter IC-GN (≈1 iteration per
//! point); these do not.
//!
//! `cargo bench --bench dic_speed`: the POI counts, valid points and mean IC-GN iterations are
//! printed once; divan prints the time per analysis, so POI/s is the count over the time.

use ffdic::dic::{analyze, DicSettings, PoiGrid};
use ffdic::image::Image;
use ffdic::model::{render_dots, SpeckleLayout};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::sync::OnceLock;

const W: usize = 1280;
const H: usize = 1080;
/// Full scale of the rendered images (background 200, dots up to ≈117 deep).
const FULL_SCALE: f64 = 255.0;
const NOISE_FRACTION_OF_FULL_SCALE: f64 = 0.005;

#[derive(Clone, Copy, Debug)]
enum Motion {
    Translation,
    StretchRotation,
}

fn noisy(mut image: Image, seed: u64) -> Image {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, NOISE_FRACTION_OF_FULL_SCALE * FULL_SCALE).unwrap();
    for v in image.data_mut() {
        *v += normal.sample(&mut rng) as f32;
    }
    image
}

fn pair(motion: Motion) -> &'static (Image, Image) {
    static PAIRS: OnceLock<[(Image, Image); 2]> = OnceLock::new();
    let pairs = PAIRS.get_or_init(|| {
        let layout = SpeckleLayout::jittered(
            (-100.0, -100.0, W as f64 + 100.0, H as f64 + 100.0),
            5.0,
            1.3,
            90.0,
            0.3,
            1,
        );
        let reference = noisy(render_dots(W, H, &layout.dots, 200.0, (1.0, 1.0)), 2);
        let translated = layout.mapped(|x, y| (x + 64.3, y + 0.4), (1.0, 1.0));
        let (c, s) = (0.5f64.to_radians().cos(), 0.5f64.to_radians().sin());
        let (cx, cy) = (W as f64 / 2.0, H as f64 / 2.0);
        // The dots are stretched along x but not turned by the 0.5° (the renderer draws
        // axis-aligned dots): a speed case, not an accuracy one.
        let stretched = layout.mapped(
            |x, y| {
                let (dx, dy) = (1.01 * (x - cx), y - cy);
                (cx + c * dx - s * dy, cy + s * dx + c * dy)
            },
            (1.01, 1.0),
        );
        let render =
            |l: &SpeckleLayout, seed| noisy(render_dots(W, H, &l.dots, 200.0, (1.0, 1.0)), seed);
        [
            (reference.clone(), render(&translated, 3)),
            (reference, render(&stretched, 4)),
        ]
    });
    match motion {
        Motion::Translation => &pairs[0],
        Motion::StretchRotation => &pairs[1],
    }
}

fn main() {
    for motion in [Motion::Translation, Motion::StretchRotation] {
        let (r, d) = pair(motion);
        for step in [20, 5] {
            let s = DicSettings {
                step_px: step,
                ..DicSettings::default()
            };
            let res = analyze(r, d, &s, None).unwrap();
            let mean_iter = res.points.iter().map(|p| p.iterations as f64).sum::<f64>()
                / res.points.len() as f64;
            println!(
                "{motion:?} step {step}: {} POIs ({}), {} valid, mean IC-GN iterations {mean_iter:.2}",
                res.points.len(),
                PoiGrid::new(&s, W, H).unwrap().len(),
                res.summary.valid
            );
        }
    }
    divan::main();
}

#[divan::bench(args = [20, 5], sample_count = 10)]
fn translation_1280x1080_subset41(bencher: divan::Bencher, step_px: usize) {
    bench(bencher, Motion::Translation, step_px);
}

#[divan::bench(args = [20, 5], sample_count = 10)]
fn stretch_rotation_1280x1080_subset41(bencher: divan::Bencher, step_px: usize) {
    bench(bencher, Motion::StretchRotation, step_px);
}

fn bench(bencher: divan::Bencher, motion: Motion, step_px: usize) {
    let (r, d) = pair(motion);
    let s = DicSettings {
        step_px,
        ..DicSettings::default()
    };
    bencher.bench(|| analyze(divan::black_box(r), divan::black_box(d), &s, None).unwrap());
}
