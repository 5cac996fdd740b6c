//! Image-level candidates fitted from the image statistics alone, without rendering a
//! comparison's frames for every trial (the doc of [`super::fit_image`] lists every image fit):
//!
//! - `sensor_noise`: photon transfer, var = mean/gain + (read/gain)² (EMVA 1288): weighted linear
//!   least squares on the measured noise-against-mean curve from the static repeats, then one
//!   levelled correction of the slope by the same estimator run on the model's frames;
//! - `vignetting` v: weighted least squares of the measured/model mean-intensity map ratio against
//!   r²/r0² (c·(1 − v r²));
//! - `illumination_change` gain, offset: from the moved frames' mean and noise-corrected contrast
//!   relative to their references, each levelled by the model's own ratio.

use super::image_stats::{ptc, FrameStats, STATS_CROP_PX};
use super::measurement::Measurement;
use super::results::{Comparison, ImageFit};
use super::scene::{Scene, Shot};
use crate::model::effects::{IlluminationChange, SensorNoise, Vignetting};
use crate::model::EffectId;
use crate::model::Effects;

use super::fit_image::{map, TARGET_BUILT};

/// Weighted straight line var = a·mean + b over photon-transfer points: (a, b, cov).
fn ptc_line(points: &[super::image_stats::PtcPoint]) -> Option<(f64, f64, [[f64; 2]; 2])> {
    let (mut s, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        if !(p.se > 0.0) {
            continue;
        }
        let w = 1.0 / (p.se * p.se);
        s += w;
        sx += w * p.mean_dn;
        sy += w * p.variance_dn2;
        sxx += w * p.mean_dn * p.mean_dn;
        sxy += w * p.mean_dn * p.variance_dn2;
    }
    let det = s * sxx - sx * sx;
    if !(det > 0.0) {
        return None;
    }
    let a = (s * sxy - sx * sy) / det;
    let b = (sxx * sy - sx * sxy) / det;
    // Scale the covariance by the reduced χ² when the points scatter more than their errors.
    let n = points.len() as f64;
    let chi: f64 = points
        .iter()
        .map(|p| ((p.variance_dn2 - a * p.mean_dn - b) / p.se).powi(2))
        .sum();
    let scale = (chi / (n - 2.0).max(1.0)).max(1.0);
    Some((
        a,
        b,
        [
            [s / det * scale, -sx / det * scale],
            [-sx / det * scale, sxx / det * scale],
        ],
    ))
}

