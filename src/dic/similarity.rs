//! A global rotation and scale between two images by the Fourier-Mellin transform (Reddy &
//! Chatterji, "An FFT-based technique for translation, rotation, and scale-invariant image
//! registration", IEEE Trans. Image Process. 5 (1996)): the magnitude spectrum ignores the
//! translation, and on log-polar axes a rotation and a scale become a shift that a phase
//! correlation finds. A second phase correlation of the rotated and scaled reference then gives
//! the translation.
//!
//! It is the first guess for seed points when the rigid offset is not enough — a specimen
//! turned by 10° moves its subsets' corners by ≈5 px relative to their centres, where IC-GN
//! from a translation no longer converges and an integer search finds nothing.

use super::fft_guess::{fast_fft_len_at_most, fft2d, ReferenceSpectrum};
use super::Warp;
use crate::image::{Image, Roi};
use ffdic_fft::{Complex, Direction};

/// Side of the square windows whose spectra are compared.
const SPECTRUM_WINDOW_PX: usize = 256;
/// Samples along angle (over 180°: a real image's magnitude spectrum is point-symmetric) and
/// along log-radius.
const LOG_POLAR_SAMPLES: usize = 256;
/// Innermost radius sampled, in frequency bins: the lowest frequencies hold the window's shape
/// more than the texture's.
const MIN_RADIUS_BINS: f64 = 3.0;
/// Side of the window for the translation (as the rigid offset's).
const TRANSLATION_WINDOW_PX: usize = 384;

/// x_def = centre + s·R(θ)·(X − centre) + translation, image axes (x right, y down), θ
/// positive from +x towards +y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    pub angle_rad: f64,
    pub scale: f64,
    pub centre: (f64, f64),
    pub translation: (f64, f64),
}

impl Similarity {
    /// The first-order shape this similarity gives the subset centred at (x, y).
    pub fn warp_at(&self, x: f64, y: f64) -> Warp {
        let (c, s) = (
            self.scale * self.angle_rad.cos(),
            self.scale * self.angle_rad.sin(),
        );
        let (dx, dy) = (x - self.centre.0, y - self.centre.1);
        let xd = self.centre.0 + c * dx - s * dy + self.translation.0;
        let yd = self.centre.1 + s * dx + c * dy + self.translation.1;
        Warp {
            u: xd - x,
            ux: c - 1.0,
            uy: -s,
            v: yd - y,
            vx: s,
            vy: c - 1.0,
        }
    }
}

/// Estimates the similarity around the centre of `roi`. `offset` is the rigid offset already
/// found (it places the deformed spectrum window over the same material); `max_motion_px`
/// bounds the translation. None when the images are too small or without texture.
pub fn estimate_similarity(
    reference: &Image,
    deformed: &Image,
    roi: Roi,
    offset: (i64, i64),
    max_motion_px: usize,
) -> Option<Similarity> {
    let (w, h) = (reference.width(), reference.height());
    let k = fast_fft_len_at_most(SPECTRUM_WINDOW_PX.min(w).min(h));
    if k < 32 {
        return None;
    }
    let (cx, cy) = (roi.x + roi.width / 2, roi.y + roi.height / 2);
    let place = |c: i64, size: usize, extent: usize| -> usize {
        (c - size as i64 / 2).clamp(0, (extent - size) as i64) as usize
    };
    let (rx, ry) = (place(cx as i64, k, w), place(cy as i64, k, h));
    // The spectra must hold the same material: the deformed window sits where the rigid
    // offset puts it — but a rigid offset found under a large rotation may be a false peak, so
    // the window in place is tried as well, and the sharper log-polar peak wins.
    let ref_spectrum = magnitude_spectrum(reference, (rx, ry), k)?;
    let n = LOG_POLAR_SAMPLES;
    let max_radius = k as f64 / 2.0 - 2.0;
    let log_step = (max_radius / MIN_RADIUS_BINS).ln() / n as f64;
    let ref_log_polar = log_polar(&ref_spectrum, k, log_step);
    let mut candidates = vec![offset];
    if offset != (0, 0) {
        candidates.push((0, 0));
    }
    let (angle_rad, scale, _) = candidates
        .into_iter()
        .filter_map(|(ox, oy)| {
            let at = (place(cx as i64 + ox, k, w), place(cy as i64 + oy, k, h));
            let spectrum = magnitude_spectrum(deformed, at, k)?;
            let b = log_polar(&spectrum, k, log_step);
            rotation_and_scale(ref_log_polar.clone(), b, log_step)
        })
        .max_by(|a, b| a.2.total_cmp(&b.2))?;
    if !(scale.is_finite() && (0.5..2.0).contains(&scale)) {
        return None;
    }

    // The translation: the reference window turned and scaled about its centre, matched
    // against the deformed image by the rigid-offset correlation.
    let kx = w.min(TRANSLATION_WINDOW_PX);
    let ky = h.min(TRANSLATION_WINDOW_PX);
    let (tx0, ty0) = (place(cx as i64, kx, w), place(cy as i64, ky, h));
    let centre = (tx0 as f64 + kx as f64 / 2.0, ty0 as f64 + ky as f64 / 2.0);
    let (cos, sin) = (angle_rad.cos() / scale, angle_rad.sin() / scale);
    let mut window = vec![f32::NAN; kx * ky];
    let (mut sum, mut count) = (0.0f64, 0usize);
    for r in 0..ky {
        for c in 0..kx {
            // X = centre + A⁻¹ (x − centre), A⁻¹ = R(−θ)/s.
            let (ex, ey) = (
                tx0 as f64 + c as f64 - centre.0,
                ty0 as f64 + r as f64 - centre.1,
            );
            let (x, y) = (
                centre.0 + cos * ex + sin * ey,
                centre.1 - sin * ex + cos * ey,
            );
            if let Some(v) = bilinear(reference, x, y) {
                window[r * kx + c] = v;
                sum += v as f64;
                count += 1;
            }
        }
    }
    if count == 0 {
        return None;
    }
    let mean = (sum / count as f64) as f32;
    for v in window.iter_mut() {
        *v = if v.is_nan() { 0.0 } else { *v - mean };
    }
    let size = (deformed.width(), deformed.height());
    let (ox, oy) = ReferenceSpectrum::of_window(&window, (kx, ky), (tx0, ty0), size, max_motion_px)
        .offset_in(deformed);
    Some(Similarity {
        angle_rad,
        scale,
        centre,
        translation: (ox as f64, oy as f64),
    })
}

