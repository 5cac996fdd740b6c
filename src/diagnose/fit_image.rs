//! Image-level candidates: parameters fitted so that the model's frames show the measured image
//! statistics, by rendering the model's centred analysis crops with fixed seeds (the same speckle
//! layout and noise for every trial, so the objective is smooth in the parameters) and minimising
//! the χ² of the statistics the effect acts on. Standard errors from the curvature of χ² at the
//! minimum (σ² = 2/∂²χ²).
//!
//! - `psf_blur` σ: the shape of the power spectra along x and y of the references above each
//!   print's dot-spacing frequency (a Gaussian PSF multiplies both by exp(−4π²σ²f²); below the
//!   spacing frequency the spectrum is the dots' placement, a printer's property no model
//!   knows); coarse grid, then golden section.
//! - `fill_factor` fx, fy: the same spectra (the aperture multiplies the x spectrum by
//!   sinc²(fx·f), the y spectrum by sinc²(fy·f)); coarse grid, then Nelder–Mead.
//! - `sensor_noise`: photon transfer, var = mean/gain + (read/gain)² (EMVA 1288): weighted linear
//!   least squares on the measured noise-against-mean curve from the static repeats, then one
//!   levelled correction of the slope by the same estimator run on the model's frames;
//!   `full_well_e` is not identifiable from unsaturated frames and is set to the ADC's full scale
//!   times the gain (not fitted, no standard error).
//! - `vignetting` v: weighted least squares of the measured/model mean-intensity map ratio against
//!   r²/r0² (c·(1 − v r²)).
//! - `illumination_change` gain, offset: from the moved frames' mean and noise-corrected contrast
//!   relative to their references, each levelled by the model's own ratio.
//! - `motion_blur` length (0–4 px) along the largest move: that moved frame's spectra along x and
//!   y; grid, then golden section.

use super::bic::image_chi2;
use super::compare::Measurement;
use super::image_stats::{psd, ptc, FrameStats, PsdBin, STATS_CROP_PX};
use super::nominal::Scene;
use super::optimise::{curvature_stderr, minimise_1d, nelder_mead, unless_stopped};
use super::results::{Comparison, ImageFit};
use crate::model::effects::{
    FillFactor, IlluminationChange, MotionBlur, PsfBlur, SensorNoise, Vignetting,
};
use crate::model::EffectId;
use crate::model::Effects;
use std::collections::BTreeMap;

fn spectra_chi2(measured: &[&FrameStats], crops: &[crate::image::Image]) -> f64 {
    let mut c = 0.0;
    for (m, img) in measured.iter().zip(crops) {
        // Spectra only: no noise curve, no mean map, no contrast (NaN is skipped).
        let empty = super::image_stats::MeanMap {
            nx: 0,
            ny: 0,
            xs: vec![],
            ys: vec![],
            values: vec![],
            se: vec![],
        };
        let only = FrameStats {
            ptc: Vec::new(),
            mean_map: empty,
            contrast: f64::NAN,
            ..(*m).clone()
        };
        let o = FrameStats {
            psd_x: psd(img, true),
            psd_y: psd(img, false),
            ..only.clone()
        };
        c += image_chi2(&only, &o).0;
    }
    c
}

/// χ² of ln(moved/reference) measured against the same ratio of the model, per spectrum bin.
fn ratio_chi2(m_moved: &[PsdBin], m_ref: &[PsdBin], o_moved: &[PsdBin], o_ref: &[PsdBin]) -> f64 {
    let rel = |b: &PsdBin| (b.se / b.value).powi(2);
    m_moved
        .iter()
        .zip(m_ref)
        .zip(o_moved.iter().zip(o_ref))
        .filter(|((a, b), (c, d))| a.value > 0.0 && b.value > 0.0 && c.value > 0.0 && d.value > 0.0)
        .map(|((a, b), (c, d))| {
            let r = (a.value / b.value).ln() - (c.value / d.value).ln();
            let var = rel(a) + rel(b) + rel(c) + rel(d);
            if var > 0.0 {
                r * r / var
            } else {
                0.0
            }
        })
        .sum()
}

/// The comparison before a fit built a scene from the same nominal model and manifest, and the
/// target's size depends on nothing else: building it again cannot fail.
const TARGET_BUILT: &str = "the comparison before this fit built the same target";

