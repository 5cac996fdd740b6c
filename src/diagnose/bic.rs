//! χ² of a comparison and ΔBIC of a candidate (Schwarz, Ann. Stat. 6 (1978)).
//!
//! The observations, each with its standard error:
//! - field: per run and scheme, the quadratic surface of the field difference (6 coefficients per
//!   component); its χ² is Σ fitted²/σ² over the points, divided by the covariance inflation of
//!   overlapping subsets ((subset/step)², at least 1), σ² the noise variance of the difference;
//! - std: per run and scheme, Δσu and Δσv over SE = √(σm² + σo²)/√(2 n_eff);
//! - image: per frame, ln of the power-spectrum bins along x and y, the noise variance of each
//!   photon-transfer bin (the model's curve interpolated at the measured means; frames with a
//!   static repeat only, see [`image_chi2_parts`]), the mean-intensity map, the contrast.
//!
//! The field and std χ² are scaled by N_eff/N for the frames the analyses share (see [`chi2`]).
//!
//! ΔBIC = χ²(with the candidate) − χ²(without) + k·ln n, with the noise levels of the
//! comparison without the candidate held fixed. A candidate is significant when ΔBIC < −10
//! (very strong evidence, Kass & Raftery, JASA 90 (1995)).

use super::image_stats::{light_change, FrameStats, PtcPoint};
use super::results::{Chi2, Comparison, ImageComparison, RunComparison, IMAGE_KINDS};
use crate::dic::DicSettings;

/// ΔBIC below which a candidate counts as found.
pub const SIGNIFICANT_DELTA_BIC: f64 = -10.0;

/// Covariance inflation of neighbouring points whose subsets overlap.
pub fn inflation(dic: &DicSettings) -> f64 {
    ((dic.subset_px as f64 / dic.step_px as f64).powi(2)).max(1.0)
}

fn ptc_at(curve: &[PtcPoint], mean: f64) -> Option<(f64, f64)> {
    if curve.len() < 2 {
        return None;
    }
    let i = curve
        .iter()
        .position(|p| p.mean_dn >= mean)
        .unwrap_or(curve.len() - 1)
        .clamp(1, curve.len() - 1);
    let (a, b) = (curve[i - 1], curve[i]);
    let t = if b.mean_dn > a.mean_dn {
        (mean - a.mean_dn) / (b.mean_dn - a.mean_dn)
    } else {
        0.0
    };
    // Extrapolate at most a little beyond the model's range.
    if !(-0.5..=1.5).contains(&t) {
        return None;
    }
    Some((
        a.variance_dn2 + t * (b.variance_dn2 - a.variance_dn2),
        a.se.max(b.se),
    ))
}

/// χ² and observation count of the image statistics of one frame.
pub fn image_chi2(m: &FrameStats, o: &FrameStats) -> (f64, usize) {
    let parts = image_chi2_parts(m, o);
    (
        parts.iter().map(|p| p.0).sum(),
        parts.iter().map(|p| p.1).sum(),
    )
}

/// The index of the mean-intensity map among [`IMAGE_KINDS`].
const MEAN_MAP: usize = 2;
/// The index of the moved frames' light change ([`light_change_chi2`]).
pub const LIGHT_CHANGE: usize = 4;

/// The weight of each image of `images` in the image χ²: 1 for a reference, 1/moved frames of
/// its pattern for a moved frame (see [`chi2`]).
fn image_weights(images: &[ImageComparison]) -> Vec<f64> {
    let mut moved_per_pattern: std::collections::BTreeMap<&str, f64> = Default::default();
    for im in images.iter().filter(|i| i.run.is_some()) {
        *moved_per_pattern.entry(im.pattern.as_str()).or_default() += 1.0;
    }
    images
        .iter()
        .map(|im| match im.run {
            Some(_) => 1.0 / moved_per_pattern[im.pattern.as_str()],
            None => 1.0,
        })
        .collect()
}

