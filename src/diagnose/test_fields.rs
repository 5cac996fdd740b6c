//! Synthetic DIC results for the module's unit tests: a grid of valid points whose displacements a
//! function gives, plus Gaussian noise of a chosen σ — an analysis whose truth is known without
//! rendering or correlating anything, so a step is tested apart from the engine and the model.

use super::discrepancy::CommonPoint;
use crate::dataset::Manifest;
use crate::dic::{DicResult, DicSettings, PoiGrid, PoiResult, PoiStatus, Summary};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// An analysis of a `width`×`height` frame at `settings`' grid whose every point moved by
/// `field(x, y)` (px of that frame) plus independent noise of σ `noise_px` per component.
pub(super) fn synthetic_result(
    (width, height): (usize, usize),
    settings: &DicSettings,
    field: impl Fn(f64, f64) -> (f64, f64),
    noise_px: f64,
    seed: u64,
) -> DicResult {
    let grid = PoiGrid::new(settings, width, height).expect("a frame larger than a subset");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_px).expect("a finite σ");
    let mut points = Vec::with_capacity(grid.xs.len() * grid.ys.len());
    for &y in &grid.ys {
        for &x in &grid.xs {
            let (x, y) = (x as f64, y as f64);
            let (u, v) = field(x, y);
            let mut p = PoiResult::invalid(x, y, PoiStatus::Converged, 1.0, 1);
            p.u = u + noise.sample(&mut rng);
            p.v = v + noise.sample(&mut rng);
            points.push(p);
        }
    }
    DicResult {
        settings: settings.clone(),
        summary: Summary::of(&points),
        grid,
        points,
        global_offset_px: (0, 0),
        strain_gauge_px: settings.strain_gauge_px(),
    }
}

/// A manifest at 26 px/mm whose runs move by `moves_mm`, run i of pattern `patterns[i % len]`;
/// `known_dots` states every print's dot size.
pub(super) fn manifest(moves_mm: &[(f64, f64)], patterns: &[&str], known_dots: bool) -> Manifest {
    let runs: Vec<_> = moves_mm
        .iter()
        .enumerate()
        .map(|(i, (dx, dy))| {
            let label = patterns[i % patterns.len()];
            let pattern = if known_dots {
                serde_json::json!({"label": label, "dot_diameter_mm": 0.5, "dot_spacing_mm": 1.0})
            } else {
                serde_json::json!({"label": label})
            };
            serde_json::json!({"id": format!("r{i}"), "pattern": pattern,
                "reference": format!("ref_{label}.tif"), "deformed": format!("def{i}.tif"),
                "stage": {"dx_mm": dx, "dy_mm": dy}})
        })
        .collect();
    serde_json::from_value(serde_json::json!({"format": crate::dataset::FORMAT,
        "name": "synthetic", "scale_px_per_mm": 26.0, "runs": runs}))
    .expect("a valid manifest")
}

/// Field differences (measured − model, px) on a grid of a 2560x2160 frame every 64 px, of a run
/// that moved by `move_px`: `field(p, t)` at p (px from the centre), plus noise of σ `noise_px`.
pub(super) fn field_points(
    move_px: (f64, f64),
    field: impl Fn((f64, f64), (f64, f64)) -> (f64, f64),
    noise_px: f64,
    seed: u64,
) -> Vec<CommonPoint> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_px).expect("a finite σ");
    let mut points = Vec::new();
    for (row, y) in (32..2160).step_by(64).enumerate() {
        for (col, x) in (32..2560).step_by(64).enumerate() {
            let (x, y) = (x as f64, y as f64);
            let (du, dv) = field((x - 1280.0, y - 1080.0), move_px);
            points.push(CommonPoint {
                index: row * 40 + col,
                x,
                y,
                du: du + noise.sample(&mut rng),
                dv: dv + noise.sample(&mut rng),
                fit_du: 0.0,
                fit_dv: 0.0,
            });
        }
    }
    points
}
