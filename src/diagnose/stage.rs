//! Where the stage landed: the travel scale, the misalignment angle and each run's rigid landing
//! offset, fitted to the measured mean displacements.
//!
//! A commanded move lands within the stage's repeatability, so every run carries its own rigid
//! offset (the paper's ≈0.4 px unintended y component on a 5 mm move is one). The fit:
//!
//! 1. travel scale and misalignment by Gauss–Newton on the mean displacement of every run and
//!    scheme, the model's mean computed from its own projection (rotation, scale and distortion in
//!    the model accounted for), with the current offsets removed;
//! 2. each run's landing ρ_r = the mean over its schemes of measured − model mean (full-resolution
//!    px): what the data say the stage did beyond travel and misalignment;
//! 3. the offset applied to the model is ρ_r, clipped per axis to the stage's envelope
//!    (±3σ of its repeatability) when a repeatability is known — the model's `stage_error`, else
//!    the dataset's `stage_repeatability_um` — and free when none is stated.
//!
//! Steps 1–2 alternate three times. An offset beyond the envelope stays in the discrepancy as its
//! rigid part, where `diagnose` finds it (candidate `stage_error`). The clip is a hard envelope
//! rather than a Gaussian prior on purpose: a run's mean displacement is known to ≈0.003 px, so a
//! prior of any realistic width would not constrain it at all.
//!
//! ρ_r also holds the difference of the two sides' sub-pixel biases; with one scheme the two
//! cannot be told apart (a 0.01 px bias is a 0.4 µm landing error at 26 px/mm), which is why a
//! dataset that states a tight repeatability lets the bias speak.

use super::nominal::Nominal;
use super::scene::Scene;
use super::stage_landing::{RepeatabilitySource, StageLanding};
use crate::dic::DicResult;
use crate::model::effects::StageError;
use crate::model::Effects;
use crate::reduce::Scheme;

/// One DIC analysis of the measurement to fit the stage against.
pub struct StageObservation<'a> {
    /// Index of the run in the manifest.
    pub run: usize,
    pub commanded: (f64, f64),
    pub scheme: &'a Scheme,
    pub result: &'a DicResult,
}

/// The repeatability that bounds the offsets: the model's, else the dataset's.
pub fn repeatability(
    model: &Effects,
    stated_um: Option<f64>,
) -> (Option<f64>, RepeatabilitySource) {
    match (model.stage_error, stated_um) {
        (Some(e), _) => (Some(e.repeatability_um), RepeatabilitySource::Model),
        (None, Some(r)) => (Some(r), RepeatabilitySource::Dataset),
        (None, None) => (None, RepeatabilitySource::Unstated),
    }
}

/// Per analysis: (run, commanded move, measured mean displacement (full px), its standard
/// error (full px), valid positions (full px)).
type Observed = (usize, (f64, f64), (f64, f64), f64, Vec<(f64, f64)>);

fn observed(obs: &[StageObservation], inflation: f64) -> Vec<Observed> {
    obs.iter()
        .filter_map(|o| {
            let bx = o.scheme.x.block as f64;
            let by = o.scheme.y.block as f64;
            let valid: Vec<_> = o
                .result
                .points
                .iter()
                .filter(|p| p.status.is_valid())
                .collect();
            if valid.is_empty() {
                return None;
            }
            let n = valid.len() as f64;
            let mu = valid.iter().map(|p| p.u).sum::<f64>() / n;
            let mv = valid.iter().map(|p| p.v).sum::<f64>() / n;
            // Scatter about the mean (real fields included: conservative) over the independent
            // points (overlapping subsets share their noise).
            let var = valid
                .iter()
                .map(|p| ((p.u - mu) * bx).powi(2) + ((p.v - mv) * by).powi(2))
                .sum::<f64>()
                / (2.0 * n);
            let se = (var * inflation.max(1.0) / n).sqrt();
            // Every valid position: a subsample would weigh a quadratic field differently from
            // the measured mean.
            let pos = valid.iter().map(|p| o.scheme.to_full(p.x, p.y)).collect();
            Some((o.run, o.commanded, (mu * bx, mv * by), se, pos))
        })
        .collect()
}