/// The light change of every moved frame of `images` ([`light_change_chi2`]), each weighed
/// as the moved frames' other statistics are in [`chi2`] ([`image_weights`]): χ² and
/// observations.
fn light_change_of(images: &[ImageComparison]) -> (f64, usize) {
    let (mut chi2, mut n) = (0.0, 0.0);
    for (im, weight) in images.iter().zip(image_weights(images)) {
        if im.run.is_none() {
            continue;
        }
        let (c, k) = light_change_chi2(im);
        chi2 += c * weight;
        n += k as f64 * weight;
    }
    (chi2, n.round() as usize)
}

/// The light change between two renderings of the model (`first`'s model side taken as the
/// measurement, `second`'s as the model): what a right model leaves of it. None without moved
/// frames.
pub fn light_change_between(first: &Comparison, second: &Comparison) -> Option<f64> {
    let images: Vec<ImageComparison> = first
        .images
        .iter()
        .zip(&second.images)
        .filter(|(a, b)| a.run.is_some() && a.run == b.run && a.pattern == b.pattern)
        .map(|(a, b)| ImageComparison {
            measured: a.model.clone(),
            model: b.model.clone(),
            ..a.clone()
        })
        .collect();
    let (chi2, n) = light_change_of(&images);
    (n > 0 && chi2 > 0.0).then_some(chi2)
}

/// χ² and observations of a moved frame's light change ([`light_change`]) about its own
/// constant (the weighted mean of q): what the model leaves of the light that changed across
/// the field between the frames.
fn light_change_chi2(moved: &ImageComparison) -> (f64, usize) {
    let blocks = light_change((&moved.measured, &moved.model));
    if blocks.len() < 2 {
        return (0.0, 0);
    }
    let (sw, swq) = blocks.iter().fold((0.0, 0.0), |(sw, swq), b| {
        let w = 1.0 / (b.se * b.se);
        (sw + w, swq + w * b.q)
    });
    let mean = swq / sw;
    let chi2 = blocks.iter().map(|b| ((b.q - mean) / b.se).powi(2)).sum();
    (chi2, blocks.len() - 1)
}

/// χ² and observation count of one frame's image statistics, per kind ([`IMAGE_KINDS`]).
pub fn image_chi2_parts(m: &FrameStats, o: &FrameStats) -> [(f64, usize); IMAGE_KINDS] {
    let mut parts = [(0.0, 0usize); IMAGE_KINDS];
    let mut kind = 0;
    let mut add = |kind: usize, d: f64, se: f64| {
        if d.is_finite() && se > 0.0 && se.is_finite() {
            parts[kind].0 += (d / se).powi(2);
            parts[kind].1 += 1;
        }
    };
    for (a, b) in m
        .psd_x
        .iter()
        .zip(&o.psd_x)
        .chain(m.psd_y.iter().zip(&o.psd_y))
    {
        if a.value > 0.0 && b.value > 0.0 {
            add(
                kind,
                (a.value / b.value).ln(),
                ((a.se / a.value).powi(2) + (b.se / b.value).powi(2)).sqrt(),
            );
        }
    }
    kind += 1;
    // Noise only where both sides measured it against a static repeat. A single frame's
    // estimate (the 3x3 second difference at every pixel) is the speckle's curvature as much as
    // its noise: on a 640x540 control's moved frame 1.5e5–1.6e7 DN² per bin against a noise of
    // some 400 DN², and 26 of 30 controls with nothing hidden disagreed with their model on it
    // by χ²/n 3.3–175 — the print's fine structure, which the spectra already compare, counted
    // again under the name of noise.
    if m.ptc_from_repeat && o.ptc_from_repeat {
        for p in &m.ptc {
            if let Some((v, se)) = ptc_at(&o.ptc, p.mean_dn) {
                add(kind, p.variance_dn2 - v, (p.se * p.se + se * se).sqrt());
            }
        }
    }
    kind += 1;
    for ((a, sa), (b, sb)) in m
        .mean_map
        .values
        .iter()
        .zip(&m.mean_map.se)
        .zip(o.mean_map.values.iter().zip(&o.mean_map.se))
    {
        add(kind, a - b, (sa * sa + sb * sb).sqrt());
    }
    add(
        kind + 1,
        m.contrast - o.contrast,
        (m.contrast_se.powi(2) + o.contrast_se.powi(2)).sqrt(),
    );
    parts
}

