//! Image-level candidates: parameters fitted so that the model's frames show the measured image
//! statistics, by rendering the model's centred analysis crops with fixed seeds (the same speckle
//! layout and noise for every trial, so the objective is smooth in the parameters) and minimising
//! the χ² of the statistics the effect acts on. Standard errors from the curvature of χ² at the
//! minimum (σ² = 2/∂²χ²), scaled by √ĉ where χ² per degree of freedom is above 1 there (a print
//! the model draws only approximately leaves the value less certain; [`dispersion_factor`]).
//!
//! - `psf_blur` σ: the power spectra along x and y of the references (a Gaussian PSF multiplies
//!   both by exp(−4π²σ²f²)). Of a characterised print, their level and shape in every bin, as
//!   the image χ² the verdict is judged by reads them; of a calibrated print, their shape alone
//!   above half its dot-spacing frequency (the level is the calibrated contrast's, and below the
//!   band edge the spectrum is the dots' placement, a printer's property no model knows);
//!   coarse grid, then Brent's method.
//! - `fill_factor` fx, fy: the same spectra (the aperture multiplies the x spectrum by
//!   sinc²(fx·f), the y spectrum by sinc²(fy·f)); coarse grid, then Nelder–Mead.
//! - `sensor_noise`, `vignetting` and `illumination_change`: from the statistics alone, without
//!   a rendering per trial ([`super::fit_image_stats`]).
//! - `motion_blur` length (0–4 px) along the largest move: that moved frame's spectra along x and
//!   y; grid, then Brent's method.

use super::bic::image_chi2;
use super::image_stats::{psd, FrameStats, PsdBin, STATS_CROP_PX};
use super::measurement::Measurement;
use super::optimise::{
    curvature_stderr, dispersion_factor, minimise_1d, nelder_mead, stderr_within_null_reach,
    unless_stopped,
};
use super::results::{Comparison, ImageFit};
use super::scene::{reference_crop, Scene, Shot};
use crate::image::Image;
use crate::model::effects::{FillFactor, MotionBlur, PsfBlur};
use crate::model::EffectId;
use crate::model::Effects;
use std::borrow::Borrow;
use std::collections::BTreeMap;
use std::sync::Arc;

/// χ² of the crops' spectra against the measured frames' and its terms (bins).
fn spectra_chi2<I: Borrow<Image>>(measured: &[&FrameStats], crops: &[I]) -> (f64, usize) {
    let (mut c, mut n) = (0.0, 0);
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
            psd_x: psd(img.borrow(), true),
            psd_y: psd(img.borrow(), false),
            ..only.clone()
        };
        let (ci, ni) = image_chi2(&only, &o);
        c += ci;
        n += ni;
    }
    (c, n)
}

/// χ² of ln(moved/reference) measured against the same ratio of the model, per spectrum bin, and
/// its terms.
fn ratio_chi2(
    m_moved: &[PsdBin],
    m_ref: &[PsdBin],
    o_moved: &[PsdBin],
    o_ref: &[PsdBin],
) -> (f64, usize) {
    let rel = |b: &PsdBin| (b.se / b.value).powi(2);
    let terms: Vec<f64> = m_moved
        .iter()
        .zip(m_ref)
        .zip(o_moved.iter().zip(o_ref))
        .filter(|((a, b), (c, d))| a.value > 0.0 && b.value > 0.0 && c.value > 0.0 && d.value > 0.0)
        .filter_map(|((a, b), (c, d))| {
            let r = (a.value / b.value).ln() - (c.value / d.value).ln();
            let var = rel(a) + rel(b) + rel(c) + rel(d);
            (var > 0.0).then(|| r * r / var)
        })
        .collect();
    (terms.iter().sum(), terms.len())
}

/// The comparison before a fit built a scene from the same nominal model and manifest, and the
/// target's size depends on nothing else: building it again cannot fail.
pub(super) const TARGET_BUILT: &str = "the comparison before this fit built the same target";

/// The reference crops of every pattern rendered with `effects`.
fn reference_crops(meas: &Measurement, before: &Comparison, effects: &Effects) -> Vec<Arc<Image>> {
    (0..meas.labels.len())
        .map(|pi| {
            reference_crop(
                &before.model.nominal,
                effects,
                &meas.manifest,
                meas.options.seed,
                pi,
            )
            .expect(TARGET_BUILT)
        })
        .collect()
}

