//! A user's intensity effect as a candidate (`[effects.user.NAME] intensity = "…"` with a
//! parameter still without a value): fitted on the moved frames' light maps, as the catalogue's
//! vignetting is on the references' mean maps ([`super::fit_image_stats::fit_vignetting`]).
//!
//! Per moved frame and block k of its 8×8 light map, the light change q_k
//! ([`super::image_stats::light_change`]: the moved frame's light against its reference's on the
//! same part of the print, measured over the model's) is what the moved frame's irradiance
//! changed by beyond the model: q_k = c·(1 + f(p_k, t; θ)), f the user's expression at the
//! block's centre p_k (px from the axis) for the run's move t, c one constant per moved frame (a
//! uniform change is the catalogue's `illumination_change`: an expression's constant term is not
//! identifiable beside c). The print's texture divides out. Gauss–Newton on central
//! differences, each parameter held within its range; standard errors from the normal matrix,
//! scaled by the reduced χ² when the blocks scatter more than their errors.

use super::fit_user_effect::{null_start, user_fit};
use super::image_stats::light_change;
use super::measurement::Measurement;
use super::results::{Comparison, GeometricTerms, ImageFit};
use crate::model::effects::user::UserField;
use crate::model::effects::UserKind;
use crate::model::Effects;
use nalgebra::{DMatrix, DVector};

/// The most Gauss–Newton steps; an expression linear in its parameters needs one or two.
const MAX_STEPS: usize = 12;

/// One block of a moved frame's light change: where it is, the run's move, and the ratio q.
#[derive(Clone, Copy, Debug)]
struct Block {
    /// Index of its moved frame (its constant c).
    frame: usize,
    p: (f64, f64),
    t: (f64, f64),
    q: f64,
    se: f64,
}

/// The blocks of every moved frame with light maps on both sides ([`light_change`]), and the
/// number of those frames.
fn blocks(meas: &Measurement, before: &Comparison) -> (Vec<Block>, usize) {
    let (cx, cy) = before.model.nominal.camera(0).centre();
    let mut out = Vec::new();
    let mut frames = 0;
    for im in before.images.iter().filter(|i| i.run.is_some()) {
        let Some(ri) = meas
            .manifest
            .runs
            .iter()
            .position(|r| im.run.as_ref() == Some(&r.id))
        else {
            continue;
        };
        let run = &meas.manifest.runs[ri];
        let [tx, ty] = before
            .model
            .nominal
            .actual_move_px(ri, (run.stage.dx_mm, run.stage.dy_mm));
        let light = light_change((&im.measured, &im.model));
        if light.is_empty() {
            continue;
        }
        out.extend(light.into_iter().map(|b| Block {
            frame: frames,
            p: (b.x - cx, b.y - cy),
            t: (tx, ty),
            q: b.q,
            se: b.se,
        }));
        frames += 1;
    }
    (out, frames)
}

/// The weighted residuals (q − c·(1 + f))/se at parameters `theta` and constants `c`.
fn residuals(blocks: &[Block], field: &UserField, theta: &[f64], c: &[f64]) -> DVector<f64> {
    DVector::from_iterator(
        blocks.len(),
        blocks.iter().map(|b| {
            let g = 1.0 + field.relative_intensity(b.p, b.t, theta);
            (b.q - c[b.frame] * g) / b.se
        }),
    )
}

/// Whether the normal matrix fixes every column: its correlation form (unit diagonal) has no
/// eigenvalue near zero, as it has when a column is a combination of others (a constant term
/// beside the frames' constants).
fn identifies(normal: &DMatrix<f64>) -> bool {
    let d: Vec<f64> = normal.diagonal().iter().map(|v| v.sqrt()).collect();
    if !d.iter().all(|v| *v > 0.0 && v.is_finite()) {
        return false;
    }
    let correlation = DMatrix::from_fn(normal.nrows(), normal.ncols(), |i, j| {
        normal[(i, j)] / (d[i] * d[j])
    });
    correlation.symmetric_eigenvalues().min() > 1e-9
}