/// N_eff/N of a comparison's analyses. They are not independent: every run of a pattern shares its
/// reference frame, every scheme of a run its moved frame; half the noise comes from each. For a
/// disagreement common to all analyses a sum over N analyses counts it N times where the data
/// hold N_eff = 1/(½Σ_runs(n_r/N)² + ½Σ_patterns(n_p/N)²) independent looks.
pub fn shared_fraction(runs: &[RunComparison]) -> f64 {
    shared_fraction_of(runs.iter().map(|r| (r.id.as_str(), r.pattern.as_str())))
}

/// [`shared_fraction`] of analyses given by (run id, pattern label).
pub fn shared_fraction_of<'a>(analyses: impl Iterator<Item = (&'a str, &'a str)>) -> f64 {
    let mut per_run: std::collections::BTreeMap<&str, f64> = Default::default();
    let mut per_pattern: std::collections::BTreeMap<&str, f64> = Default::default();
    let mut total = 0.0;
    for (run, pattern) in analyses {
        *per_run.entry(run).or_default() += 1.0;
        *per_pattern.entry(pattern).or_default() += 1.0;
        total += 1.0;
    }
    let total = f64::max(total, 1.0);
    let conc = |m: &std::collections::BTreeMap<&str, f64>| {
        m.values().map(|k| (k / total).powi(2)).sum::<f64>()
    };
    let n_eff = 1.0 / (0.5 * conc(&per_run) + 0.5 * conc(&per_pattern)).max(1.0 / total);
    n_eff / total
}

/// χ² of a comparison; `noise_from` holds the noise levels fixed to another comparison's (the one
/// without the candidate) so two χ² can be subtracted.
pub fn chi2(cmp: &Comparison, noise_from: Option<&Comparison>, dic: &DicSettings) -> Chi2 {
    let infl = inflation(dic);
    let (mut field, mut std, mut n) = (0.0, 0.0, 0usize);
    let shared = shared_fraction(&cmp.runs);
    for (k, r) in cmp.runs.iter().enumerate() {
        let d = &r.detail;
        let var = noise_from
            .and_then(|b| b.runs.get(k))
            .map_or(d.residual_var_px2, |b| b.detail.residual_var_px2);
        if !(var.0 > 0.0 && var.1 > 0.0) || d.common.is_empty() {
            continue;
        }
        let s: f64 = d
            .common
            .iter()
            .map(|p| p.fit_du * p.fit_du / var.0 + p.fit_dv * p.fit_dv / var.1)
            .sum();
        field += s / infl;
        n += 12;
        let n_eff = (d.points as f64 / infl).max(1.0);
        for c in 0..2 {
            let (a, b) = (r.measured.random_px[c], r.model.random_px[c]);
            let se = ((a * a + b * b) / (2.0 * n_eff)).sqrt();
            if se > 0.0 && (a - b).is_finite() {
                std += ((a - b) / se).powi(2);
                n += 1;
            }
        }
    }
    field *= shared;
    std *= shared;
    let mut image = 0.0;
    let mut n_image = 0;
    let mut image_parts = [(0.0, 0usize); IMAGE_KINDS];
    // The moved frames of a pattern show the same print as its reference, shifted: their
    // statistics repeat the reference's disagreement with the model's print, so together they
    // count as one frame (each weighs 1/moved frames of its pattern), and the mean-intensity map
    // — a property of the illumination and lens, not of the move — is the reference's alone.
    // What the light did between the frames is the moved frames' light change against their
    // reference ([`light_change_of`]), weighed as their other statistics.
    for (im, weight) in cmp.images.iter().zip(image_weights(&cmp.images)) {
        for (kind, (acc, (c, k))) in image_parts
            .iter_mut()
            .zip(image_chi2_parts(&im.measured, &im.model))
            .enumerate()
        {
            if im.run.is_some() && kind == MEAN_MAP {
                continue;
            }
            let k = (k as f64 * weight).round() as usize;
            acc.0 += c * weight;
            acc.1 += k;
            image += c * weight;
            n_image += k;
        }
    }
    let light = light_change_of(&cmp.images);
    image_parts[LIGHT_CHANGE] = light;
    image += light.0;
    n_image += light.1;
    n += n_image;
    Chi2 {
        field,
        std,
        image,
        total: field + std + image,
        observations: n,
        image_observations: n_image,
        image_parts,
    }
}