pub fn fit_sensor_noise(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
) -> Option<ImageFit> {
    // Only the patterns with a static repeat: a single frame's curve is the speckle's curvature,
    // not its noise (a dataset with repeats for some patterns only would fit a slope to it).
    let with_repeat: Vec<usize> = (0..meas.reference_stats.len())
        .filter(|&pi| meas.reference_stats[pi].ptc_from_repeat)
        .collect();
    let points: Vec<_> = with_repeat
        .iter()
        .flat_map(|&pi| meas.reference_stats[pi].ptc.iter().copied())
        .collect();
    let (a, b, cov) = ptc_line(&points)?;
    let full_scale = before.model.nominal.full_scale_dn();
    let make = |a: f64, b: f64| {
        let gain = 1.0 / a.max(1e-9);
        SensorNoise {
            full_well_e: full_scale * gain,
            read_noise_e: b.max(0.0).sqrt() * gain,
            gain,
        }
    };
    let mut sn = make(a, b);
    let (mut a_fit, mut b_fit) = (a, b);
    let (mut se_a_fit, mut se_b_fit) = (cov[0][0].sqrt(), cov[1][1].sqrt());
    // Levelled correction: the same estimator on the model's frames with the candidate.
    if a > 0.0 {
        let effects = Effects {
            sensor_noise: Some(sn),
            ..model.clone()
        };
        let scene = Scene::new(
            &before.model.nominal,
            &effects,
            &meas.manifest,
            meas.options.seed,
        )
        .expect(TARGET_BUILT);
        let mut model_points = Vec::new();
        for &pi in &with_repeat {
            let r0 = scene.render(pi, Shot::REFERENCE, Some(STATS_CROP_PX));
            let r1 = scene.render(pi, Shot::REPEAT, Some(STATS_CROP_PX));
            model_points.extend(ptc(&r0, Some(&r1)));
        }
        if let Some((am, bm, model_cov)) = ptc_line(&model_points) {
            if am > 0.0 {
                a_fit = a * a / am;
                b_fit = b + (b - bm);
                sn = make(a_fit, b_fit);
                // The correction reads the measured line twice and the model's once, each with
                // its own noise: δa_fit/a_fit = √(4(δa/a)² + (δam/am)²), δb_fit = √(4δb² + δbm²).
                // Without it the errors were some 2x too small (16 datasets of the shot-noise
                // test's design, seeds 1001–1016: RMS z of the gain 1.71, of the read noise
                // 2.12).
                let (se_a, se_b) = (se_a_fit, se_b_fit);
                let (se_am, se_bm) = (model_cov[0][0].sqrt(), model_cov[1][1].sqrt());
                se_a_fit = a_fit * (4.0 * (se_a / a).powi(2) + (se_am / am).powi(2)).sqrt();
                se_b_fit = (4.0 * se_b * se_b + se_bm * se_bm).sqrt();
            }
        }
    }
    let (se_a, se_b) = (se_a_fit, se_b_fit);
    let gain = sn.gain;
    let se_gain = se_a / (a_fit * a_fit).max(1e-300);
    // read = √b / a: δread² = (δb/(2√b a))² + (√b δa/a²)².
    let sb = b_fit.max(1e-12).sqrt();
    let se_read =
        ((se_b / (2.0 * sb * a_fit)).powi(2) + (sb * se_a / (a_fit * a_fit)).powi(2)).sqrt();
    Some(ImageFit {
        geometric: Default::default(),
        effect: EffectId::SensorNoise.into(),
        params: map(&[
            ("gain", gain),
            ("read_noise_e", sn.read_noise_e),
            ("full_well_e", sn.full_well_e),
        ]),
        stderr: map(&[("gain", se_gain), ("read_noise_e", se_read)]),
        effects: Effects {
            sensor_noise: Some(sn),
            ..model.clone()
        },
        k: 2,
        beyond_null: a_fit > 2.0 * se_a,
    })
}