/// Fits travel scale, misalignment and landing offsets (module doc) into `nominal`. `runs` is the
/// number of runs in the manifest; `inflation` the variance inflation of overlapping subsets.
pub fn fit_stage(
    nominal: &mut Nominal,
    model: &Effects,
    obs: &[StageObservation],
    runs: usize,
    stated_um: Option<f64>,
    inflation: f64,
) {
    let (rep, source) = repeatability(model, stated_um);
    nominal.stage = StageLanding {
        repeatability_um: rep,
        source,
        landing_px: vec![[0.0, 0.0]; runs],
        landing_se_px: vec![0.0; runs],
        offsets_px: vec![[0.0, 0.0]; runs],
    };
    let data = observed(obs, inflation);
    if data.is_empty() {
        return;
    }
    let envelope = nominal.stage.envelope_px(nominal.scale_px_per_mm);
    let moves: f64 = data.iter().map(|d| d.1 .0.powi(2) + d.1 .1.powi(2)).sum();
    for _ in 0..3 {
        if moves > 1e-18 {
            fit_travel_and_angle(nominal, model, &data);
        }
        // Landings: mean over each run's analyses of measured − model (no offset).
        let scene = Scene::geometry_only(nominal, model);
        let mut sum = vec![[0.0, 0.0, 0.0, 0.0]; runs];
        for (run, cmd, meas, se, pos) in &data {
            let (mx, my) = mean_displacement(&scene, *cmd, pos);
            let s = &mut sum[*run];
            s[0] += meas.0 - mx;
            s[1] += meas.1 - my;
            s[2] += 1.0;
            s[3] += se * se;
        }
        for (r, s) in sum.iter().enumerate() {
            if s[2] == 0.0 {
                continue;
            }
            let l = [s[0] / s[2], s[1] / s[2]];
            nominal.stage.landing_px[r] = l;
            // The analyses of a run share its frames: their mean is no better than one of them.
            nominal.stage.landing_se_px[r] = (s[3] / s[2]).sqrt();
            nominal.stage.offsets_px[r] = [
                l[0].clamp(-envelope, envelope),
                l[1].clamp(-envelope, envelope),
            ];
        }
    }
}

fn mean_displacement(scene: &Scene, cmd: (f64, f64), pos: &[(f64, f64)]) -> (f64, f64) {
    let n = pos.len() as f64;
    let (mut mx, mut my) = (0.0, 0.0);
    for &p in pos {
        let (u, v) = scene.geometric_displacement(cmd, p);
        mx += u / n;
        my += v / n;
    }
    (mx, my)
}

/// Gauss–Newton for (ln travel scale, angle) on the mean displacements, the current offsets
/// removed; three steps at most.
fn fit_travel_and_angle(nominal: &mut Nominal, model: &Effects, data: &[Observed]) {
    for _ in 0..3 {
        let scene = Scene::geometry_only(nominal, model);
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (run, cmd, meas, _, pos) in data {
            let (mx, my) = mean_displacement(&scene, *cmd, pos);
            let [ox, oy] = nominal.stage.applied_offset_px(*run);
            // The actual move in px: derivative of the mean with respect to ln(scale) and angle.
            let (sx, sy) = nominal.scaled_move(cmd.0, cmd.1);
            let (s, c) = nominal.misalignment_rad.sin_cos();
            let k = nominal.scale_px_per_mm;
            let t = (k * (c * sx - s * sy), k * (s * sx + c * sy));
            let j1 = t;
            let j2 = (-t.1, t.0);
            let e = (meas.0 - mx - ox, meas.1 - my - oy);
            a11 += j1.0 * j1.0 + j1.1 * j1.1;
            a12 += j1.0 * j2.0 + j1.1 * j2.1;
            a22 += j2.0 * j2.0 + j2.1 * j2.1;
            b1 += j1.0 * e.0 + j1.1 * e.1;
            b2 += j2.0 * e.0 + j2.1 * e.1;
        }
        let det = a11 * a22 - a12 * a12;
        if !(det.abs() > 1e-12 * (a11 * a22).max(1e-300)) {
            break;
        }
        let dk = (a22 * b1 - a12 * b2) / det;
        let dth = (a11 * b2 - a12 * b1) / det;
        nominal.travel_scale *= dk.exp();
        nominal.misalignment_rad += dth;
        if dk.abs() < 1e-10 && dth.abs() < 1e-10 {
            break;
        }
    }
}