/// Phase correlation of two log-polar spectra: (angle, scale, peak height). Rows are angle,
/// columns log-radius; shifts beyond half an axis are negative.
fn rotation_and_scale(
    mut a: Vec<Complex<f32>>,
    mut b: Vec<Complex<f32>>,
    log_step: f64,
) -> Option<(f64, f64, f64)> {
    let n = LOG_POLAR_SAMPLES;
    fft2d(&mut a, n, Direction::Forward);
    fft2d(&mut b, n, Direction::Forward);
    for (x, y) in a.iter_mut().zip(&b) {
        let cross = x.conj() * y;
        let mag = cross.norm();
        *x = if mag > 1e-20 {
            cross / mag
        } else {
            Complex::new(0.0, 0.0)
        };
    }
    fft2d(&mut a, n, Direction::Inverse);
    let (mut best, mut at) = (f32::NEG_INFINITY, (0usize, 0usize));
    for (idx, v) in a.iter().enumerate() {
        if v.re > best {
            best = v.re;
            at = (idx % n, idx / n);
        }
    }
    if !best.is_finite() {
        return None;
    }
    let value = |r: usize, c: usize| a[(r % n) * n + (c % n)].re as f64;
    let (c0, r0) = at;
    let sub_r = parabola(value(r0 + n - 1, c0), value(r0, c0), value(r0 + 1, c0));
    let sub_c = parabola(value(r0, c0 + n - 1), value(r0, c0), value(r0, c0 + 1));
    let signed = |i: usize, sub: f64| {
        let i = if i >= n / 2 {
            i as f64 - n as f64
        } else {
            i as f64
        };
        i + sub
    };
    let angle_rad = signed(r0, sub_r) * std::f64::consts::PI / n as f64;
    // A scale s in space shrinks the spectrum by 1/s: the deformed spectrum's features sit
    // at radii 1/s times the reference's.
    let scale = (-signed(c0, sub_c) * log_step).exp();
    Some((angle_rad, scale, best as f64))
}

/// |FFT| of the Hann-windowed, zero-mean k x k window at `origin`, centred (DC at k/2) and
/// weighted by Reddy & Chatterji's high-pass (1 − cos πξ cos πη)(2 − cos πξ cos πη), which
/// lets the texture's frequencies speak rather than the window's.
fn magnitude_spectrum(image: &Image, (x0, y0): (usize, usize), k: usize) -> Option<Vec<f32>> {
    let (mean, std) = image.crop(Roi::new(x0, y0, k, k)).mean_std();
    if !(std > 0.0) {
        return None;
    }
    let hann: Vec<f64> = (0..k)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / k as f64).cos())
        .collect();
    let mut data = vec![Complex::new(0.0f32, 0.0); k * k];
    for r in 0..k {
        for c in 0..k {
            let v = (image.get(x0 + c, y0 + r) as f64 - mean) * hann[r] * hann[c];
            data[r * k + c].re = v as f32;
        }
    }
    fft2d(&mut data, k, Direction::Forward);
    let mut out = vec![0.0f32; k * k];
    for r in 0..k {
        for c in 0..k {
            let (sr, sc) = ((r + k / 2) % k, (c + k / 2) % k);
            let xi = std::f64::consts::PI * (sc as f64 - (k / 2) as f64) / k as f64;
            let eta = std::f64::consts::PI * (sr as f64 - (k / 2) as f64) / k as f64;
            let q = xi.cos() * eta.cos();
            let high_pass = (1.0 - q) * (2.0 - q);
            out[sr * k + sc] = data[r * k + c].norm() * high_pass as f32;
        }
    }
    Some(out)
}

