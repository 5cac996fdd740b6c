//! Renders, through a model, the frames a camera on the bench would deliver for an experiment,
//! and writes them as a dataset (`ffdic-dataset/1`). Deterministic for a seed: every frame's
//! noise seed is derived from (seed, pattern, frame), every pattern's dots from (seed, pattern).

use super::captures::{capture_plan, layout_seed, TargetCapture};
use super::spec::ExperimentSpec;
use crate::dataset::{CameraInfo, DatasetError, Manifest, PatternInfo};
use crate::image::{write_tiff_u16, Image, ImageError};
use crate::model::derive_seed;
use crate::model::{render_frame, FrameSpec, ModelConfig, SpecklePattern, TargetDot, TooManyDots};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    #[error(transparent)]
    Target(#[from] TooManyDots),
    #[error("cannot create {path}: {source}")]
    Create {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// The dots of pattern number `index`, covering the field of view plus every move.
pub fn pattern_dots(
    spec: &ExperimentSpec,
    pattern: &SpecklePattern,
    index: usize,
    seed: u64,
) -> Result<Vec<TargetDot>, TooManyDots> {
    let travel = spec
        .all_moves()
        .iter()
        .map(|m| m.dx_mm.abs().max(m.dy_mm.abs()))
        .fold(0.0, f64::max);
    pattern.dots(
        spec.camera.field_mm(travel + 2.0),
        derive_seed(seed, index as u64, 0xD075),
    )
}

/// Renders one frame of pattern `index` at a commanded stage position.
pub fn render_stage_frame(
    spec: &ExperimentSpec,
    model: &ModelConfig,
    dots: &[TargetDot],
    (dx_mm, dy_mm): (f64, f64),
    frame_seed: u64,
) -> Image {
    let frame = FrameSpec {
        stage_dx_mm: dx_mm,
        stage_dy_mm: dy_mm,
        moved: dx_mm != 0.0 || dy_mm != 0.0,
        seed: frame_seed,
    };
    render_frame(&spec.camera, &model.effects, dots, &frame)
}

/// Writes the dataset into `out` (created if needed); `progress(done, total)` after each frame.
pub fn simulate_dataset(
    spec: &ExperimentSpec,
    model: &ModelConfig,
    seed: u64,
    out: &Path,
    progress: &dyn Fn(usize, usize),
) -> Result<Manifest, SimulateError> {
    std::fs::create_dir_all(out).map_err(|source| SimulateError::Create {
        path: out.to_owned(),
        source,
    })?;
    let moves = spec.all_moves();
    let patterns = spec.patterns();
    let labels: Vec<&str> = patterns.iter().map(|p| p.label.as_str()).collect();
    let captures = capture_plan(&labels, &moves, spec.static_frames, spec.repeats);
    let total: usize = captures.iter().map(TargetCapture::frame_count).sum();
    let mut done = 0;
    let mut manifest = Manifest::new(&spec.name, spec.camera.scale_px_per_mm);
    manifest.camera = Some(CameraInfo {
        width: spec.camera.width,
        height: spec.camera.height,
        bit_depth: 16,
        extra: Default::default(),
    });
    manifest.extra.insert(
        "simulated_with".into(),
        serde_json::json!({"model": model.name, "seed": seed}),
    );
    // Frame numbers run on over a pattern's captures: every frame gets its own noise.
    let mut frame_no = vec![0u64; patterns.len()];
    let mut dots = Vec::new();
    for target in &captures {
        let pi = target.pattern_index;
        let pattern = &patterns[pi];
        if target.capture == 1 || spec.new_layout_per_repeat {
            dots = pattern_dots(spec, pattern, pi, layout_seed(seed, target.capture))?;
        }
        let mut shoot = |name: &str, stage: (f64, f64)| -> Result<(), SimulateError> {
            let img = render_stage_frame(
                spec,
                model,
                &dots,
                stage,
                derive_seed(seed, pi as u64, frame_no[pi]),
            );
            frame_no[pi] += 1;
            write_tiff_u16(&out.join(name), &img)?;
            done += 1;
            progress(done, total);
            Ok(())
        };
        for shot in target.shots(&moves) {
            shoot(shot.file, (shot.dx_mm, shot.dy_mm))?;
            if let Some(run) = shot.run {
                manifest.runs.push(target.manifest_run(
                    run,
                    &moves[run.move_index],
                    pattern_info(&pattern.label, pattern, true),
                    None,
                ));
            }
        }
    }
    manifest.write(out)?;
    Ok(manifest)
}

/// What a dataset records of the speckle in front of the camera: every parameter of the pattern.
/// `characterised` says the print is known exactly (a simulation renders the very print it names,
/// and a bench's request may say so: its `profile` is stated, see `diagnose::print`); a print on a
/// real bench is otherwise only nominal, and a comparison calibrates it to the frames.
pub(crate) fn pattern_info(
    label: &str,
    pattern: &crate::model::SpecklePattern,
    characterised: bool,
) -> PatternInfo {
    PatternInfo {
        label: label.to_string(),
        dot_diameter_mm: Some(pattern.dot_diameter_mm),
        dot_spacing_mm: Some(pattern.dot_spacing_mm),
        profile: characterised.then_some(pattern.profile),
        contrast: Some(pattern.contrast),
        edge_softness_mm: Some(pattern.edge_softness_mm),
        ..PatternInfo::default()
    }
}
