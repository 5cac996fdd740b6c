//! Time to render one 2560x2160 frame of the paper's pattern b through the paper's bench model
//! (dots integrated over pixel apertures, shot and read noise, 16-bit ADC). The issue asks ≤ 2 s.

use ffdic::experiment::{pattern_dots, render_stage_frame, ExperimentSpec};
use ffdic::model::{ModelConfig, SpecklePattern};
use std::path::Path;

fn main() {
    divan::main();
}

#[divan::bench(sample_count = 5)]
fn render_pattern_b_2560x2160(bencher: divan::Bencher) {
    let spec = ExperimentSpec::paper();
    let model = ModelConfig::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("config/models/paper-bench.toml"),
    )
    .unwrap();
    let pattern = SpecklePattern::preset("b").unwrap();
    let dots = pattern_dots(&spec, &pattern, 1, 1).expect("the paper's target fits");
    bencher.bench(|| render_stage_frame(&spec, &model, &dots, (5.0, 0.0), 3));
}