/// The fitted parameters, their standard errors; None when the blocks cannot identify them (a
/// singular normal matrix, too few blocks, a value that is not finite).
fn gauss_newton(
    blocks: &[Block],
    frames: usize,
    field: &UserField,
    mut theta: Vec<f64>,
    ranges: &[(f64, f64)],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = theta.len();
    let m = n + frames;
    if blocks.len() <= m {
        return None;
    }
    let mut c = vec![1.0; frames];
    let step: Vec<f64> = ranges.iter().map(|&(lo, hi)| 1e-6 * (hi - lo)).collect();
    let mut se = vec![f64::INFINITY; n];
    for _ in 0..MAX_STEPS {
        let r = residuals(blocks, field, &theta, &c);
        let mut jac = DMatrix::<f64>::zeros(blocks.len(), m);
        for j in 0..n {
            let (mut hi, mut lo) = (theta.clone(), theta.clone());
            hi[j] += step[j];
            lo[j] -= step[j];
            let d = (residuals(blocks, field, &hi, &c) - residuals(blocks, field, &lo, &c))
                / (2.0 * step[j]);
            jac.set_column(j, &d);
        }
        for (k, b) in blocks.iter().enumerate() {
            jac[(k, n + b.frame)] = -(1.0 + field.relative_intensity(b.p, b.t, &theta)) / b.se;
        }
        let normal = jac.transpose() * &jac;
        if !identifies(&normal) {
            return None;
        }
        let inverse = normal.cholesky()?.inverse();
        let delta = -(&inverse * (jac.transpose() * &r));
        if !delta.iter().all(|d| d.is_finite()) {
            return None;
        }
        let dof = (blocks.len() - m) as f64;
        let scale = (r.norm_squared() / dof).max(1.0);
        se = (0..n).map(|j| (inverse[(j, j)] * scale).sqrt()).collect();
        let mut settled = true;
        for (j, (value, &(lo, hi))) in theta.iter_mut().zip(ranges).enumerate() {
            let next = (*value + delta[j]).clamp(lo, hi);
            settled &= (next - *value).abs() <= 1e-3 * se[j];
            *value = next;
        }
        for (f, cf) in c.iter_mut().enumerate() {
            *cf += delta[n + f];
        }
        if settled {
            break;
        }
    }
    Some((theta, se))
}

/// Fits user effect `name` of `model` on the moved frames' light change; None when it is not a
/// proposed intensity effect of the model, or when these frames cannot identify its parameters.
pub fn fit_user_intensity(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    name: &str,
) -> Option<ImageFit> {
    let effect = model.user.get(name).filter(|e| e.is_proposed())?;
    let field = effect.field().ok()?;
    if field.kind() != UserKind::Intensity {
        return None;
    }
    let ranges: Vec<(f64, f64)> = effect.params.values().map(|p| (p.min, p.max)).collect();
    let start = null_start(&ranges);
    let (blocks, frames) = blocks(meas, before);
    let (values, stderr) = gauss_newton(&blocks, frames, &field, start, &ranges)?;
    Some(user_fit(
        (name, effect),
        (&values, &stderr),
        model.clone(),
        GeometricTerms::default(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::UserEffect;

    /// An intensity ramp on two moved frames' blocks, each frame with its own constant and the
    /// blocks' scatter at their errors: the ramp's slopes come back within three errors, and
    /// a constant term (what the frames' constants already hold) leaves the fit singular.
    #[test]
    fn a_ramp_on_the_moved_frames_is_found_beside_each_frame_s_constant() {
        let lamp: UserEffect = toml::from_str(
            "intensity = \"gx * x + gy * y\"\n[params.gx]\nmin = -1e-3\nmax = 1e-3\n[params.gy]\nmin = -1e-3\nmax = 1e-3\n",
        )
        .unwrap();
        let field = lamp.field().unwrap();
        let truth = [3e-5, -2e-5];
        let mut blocks = Vec::new();
        let mut noise = 0.37f64;
        for (frame, c) in [0.98, 1.03].into_iter().enumerate() {
            for j in 0..8 {
                for i in 0..8 {
                    let p = (i as f64 * 160.0 - 560.0, j as f64 * 135.0 - 472.5);
                    let t = (130.0 * frame as f64, 0.0);
                    // A deterministic scatter of about one error, alternating in sign.
                    noise = (noise * 997.0).fract();
                    let se = 1e-3;
                    let q = c * (1.0 + field.relative_intensity(p, t, &truth))
                        + se * (2.0 * noise - 1.0) * 1.7;
                    blocks.push(Block { frame, p, t, q, se });
                }
            }
        }
        let ranges = [(-1e-3, 1e-3); 2];
        let (values, se) = gauss_newton(&blocks, 2, &field, vec![0.0, 0.0], &ranges).unwrap();
        for k in 0..2 {
            assert!(
                (values[k] - truth[k]).abs() < 3.0 * se[k] && se[k] < 2e-6,
                "{k}: {} ± {} (truth {})",
                values[k],
                se[k],
                truth[k]
            );
        }
        let constant: UserEffect =
            toml::from_str("intensity = \"g\"\n[params.g]\nmin = -1.0\nmax = 1.0\n").unwrap();
        let constant = constant.field().unwrap();
        assert!(gauss_newton(&blocks, 2, &constant, vec![0.0], &[(-1.0, 1.0)]).is_none());
    }
}