pub fn fit_vignetting(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
) -> Option<ImageFit> {
    let (w, h) = (meas.width as f64, meas.height as f64);
    let (cx, cy) = ((w - 1.0) / 2.0, (h - 1.0) / 2.0);
    let r0 = 0.5 * (w * w + h * h).sqrt();
    // ratio = c − (c v)·r²: normal equations in (c, cv).
    let (mut s, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut pts = Vec::new();
    for im in before.images.iter().filter(|i| i.run.is_none()) {
        let (m, o) = (&im.measured.mean_map, &im.model.mean_map);
        for j in 0..m.ny.min(o.ny) {
            for i in 0..m.nx.min(o.nx) {
                let k = j * m.nx + i;
                let ratio = m.values[k] / o.values[k];
                let se = ((m.se[k] / m.values[k]).powi(2) + (o.se[k] / o.values[k]).powi(2)).sqrt()
                    * ratio;
                if !(se > 0.0 && ratio.is_finite()) {
                    continue;
                }
                let r2 = ((m.xs[i] - cx).powi(2) + (m.ys[j] - cy).powi(2)) / (r0 * r0);
                let wgt = 1.0 / (se * se);
                s += wgt;
                sx += wgt * r2;
                sy += wgt * ratio;
                sxx += wgt * r2 * r2;
                sxy += wgt * r2 * ratio;
                pts.push((r2, ratio, se));
            }
        }
    }
    let det = s * sxx - sx * sx;
    if !(det > 0.0) {
        return None;
    }
    let slope = (s * sxy - sx * sy) / det;
    let c = (sxx * sy - sx * sxy) / det;
    let chi: f64 = pts
        .iter()
        .map(|(x, y, se)| ((y - c - slope * x) / se).powi(2))
        .sum();
    let scale = (chi / (pts.len() as f64 - 2.0).max(1.0)).max(1.0);
    let se_slope = (s / det * scale).sqrt();
    let v = -slope / c;
    let se_v = se_slope / c.abs();
    let existing = model.vignetting.map_or(0.0, |x| x.v);
    Some(ImageFit {
        geometric: Default::default(),
        effect: EffectId::Vignetting.into(),
        params: map(&[("v", v + existing)]),
        stderr: map(&[("v", se_v)]),
        effects: Effects {
            vignetting: Some(Vignetting { v: v + existing }),
            ..model.clone()
        },
        k: 1,
        beyond_null: v.abs() > 2.0 * se_v,
    })
}

pub fn fit_illumination_change(before: &Comparison, model: &Effects) -> Option<ImageFit> {
    let noise = before.model.nominal.noise_floor_dn.powi(2);
    let refs: Vec<&super::results::ImageComparison> =
        before.images.iter().filter(|i| i.run.is_none()).collect();
    let (mut gains, mut offsets) = (Vec::new(), Vec::new());
    for im in before.images.iter().filter(|i| i.run.is_some()) {
        let Some(r) = refs.iter().find(|r| r.pattern == im.pattern) else {
            continue;
        };
        let sig = |s: &FrameStats| ((s.contrast * s.mean_dn).powi(2) - noise).max(1e-12).sqrt();
        let g = (sig(&im.measured) / sig(&r.measured)) / (sig(&im.model) / sig(&r.model));
        let expected_mean = r.measured.mean_dn * im.model.mean_dn / r.model.mean_dn;
        gains.push(g);
        offsets.push(im.measured.mean_dn - g * expected_mean);
    }
    if gains.is_empty() {
        return None;
    }
    let stats = |v: &[f64]| {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        let sd = if v.len() > 1 {
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        } else {
            0.0
        };
        (m, sd / n.sqrt())
    };
    let (g, mut se_g) = stats(&gains);
    let (o, mut se_o) = stats(&offsets);
    // One run: the contrast's own standard error bounds the gain's.
    let cse = refs
        .iter()
        .map(|r| r.measured.contrast_se / r.measured.contrast)
        .fold(0.0, f64::max)
        * 2f64.sqrt();
    se_g = se_g.max(cse * g);
    let mean_ref = refs.iter().map(|r| r.measured.mean_dn).sum::<f64>() / refs.len() as f64;
    se_o = se_o.max(se_g * mean_ref);
    Some(ImageFit {
        geometric: Default::default(),
        effect: EffectId::IlluminationChange.into(),
        params: map(&[("gain", g), ("offset", o)]),
        stderr: map(&[("gain", se_g), ("offset", se_o)]),
        effects: Effects {
            illumination_change: Some(IlluminationChange { gain: g, offset: o }),
            ..model.clone()
        },
        k: 2,
        beyond_null: (g - 1.0).abs() > 2.0 * se_g || o.abs() > 2.0 * se_o,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::PtcPoint;

    #[test]
    fn a_photon_transfer_line_gives_back_gain_and_read_noise() {
        // EMVA 1288: var = mean/K + (σ_read/K)², K = 2.5 e⁻/DN, σ_read = 6 e⁻; points on the line
        // with the binomial errors of a variance from 10,000 pixels.
        let (gain, read) = (2.5, 6.0);
        let points: Vec<PtcPoint> = (1..=12)
            .map(|k| {
                let mean_dn = 300.0 * k as f64;
                let variance_dn2 = mean_dn / gain + (read / gain).powi(2);
                PtcPoint {
                    mean_dn,
                    variance_dn2,
                    se: variance_dn2 * (2.0 / 10_000f64).sqrt(),
                }
            })
            .collect();
        let (a, b, cov) = ptc_line(&points).unwrap();
        assert!((1.0 / a - gain).abs() < 1e-9, "{}", 1.0 / a);
        assert!((b.sqrt() * gain - read).abs() < 1e-6, "{}", b.sqrt() * gain);
        // Exact points: the covariance is the weights' own, positive on the diagonal.
        assert!(cov[0][0] > 0.0 && cov[1][1] > 0.0);
        // One point, or points without errors, fix no line.
        assert!(ptc_line(&points[..1]).is_none());
        let no_errors: Vec<PtcPoint> = points.iter().map(|p| PtcPoint { se: 0.0, ..*p }).collect();
        assert!(ptc_line(&no_errors).is_none());
    }
}