/// Resamples a centred k x k spectrum on n x n log-polar axes (rows: angle 0..180°, columns:
/// radius MIN_RADIUS_BINS·e^(j·log_step)), zero-mean, as complex input for a phase correlation.
fn log_polar(spectrum: &[f32], k: usize, log_step: f64) -> Vec<Complex<f32>> {
    let n = LOG_POLAR_SAMPLES;
    let centre = (k / 2) as f64;
    let mut out = vec![Complex::new(0.0f32, 0.0); n * n];
    let mut sum = 0.0f64;
    for r in 0..n {
        let theta = std::f64::consts::PI * r as f64 / n as f64;
        let (cos, sin) = (theta.cos(), theta.sin());
        for c in 0..n {
            let rho = MIN_RADIUS_BINS * (c as f64 * log_step).exp();
            let (x, y) = (centre + rho * cos, centre + rho * sin);
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let (x0, y0) = (x0 as usize, y0 as usize);
            let at = |xx: usize, yy: usize| spectrum[yy.min(k - 1) * k + xx.min(k - 1)] as f64;
            let v = (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x0 + 1, y0))
                + fy * ((1.0 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
            out[r * n + c].re = v as f32;
            sum += v;
        }
    }
    let mean = (sum / (n * n) as f64) as f32;
    for v in out.iter_mut() {
        v.re -= mean;
    }
    out
}

/// Sub-sample position of a peak from three samples (−1, 0, +1), within ±0.5.
fn parabola(left: f64, centre: f64, right: f64) -> f64 {
    let denom = left - 2.0 * centre + right;
    if denom.abs() < 1e-20 {
        return 0.0;
    }
    (0.5 * (left - right) / denom).clamp(-0.5, 0.5)
}

/// Bilinear sample at (x, y), None outside the image.
fn bilinear(image: &Image, x: f64, y: f64) -> Option<f32> {
    let (w, h) = (image.width(), image.height());
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
        return None;
    }
    let (x0, y0) = (
        (x.floor() as usize).min(w - 2),
        (y.floor() as usize).min(h - 2),
    );
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let at = |c: usize, r: usize| image.get(c, r);
    Some(
        (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x0 + 1, y0))
            + fy * ((1.0 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth random texture: Gaussian blobs evaluated analytically at any point, so a
    /// rotated and scaled copy is exact (no resampling of a raster).
    fn blobs(seed: u64) -> Vec<(f64, f64, f64)> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..9000)
            .map(|_| (next() * 700.0 - 50.0, next() * 700.0 - 50.0, 1.5 + next()))
            .collect()
    }

    fn render(blobs: &[(f64, f64, f64)]) -> Image {
        let mut img = Image::filled(600, 600, 0.0);
        for &(bx, by, s) in blobs {
            let reach = (4.0 * s).ceil() as i64;
            for r in (by as i64 - reach).max(0)..(by as i64 + reach).min(599) {
                for c in (bx as i64 - reach).max(0)..(bx as i64 + reach).min(599) {
                    let d2 = (c as f64 - bx).powi(2) + (r as f64 - by).powi(2);
                    let v = img.get(c as usize, r as usize) + (-d2 / (2.0 * s * s)).exp() as f32;
                    img.set(c as usize, r as usize, v);
                }
            }
        }
        img
    }

    #[test]
    fn finds_rotation_scale_and_translation() {
        let b = blobs(7);
        let reference = render(&b);
        let truth = Similarity {
            angle_rad: 8f64.to_radians(),
            scale: 1.05,
            centre: (320.0, 280.0),
            translation: (6.0, -4.0),
        };
        // The deformed image shows the reference blob at X at truth(X), its σ scaled.
        let moved: Vec<(f64, f64, f64)> = b
            .iter()
            .map(|&(x, y, s)| {
                let w = truth.warp_at(x, y);
                (x + w.u, y + w.v, s * truth.scale)
            })
            .collect();
        let deformed = render(&moved);
        let roi = Roi::centred(600, 600, 400, 400);
        let est = estimate_similarity(&reference, &deformed, roi, (0, 0), 100).unwrap();
        assert!(
            (est.angle_rad - truth.angle_rad).abs() < 0.3f64.to_radians(),
            "{est:?}"
        );
        assert!((est.scale - truth.scale).abs() < 0.01, "{est:?}");
        for (x, y) in [(150.0, 150.0), (450.0, 300.0), (300.0, 450.0)] {
            let (p, q) = (est.warp_at(x, y), truth.warp_at(x, y));
            assert!(
                (p.u - q.u).abs() < 2.5 && (p.v - q.v).abs() < 2.5,
                "{x},{y}: {p:?} vs {q:?}"
            );
        }
    }
}