/// The reference crops of every pattern rendered with `effects`.
fn reference_crops(
    meas: &Measurement,
    before: &Comparison,
    effects: &Effects,
) -> Vec<crate::image::Image> {
    let scene = Scene::new(
        &before.model.nominal,
        effects,
        &meas.manifest,
        meas.options.seed,
    )
    .expect(TARGET_BUILT);
    (0..meas.labels.len())
        .map(|pi| scene.render(pi, (0.0, 0.0), false, 0, Some(STATS_CROP_PX)))
        .collect()
}

fn map(pairs: &[(&str, f64)]) -> BTreeMap<String, f64> {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

/// `stop`: the job was cancelled (the fit then ends early, its result meaningless).
pub fn fit_psf_blur(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    stop: &dyn Fn() -> bool,
) -> ImageFit {
    let measured: Vec<&FrameStats> = meas.reference_stats.iter().collect();
    let with = |s: f64| Effects {
        psf_blur: Some(PsfBlur {
            sigma_px: s.max(0.0),
        }),
        ..model.clone()
    };
    // The spectra's shape, not their level: the level is the print's contrast and density
    // (calibrated or stated), the shape is where a blur acts.
    // Above half each print's dot-spacing frequency: below it the spectrum's shape is the
    // dots' placement statistics (which the comparison chose there, `compare::choose_placement`),
    // above it their profile and whatever blurs it.
    let nominal = &before.model.nominal;
    let f_min: Vec<f64> = nominal
        .patterns
        .iter()
        .map(|p| super::print::placement_band_edge(&p.pattern, nominal.scale_px_per_mm))
        .collect();
    let obj = |x: &[f64]| {
        measured
            .iter()
            .zip(reference_crops(meas, before, &with(x[0])))
            .zip(&f_min)
            .map(|((m, crop), f)| super::print::spectral_shape_chi2_above(m, &crop, *f))
            .sum::<f64>()
    };
    let obj = unless_stopped(&obj, stop);
    let sigma = minimise_1d(&|s| obj(&[s]), 0.0, 3.0, 9);
    let se = curvature_stderr(&obj, &[sigma], &[0.05], &[0.0], &[3.0])[0];
    ImageFit {
        geometric: Default::default(),
        effect: EffectId::PsfBlur.into(),
        params: map(&[("sigma_px", sigma)]),
        stderr: map(&[("sigma_px", se)]),
        effects: with(sigma),
        k: 1,
        beyond_null: sigma > 2.0 * se,
    }
}

/// `stop`: as for [`fit_psf_blur`].
pub fn fit_fill_factor(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    stop: &dyn Fn() -> bool,
) -> ImageFit {
    let measured: Vec<&FrameStats> = meas.reference_stats.iter().collect();
    let with = |fx: f64, fy: f64| Effects {
        fill_factor: Some(FillFactor {
            fx: fx.clamp(0.05, 1.0),
            fy: fy.clamp(0.05, 1.0),
        }),
        ..model.clone()
    };
    let obj =
        |x: &[f64]| spectra_chi2(&measured, &reference_crops(meas, before, &with(x[0], x[1])));
    let obj = unless_stopped(&obj, stop);
    let mut best = (f64::INFINITY, [1.0, 1.0]);
    for fx in [0.3, 0.65, 1.0] {
        for fy in [0.3, 0.65, 1.0] {
            let v = obj(&[fx, fy]);
            if v < best.0 {
                best = (v, [fx, fy]);
            }
        }
    }
    let (lo, hi) = ([0.05, 0.05], [1.0, 1.0]);
    let x = nelder_mead(&obj, &best.1, &[0.12, 0.12], &lo, &hi, 40);
    let se = curvature_stderr(&obj, &x, &[0.04, 0.04], &lo, &hi);
    ImageFit {
        geometric: Default::default(),
        effect: EffectId::FillFactor.into(),
        params: map(&[("fx", x[0]), ("fy", x[1])]),
        stderr: map(&[("fx", se[0]), ("fy", se[1])]),
        effects: with(x[0], x[1]),
        k: 2,
        beyond_null: (1.0 - x[0]) > 2.0 * se[0] || (1.0 - x[1]) > 2.0 * se[1],
    }
}

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
    let points: Vec<_> = meas
        .reference_stats
        .iter()
        .flat_map(|s| s.ptc.iter().copied())
        .collect();
    let (a, b, cov) = ptc_line(&points)?;
    let bits = before.model.nominal.bit_depth;
    let full_scale = 2f64.powi(bits as i32) - 1.0;
    let make = |a: f64, b: f64| {
        let gain = 1.0 / a.max(1e-9);
        SensorNoise {
            full_well_e: full_scale * gain,
            read_noise_e: b.max(0.0).sqrt() * gain,
            gain,
        }
    };
    let mut sn = make(a, b);
    let mut a_fit = a;
    let mut b_fit = b;
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
        for pi in 0..meas.labels.len() {
            let r0 = scene.render(pi, (0.0, 0.0), false, 0, Some(STATS_CROP_PX));
            let r1 = scene.render(pi, (0.0, 0.0), false, 1, Some(STATS_CROP_PX));
            model_points.extend(ptc(&r0, Some(&r1)));
        }
        if let Some((am, bm, _)) = ptc_line(&model_points) {
            if am > 0.0 {
                a_fit = a * a / am;
                b_fit = b + (b - bm);
                sn = make(a_fit, b_fit);
            }
        }
    }
    let se_a = cov[0][0].sqrt();
    let se_b = cov[1][1].sqrt();
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

