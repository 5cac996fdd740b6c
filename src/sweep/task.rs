//! One shard: render the reference and the moved frame once, then for each scheme reduce both,
//! correlate and measure the error against the model's own truth. Numerics only.

use super::plan::{task_effects, Plan, Shard};
use super::spec::SweepError;
use crate::dic::{DicError, PreparedReference, Watch};
use crate::model::{project, render_frame_until, FrameSpec};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Dot diameters of the print axis are in pixels of the 2x2-reduced image: the paper's
/// convention (its 1280x1080 images of a 2560x2160 sensor).
pub const REFERENCE_BLOCK_PX: f64 = 2.0;

/// What one task measured. Errors are against the displacement the model itself imposes at the
/// image centre (commanded move through the model's stage and lens), in reduced px.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskResult {
    pub id: String,
    pub points: usize,
    pub valid: usize,
    pub truth_u_px: f64,
    pub truth_v_px: f64,
    pub u_bias_px: f64,
    pub v_bias_px: f64,
    pub u_std_px: f64,
    pub v_std_px: f64,
    pub exx_std: f64,
    pub eyy_std: f64,
    pub exy_std: f64,
    /// Wall time of the task's share of its shard (rendering split over its schemes), s.
    pub elapsed_s: f64,
}

/// Runs every task of `shard`; the results in the shard's task order. `cancelled` is asked
/// before each rendering and task and before every DIC point (a shard of a large sensor
/// takes seconds): once it says so, [`SweepError::Cancelled`].
pub fn run_shard(
    plan: &Plan,
    shard: &Shard,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Result<Vec<TaskResult>, SweepError> {
    let check = || {
        if cancelled() {
            Err(SweepError::Cancelled)
        } else {
            Ok(())
        }
    };
    let Some(first) = shard.tasks.first() else {
        return Ok(Vec::new());
    };
    let started = Instant::now();
    let spec = &plan.spec;
    let camera = &spec.camera;
    let effects = task_effects(
        &plan.base_effects,
        first.noise,
        first.psf_sigma_px,
        first.aperture,
    );
    let pattern = first
        .print
        .pattern(camera.scale_px_per_mm, REFERENCE_BLOCK_PX);
    let step_mm = REFERENCE_BLOCK_PX / camera.scale_px_per_mm;
    let (dx_mm, dy_mm) = (
        spec.move_mm[0] + first.subpixel_px[0] * step_mm,
        spec.move_mm[1] + first.subpixel_px[1] * step_mm,
    );
    let margin_mm = dx_mm.abs().max(dy_mm.abs()) + 2.0;
    let dots = pattern
        .dots(
            camera.field_mm(margin_mm),
            crate::model::derive_seed(first.seed, 0, 0xD075),
        )
        .map_err(|e| SweepError::Task(e.to_string()))?;
    let reference_frame = FrameSpec {
        stage_dx_mm: 0.0,
        stage_dy_mm: 0.0,
        moved: false,
        seed: crate::model::derive_seed(first.seed, 1, 0xF2A3),
    };
    let moved_frame = FrameSpec {
        stage_dx_mm: dx_mm,
        stage_dy_mm: dy_mm,
        moved: true,
        seed: crate::model::derive_seed(first.seed, 2, 0xF2A3),
    };
    let render = |frame: &FrameSpec| {
        render_frame_until(camera, &effects, &dots, frame, cancelled).ok_or(SweepError::Cancelled)
    };
    let reference = render(&reference_frame)?;
    let moved = render(&moved_frame)?;
    // The target point on the optical axis at the reference position, where it lands in each.
    let at_ref = project(camera, &effects, &reference_frame, 0.0, 0.0);
    let at_moved = project(camera, &effects, &moved_frame, 0.0, 0.0);
    let render_s = started.elapsed().as_secs_f64() / shard.tasks.len() as f64;

    let mut results = Vec::with_capacity(shard.tasks.len());
    for task in &shard.tasks {
        check()?;
        let started = Instant::now();
        let reduce = |image| {
            crate::reduce::reduce(image, &task.scheme).map_err(|e| SweepError::Task(e.to_string()))
        };
        let (r, m) = (reduce(&reference)?, reduce(&moved)?);
        let (bx, by) = (task.scheme.x.block as f64, task.scheme.y.block as f64);
        let (truth_u_px, truth_v_px) = ((at_moved.0 - at_ref.0) / bx, (at_moved.1 - at_ref.1) / by);
        let watch = || Watch {
            progress: None,
            cancelled: Some(cancelled),
        };
        let result = PreparedReference::new(&r, &spec.dic)
            .and_then(|p| p.correlate_watched(&m, watch()))
            .map_err(|e| match e {
                DicError::Cancelled => SweepError::Cancelled,
                other => SweepError::Task(format!("task {}: {other}", task.id)),
            })?;
        let s = result.summary;
        results.push(TaskResult {
            id: task.id.clone(),
            points: s.points,
            valid: s.valid,
            truth_u_px,
            truth_v_px,
            u_bias_px: s.u.mean - truth_u_px,
            v_bias_px: s.v.mean - truth_v_px,
            u_std_px: s.u.std,
            v_std_px: s.v.std,
            exx_std: s.exx.std,
            eyy_std: s.eyy.std,
            exy_std: s.exy.std,
            elapsed_s: render_s + started.elapsed().as_secs_f64(),
        });
    }
    Ok(results)
}