/// The image χ² change from `before` to `after`, each kind divided by its overdispersion
/// ĉ = max(1, χ²/n) with the candidate (quasi-likelihood: statistics that scatter about the model
/// more than their standard errors say — a print's texture in the mean map, a print's spectrum
/// the model cannot draw — count only as much as their scatter allows). Negative is a drop.
pub fn image_change(before: &Chi2, after: &Chi2) -> f64 {
    before
        .image_parts
        .iter()
        .zip(&after.image_parts)
        .map(|(b, a)| {
            let c_hat = (a.0 / a.1.max(1) as f64).max(1.0);
            (a.0 - b.0) / c_hat
        })
        .sum()
}

/// ΔBIC of adding `k` parameters that moved χ² from `before` to `after`, the image statistics
/// scaled for their overdispersion ([`image_change`]).
pub fn delta_bic(before: &Chi2, after: &Chi2, k: usize) -> f64 {
    (after.field - before.field)
        + (after.std - before.std)
        + image_change(before, after)
        + k as f64 * (before.observations.max(1) as f64).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chi2(field: f64, std: f64, image_parts: [(f64, usize); IMAGE_KINDS]) -> Chi2 {
        Chi2 {
            field,
            std,
            image: image_parts.iter().map(|p| p.0).sum(),
            total: 0.0,
            observations: 1000,
            image_observations: image_parts.iter().map(|p| p.1).sum(),
            image_parts,
        }
    }

    /// A moved frame's statistics with an 8×8 light map of `value(x, y)` (x, y px over
    /// 640×540), each block ± 0.002.
    fn with_light(value: impl Fn(f64, f64) -> f64) -> FrameStats {
        let xs: Vec<f64> = (0..8).map(|i| 40.0 + 80.0 * i as f64).collect();
        let ys: Vec<f64> = (0..8).map(|j| 33.75 + 67.5 * j as f64).collect();
        let values = ys
            .iter()
            .flat_map(|&y| xs.iter().map(move |&x| (x, y)))
            .map(|(x, y)| value(x, y))
            .collect();
        FrameStats {
            light_map: Some(crate::diagnose::image_stats::MeanMap {
                nx: 8,
                ny: 8,
                xs,
                ys,
                values,
                se: vec![0.002; 64],
            }),
            ..crate::diagnose::test_fields::frame_stats(2000.0)
        }
    }

    /// The light change counts what varies across the moved frame beyond the model, not a
    /// uniform change: 2 % more light everywhere leaves χ² at 0, a ramp (±3 %, about 6.5
    /// errors of q RMS) is far beyond its 63 observations.
    #[test]
    fn the_light_change_is_what_varies_over_the_moved_frame() {
        let moved = |measured: FrameStats| ImageComparison {
            frame: "moved".into(),
            pattern: "a".into(),
            run: Some("x5mm".into()),
            measured,
            model: with_light(|_, _| 1.0),
        };
        let (chi2, n) = light_change_chi2(&moved(with_light(|_, _| 1.02)));
        assert_eq!(n, 63);
        assert!(chi2 < 1e-9, "{chi2}");
        let lamp = moved(with_light(|x, _| 1.0 + 1e-4 * (x - 320.0)));
        let (chi2, _) = light_change_chi2(&lamp);
        assert!(chi2 > 20.0 * 63.0, "{chi2}");
        // A reference has none.
        let reference = ImageComparison {
            run: None,
            ..moved(with_light(|_, _| 1.0))
        };
        assert_eq!(light_change_of(&[reference]), (0.0, 0));
    }

    #[test]
    fn delta_bic_of_a_known_comparison() {
        // The field χ² falls from 900 to 400, std from 50 to 48, the images are well described
        // (χ² at their count) and stay: ΔBIC = −500 − 2 + 0 + 2·ln 1000 = −488.18.
        let parts = [(100.0, 100), (20.0, 20), (0.0, 0), (1.0, 1), (0.0, 0)];
        let before = chi2(900.0, 50.0, parts);
        let after = chi2(400.0, 48.0, parts);
        let expected = -502.0 + 2.0 * 1000f64.ln();
        assert!((delta_bic(&before, &after, 2) - expected).abs() < 1e-9);
        assert!(delta_bic(&before, &after, 2) < SIGNIFICANT_DELTA_BIC);
        // A candidate that changes nothing pays its parameters' price.
        assert_eq!(delta_bic(&before, &before, 3), 3.0 * 1000f64.ln());
    }

    #[test]
    fn an_overdispersed_image_statistic_counts_only_as_far_as_its_scatter() {
        // Spectra at χ²/n = 4 with the candidate: a drop of 200 counts as 50.
        let before = chi2(
            0.0,
            0.0,
            [(600.0, 100), (20.0, 20), (0.0, 0), (1.0, 1), (0.0, 0)],
        );
        let after = chi2(
            0.0,
            0.0,
            [(400.0, 100), (20.0, 20), (0.0, 0), (1.0, 1), (0.0, 0)],
        );
        assert!((image_change(&before, &after) + 50.0).abs() < 1e-12);
    }

    /// The noise's χ² counts frames whose noise both sides measured against a static repeat;
    /// a single frame's curve (speckle curvature as much as noise) adds nothing.
    #[test]
    fn noise_is_compared_only_between_repeats() {
        let curve = |variance_dn2: f64| {
            [1000.0, 2000.0, 3000.0]
                .map(|mean_dn| PtcPoint {
                    mean_dn,
                    variance_dn2,
                    se: 1.0,
                })
                .to_vec()
        };
        let stats = |variance_dn2: f64, from_repeat: bool| FrameStats {
            ptc: curve(variance_dn2),
            ptc_from_repeat: from_repeat,
            ..crate::diagnose::test_fields::frame_stats(2000.0)
        };
        const NOISE: usize = 1;
        // 10 DN² apart at SE √2 per point: χ² = 3 · 100/2.
        let both = image_chi2_parts(&stats(410.0, true), &stats(400.0, true));
        assert_eq!(both[NOISE].1, 3);
        assert!((both[NOISE].0 - 150.0).abs() < 1e-9, "{:?}", both[NOISE]);
        for (m, o) in [(false, true), (true, false), (false, false)] {
            let one = image_chi2_parts(&stats(4.1e5, m), &stats(400.0, o));
            assert_eq!(
                one[NOISE],
                (0.0, 0),
                "repeat on the model {m}, measured {o}"
            );
        }
    }

    #[test]
    fn shared_frames_reduce_the_effective_count() {
        // Three schemes of one run of one pattern: one look, not three.
        let one_run = [("r", "a"); 3];
        assert!((shared_fraction_of(one_run.into_iter()) - 1.0 / 3.0).abs() < 1e-12);
        // Runs of distinct patterns and one scheme each are independent looks.
        let distinct = [("r1", "a"), ("r2", "b"), ("r3", "c"), ("r4", "d")];
        assert!((shared_fraction_of(distinct.into_iter()) - 1.0).abs() < 1e-12);
        // Subsets of 29 px every 10 px: (29/10)² = 8.41.
        let dic = DicSettings {
            subset_px: 29,
            step_px: 10,
            ..DicSettings::default()
        };
        assert!((inflation(&dic) - 8.41).abs() < 1e-12);
    }
}
