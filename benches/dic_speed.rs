//! POI/s of the DIC engine on a 1280x1080 analytically rendered speckle pair moved by
//! (64.3, 0.4) px, subset 41, prepare (pre-filter, B-spline coefficients, gradients, FFT guess)
//! included. `cargo bench --bench dic_speed`; divan prints the time per analysis, and the
//! POI counts are printed once so POI/s is that count over the time.

use ffdic::dic::{analyze, DicSettings, PoiGrid};
use ffdic::image::Image;
use ffdic::model::{render_dots, SpeckleLayout};
use std::sync::OnceLock;

const W: usize = 1280;
const H: usize = 1080;

fn pair() -> &'static (Image, Image) {
    static PAIR: OnceLock<(Image, Image)> = OnceLock::new();
    PAIR.get_or_init(|| {
        let layout = SpeckleLayout::jittered(
            (-100.0, -100.0, W as f64 + 100.0, H as f64 + 100.0),
            5.0,
            1.3,
            90.0,
            0.3,
            1,
        );
        let moved = layout.mapped(|x, y| (x + 64.3, y + 0.4), (1.0, 1.0));
        (
            render_dots(W, H, &layout.dots, 200.0, (1.0, 1.0)),
            render_dots(W, H, &moved.dots, 200.0, (1.0, 1.0)),
        )
    })
}

fn main() {
    let (r, d) = pair();
    for step in [20, 5] {
        let s = DicSettings {
            step_px: step,
            ..DicSettings::default()
        };
        let res = analyze(r, d, &s, None).unwrap();
        let mean_iter =
            res.points.iter().map(|p| p.iterations as f64).sum::<f64>() / res.points.len() as f64;
        println!(
            "step {step}: {} POIs ({}), {} valid, mean IC-GN iterations {mean_iter:.2}",
            res.points.len(),
            PoiGrid::new(&s, W, H).unwrap().len(),
            res.summary.valid
        );
    }
    divan::main();
}

#[divan::bench(args = [20, 5], sample_count = 10)]
fn analyze_1280x1080_subset41(bencher: divan::Bencher, step_px: usize) {
    let (r, d) = pair();
    let s = DicSettings {
        step_px,
        ..DicSettings::default()
    };
    bencher.bench(|| analyze(divan::black_box(r), divan::black_box(d), &s, None).unwrap());
}