/// The `stage_error` candidate: the repeatability the landings show (RMS per axis over the
/// runs), tested against the repeatability the dataset states — the null hypothesis is "the
/// stage behaves as specified", not "the stage is perfect". None when no repeatability is stated
/// (the offsets are then free and nothing can be tested).
pub fn fit_stage_error(
    before: &super::results::Comparison,
    model: &Effects,
) -> Option<super::results::ImageFit> {
    let nominal = &before.model.nominal;
    let stated = match nominal.stage.source {
        RepeatabilitySource::Dataset => nominal.stage.repeatability_um?,
        RepeatabilitySource::Model | RepeatabilitySource::Unstated => return None,
    };
    let (sigma_um, se_um) = nominal
        .stage
        .observed_repeatability_um(nominal.scale_px_per_mm)?;
    let param = |v: f64| [("repeatability_um".to_string(), v)].into_iter().collect();
    Some(super::results::ImageFit {
        geometric: Default::default(),
        effect: crate::model::EffectId::StageError.into(),
        params: param(sigma_um),
        stderr: param(se_um),
        effects: Effects {
            stage_error: Some(StageError {
                repeatability_um: sigma_um.max(stated),
            }),
            ..model.clone()
        },
        k: 1,
        beyond_null: sigma_um - stated > 2.0 * se_um,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::synthetic_result;
    use crate::dic::DicSettings;

    fn nominal() -> Nominal {
        Nominal {
            width: 1280,
            height: 1080,
            bit_depth: 16,
            scale_px_per_mm: 26.0,
            noise_floor_dn: 0.0,
            misalignment_rad: 0.0,
            travel_scale: 1.0,
            stage: StageLanding::default(),
            patterns: Vec::new(),
        }
    }

    #[test]
    fn travel_angle_and_landings_from_synthetic_offsets() {
        // The stage travels 1.002 times what it is told along axes turned by 1 mrad; three
        // moved runs land where told, two static runs land 0.05 and 0.12 px away. Each run's
        // mean displacement is measured at 0.002 px of noise per point.
        let (travel, angle): (f64, f64) = (1.002, 1e-3);
        let commands = [(5.0, 0.0), (0.0, 4.0), (-3.0, 4.0), (0.0, 0.0), (0.0, 0.0)];
        let offsets = [
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.05, -0.03],
            [0.12, 0.0],
        ];
        let settings = DicSettings {
            subset_px: 29,
            step_px: 64,
            ..DicSettings::default()
        };
        let results: Vec<_> = commands
            .iter()
            .zip(offsets)
            .enumerate()
            .map(|(k, (&(dx, dy), o))| {
                let (sin, cos) = angle.sin_cos();
                let (sx, sy) = (26.0 * travel * dx, 26.0 * travel * dy);
                let mean = (cos * sx - sin * sy + o[0], sin * sx + cos * sy + o[1]);
                synthetic_result((1280, 1080), &settings, |_, _| mean, 0.002, k as u64)
            })
            .collect();
        let native = Scheme::parse("native").unwrap();
        let obs: Vec<StageObservation> = results
            .iter()
            .enumerate()
            .map(|(run, result)| StageObservation {
                run,
                commanded: commands[run],
                scheme: &native,
                result,
            })
            .collect();
        // A stated repeatability of 1 µm: an envelope of ±3σ = 0.078 px.
        let mut n = nominal();
        fit_stage(&mut n, &Effects::default(), &obs, 5, Some(1.0), 1.0);
        assert!((n.travel_scale - travel).abs() < 1e-5, "{}", n.travel_scale);
        assert!(
            (n.misalignment_rad - angle).abs() < 1e-5,
            "{}",
            n.misalignment_rad
        );
        assert_eq!(n.stage.source, RepeatabilitySource::Dataset);
        for (r, o) in offsets.iter().enumerate() {
            let (l, se) = (n.stage.landing_px[r], n.stage.landing_se_px[r]);
            for c in 0..2 {
                assert!(
                    (l[c] - o[c]).abs() < 4.0 * se.max(1e-4),
                    "run {r}: {l:?} ± {se}"
                );
            }
        }
        // What the data say is kept; what the model renders is held to the envelope.
        let envelope = 3.0 * 1.0 * 26.0 / 1000.0;
        assert!((n.stage.offsets_px[4][0] - envelope).abs() < 1e-12);
        assert!((n.stage.offsets_px[3][0] - n.stage.landing_px[3][0]).abs() < 1e-12);
    }
}