/// The standard errors of an image fit at its minimum `x`: from χ²'s curvature (`obj`), no
/// smaller than χ² at the effect's `null` allows ([`stderr_within_null_reach`]), scaled by the
/// scatter its terms leave there beyond their own errors (`obj_dof`: χ² and its terms;
/// [`dispersion_factor`]). Measured on the independent generator's benches: docs/calibration.md.
fn honest_stderr(
    effect: EffectId,
    obj: &dyn Fn(&[f64]) -> f64,
    obj_dof: &dyn Fn(&[f64]) -> (f64, usize),
    x: &[f64],
    null: &[f64],
    h: &[f64],
    (lo, hi): (&[f64], &[f64]),
) -> Vec<f64> {
    let (chi2, terms) = obj_dof(x);
    let factor = dispersion_factor(chi2, terms.saturating_sub(x.len()));
    tracing::debug!(%effect, chi2, terms, factor, "an image fit's minimum");
    let curvature = curvature_stderr(obj, x, chi2, h, lo, hi);
    stderr_within_null_reach(obj, x, chi2, null, &curvature, h, (lo, hi))
        .into_iter()
        .map(|se| se * factor)
        .collect()
}

pub(super) fn map(pairs: &[(&str, f64)]) -> BTreeMap<String, f64> {
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
    // Fitted only against characterised prints (`identifiability.rs`: a print calibrated from
    // the frames absorbs the blur), whose level is stated: the spectra's level is evidence too,
    // read as the verdict's image χ² reads it. On the spectra's shape alone (above half the
    // dot-spacing frequency), five realisations of the independent generator's characterised
    // prints gave σ 1.4–3.4 SE high (0.623–0.671 px for a truth of 0.6), and every one then
    // named an aperture for the rest of the spectrum (docs/calibration.md).
    let obj_dof = |x: &[f64]| spectra_chi2(&measured, &reference_crops(meas, before, &with(x[0])));
    let chi2 = |x: &[f64]| obj_dof(x).0;
    let obj = unless_stopped(&chi2, stop);
    let sigma = minimise_1d(&|s| obj(&[s]), 0.0, 3.0, 9);
    let se = honest_stderr(
        EffectId::PsfBlur,
        &obj,
        &obj_dof,
        &[sigma],
        &[0.0],
        &[0.05],
        (&[0.0], &[3.0]),
    )[0];
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
    let obj_dof =
        |x: &[f64]| spectra_chi2(&measured, &reference_crops(meas, before, &with(x[0], x[1])));
    let chi2 = |x: &[f64]| obj_dof(x).0;
    let obj = unless_stopped(&chi2, stop);
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
    let se = honest_stderr(
        EffectId::FillFactor,
        &obj,
        &obj_dof,
        &x,
        &[1.0, 1.0],
        &[0.04, 0.04],
        (&lo, &hi),
    );
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

/// `stop`: as for [`fit_psf_blur`].
pub fn fit_motion_blur(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    stop: &dyn Fn() -> bool,
) -> Option<ImageFit> {
    let runs = &meas.manifest.runs;
    // The largest move (the first of equals): blur grows with the stage's speed, and every
    // trial renders the path.
    let m = |i: &usize| runs[*i].stage.dx_mm.hypot(runs[*i].stage.dy_mm);
    let i = (0..runs.len())
        .filter(|i| m(i) != 0.0)
        .min_by(|a, b| m(b).total_cmp(&m(a)))?;
    let first = &runs[i].stage;
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
    let pi = meas.pattern_of_run[i];
    let r = ref_scene.render(pi, Shot::REFERENCE, Some(STATS_CROP_PX));
    let (rx, ry) = (psd(&r, true), psd(&r, false));
    let (moved, reference) = (&meas.moved_stats[i], &meas.reference_stats[pi]);
    let at = before
        .model
        .nominal
        .landed_command(i, (first.dx_mm, first.dy_mm));
    let obj_dof = |x: &[f64]| {
        let scene = Scene::new(
            &before.model.nominal,
            &with(x[0]),
            &meas.manifest,
            meas.options.seed,
        )
        .expect(TARGET_BUILT);
        let crop = scene.render(pi, Shot::of_run(i, at), Some(STATS_CROP_PX));
        let (cx, nx) = ratio_chi2(&moved.psd_x, &reference.psd_x, &psd(&crop, true), &rx);
        let (cy, ny) = ratio_chi2(&moved.psd_y, &reference.psd_y, &psd(&crop, false), &ry);
        (cx + cy, nx + ny)
    };
    let chi2 = |x: &[f64]| obj_dof(x).0;
    let obj = unless_stopped(&chi2, stop);
    let l = minimise_1d(&|l| obj(&[l]), 0.0, 4.0, 9);
    let se = honest_stderr(
        EffectId::MotionBlur,
        &obj,
        &obj_dof,
        &[l],
        &[0.0],
        &[0.2],
        (&[0.0], &[4.0]),
    )[0];
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::image_stats::PtcPoint;
    use crate::diagnose::test_fields::{
        comparison, frame_stats, manifest, measurement, PrintStated,
    };
    use crate::image::Image;

    fn bin(f: f64, value: f64, se: f64) -> PsdBin {
        PsdBin { f, value, se }
    }

    #[test]
    fn the_moved_frames_spectrum_is_compared_relative_to_its_reference() {
        // One bin: measured moved 2 ± 0.2 over reference 1 ± 0.1, the model's 1 ± 0.1 over
        // 1 ± 0.1. r = ln 2, its variance the four relative variances, 4·0.1²: χ² = ln²2/0.04.
        // A second bin with no power on one side is skipped.
        let m_moved = [bin(0.1, 2.0, 0.2), bin(0.2, 0.0, 0.1)];
        let m_ref = [bin(0.1, 1.0, 0.1), bin(0.2, 1.0, 0.1)];
        let o = [bin(0.1, 1.0, 0.1), bin(0.2, 1.0, 0.1)];
        let (chi2, terms) = ratio_chi2(&m_moved, &m_ref, &o, &o);
        let truth = 2f64.ln().powi(2) / 0.04;
        assert!((chi2 - truth).abs() < 1e-12, "{chi2} against {truth}");
        assert_eq!(terms, 1);
    }

    proptest::proptest! {
        /// A blur common to both measured frames (lens, print: the same factor on the moved
        /// frame's spectrum and its reference's, bin by bin) cannot pass for motion: χ² is
        /// unchanged; and a measured ratio equal to the model's gives zero.
        #[test]
        fn a_blur_common_to_both_frames_cancels(
            factors in proptest::collection::vec(0.05f64..1.0, 6),
            values in proptest::collection::vec(0.1f64..10.0, 18),
        ) {
            let spectrum = |offset: usize| -> Vec<PsdBin> {
                (0..6).map(|k| bin(0.05 * (k + 1) as f64, values[offset + k], 0.1 * values[offset + k])).collect()
            };
            let (moved, reference, model) = (spectrum(0), spectrum(6), spectrum(12));
            let blurred = |s: &[PsdBin]| -> Vec<PsdBin> {
                s.iter().zip(&factors).map(|(b, f)| bin(b.f, b.value * f, b.se * f)).collect()
            };
            let (plain, _) = ratio_chi2(&moved, &reference, &model, &model);
            let (common, _) = ratio_chi2(&blurred(&moved), &blurred(&reference), &model, &model);
            proptest::prop_assert!((plain - common).abs() <= 1e-9 * plain.max(1.0));
            proptest::prop_assert!(ratio_chi2(&moved, &reference, &moved, &reference).0.abs() < 1e-12);
        }
    }

    /// A 64x64 speckle-like texture at mean `level`.
    fn texture(level: f32) -> Image {
        Image::from_fn(64, 64, |x, y| {
            let (x, y) = (x as f32, y as f32);
            let hash = ((x * 12.9898 + y * 78.233).sin() * 43758.547).fract();
            level * (1.0 + 0.2 * (x / 2.3).sin() * (y / 1.7).cos() + 0.1 * hash)
        })
    }

    #[test]
    fn the_spectra_fits_compare_the_spectra_alone() {
        // The measured reference at twice the exposure, with another contrast, a noise curve and
        // a mean map the model's crop knows nothing of: spectra relative to the mean squared are
        // the same, so χ² is zero. The same crop blurred along x (a 1-2-1 filter) is not.
        let bright = texture(2000.0);
        let measured = FrameStats {
            psd_x: psd(&bright, true),
            psd_y: psd(&bright, false),
            contrast: 0.9,
            ptc: vec![PtcPoint {
                mean_dn: 2000.0,
                variance_dn2: 400.0,
                se: 1.0,
            }],
            ..frame_stats(2000.0)
        };
        assert!(!measured.psd_x.is_empty());
        let crop = texture(1000.0);
        let (same, terms) = spectra_chi2(&[&measured], std::slice::from_ref(&crop));
        assert!(terms > 0);
        assert!(same < 1e-9, "{same}");
        let blurred = Image::from_fn(64, 64, |x, y| {
            let at = |x: usize| crop.data()[y * 64 + x.clamp(0, 63)];
            0.25 * at(x.saturating_sub(1)) + 0.5 * at(x) + 0.25 * at(x + 1)
        });
        let (blur, _) = spectra_chi2(&[&measured], &[blurred]);
        assert!(blur > 100.0, "{blur}");
    }

    #[test]
    fn a_dataset_without_a_move_has_no_motion_blur_to_fit() {
        let meas = measurement(
            manifest(&[(0.0, 0.0), (0.0, 0.0)], &["a"], PrintStated::Nothing),
            &["ff100"],
        );
        let before = comparison(Vec::new());
        let fit = fit_motion_blur(&meas, &before, &Effects::default(), &|| false);
        assert_eq!(fit, None);
        assert_eq!(
            map(&[("fx", 0.5), ("fy", 0.25)]),
            BTreeMap::from([("fx".to_string(), 0.5), ("fy".to_string(), 0.25)])
        );
    }
}