/// `stop`: as for [`fit_psf_blur`].
pub fn fit_motion_blur(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    stop: &dyn Fn() -> bool,
) -> Option<ImageFit> {
    let runs = &meas.manifest.runs;
    // The three largest moves.
    let mut order: Vec<usize> = (0..runs.len())
        .filter(|&i| runs[i].stage.dx_mm != 0.0 || runs[i].stage.dy_mm != 0.0)
        .collect();
    if order.is_empty() {
        return None;
    }
    order.sort_by(|&a, &b| {
        let m = |i: usize| runs[i].stage.dx_mm.hypot(runs[i].stage.dy_mm);
        m(b).total_cmp(&m(a))
    });
    // The largest move: blur grows with the stage's speed, and every trial renders the path.
    order.truncate(1);
    let first = &runs[order[0]].stage;
    let angle = first.dy_mm.atan2(first.dx_mm) + before.model.nominal.misalignment_rad;
    let with = |l: f64| Effects {
        motion_blur: Some(MotionBlur {
            length_px: l.max(0.0),
            angle_rad: angle,
        }),
        ..model.clone()
    };
    // Motion blur acts on the moved frame only: fit the moved frame's spectra *relative to its
    // reference*, measured against model, so a blur common to both (lens, print) cannot pass for
    // motion.
    let ref_scene = Scene::new(
        &before.model.nominal,
        model,
        &meas.manifest,
        meas.options.seed,
    )
    .expect(TARGET_BUILT);
    let pairs: Vec<(&FrameStats, &FrameStats, Vec<PsdBin>, Vec<PsdBin>)> = order
        .iter()
        .map(|&i| {
            let pi = meas.pattern_of_run[i];
            let r = ref_scene.render(pi, (0.0, 0.0), false, 0, Some(STATS_CROP_PX));
            (
                &meas.moved_stats[i],
                &meas.reference_stats[pi],
                psd(&r, true),
                psd(&r, false),
            )
        })
        .collect();
    let obj = |x: &[f64]| {
        let scene = Scene::new(
            &before.model.nominal,
            &with(x[0]),
            &meas.manifest,
            meas.options.seed,
        )
        .expect(TARGET_BUILT);
        let crops: Vec<_> = order
            .iter()
            .map(|&i| {
                let r = &runs[i];
                scene.render(
                    meas.pattern_of_run[i],
                    before
                        .model
                        .nominal
                        .landed_command(i, (r.stage.dx_mm, r.stage.dy_mm)),
                    true,
                    2 + i as u64,
                    Some(STATS_CROP_PX),
                )
            })
            .collect();
        let mut c = 0.0;
        for ((moved, reference, rx, ry), crop) in pairs.iter().zip(&crops) {
            c += ratio_chi2(&moved.psd_x, &reference.psd_x, &psd(crop, true), rx);
            c += ratio_chi2(&moved.psd_y, &reference.psd_y, &psd(crop, false), ry);
        }
        c
    };
    let obj = unless_stopped(&obj, stop);
    let l = minimise_1d(&|l| obj(&[l]), 0.0, 4.0, 9);
    let se = curvature_stderr(&obj, &[l], &[0.2], &[0.0], &[4.0])[0];
    Some(ImageFit {
        geometric: Default::default(),
        effect: EffectId::MotionBlur.into(),
        params: map(&[("length_px", l), ("angle_rad", angle)]),
        stderr: map(&[("length_px", se)]),
        effects: with(l),
        k: 1,
        beyond_null: l > 2.0 * se,
    })
}
