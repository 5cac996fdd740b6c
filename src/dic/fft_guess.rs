//! Global integer rigid offset by phase correlation (Kuglin & Hines, "The phase correlation image
//! alignment method", Proc. IEEE Int. Conf. Cybernetics and Society, 1975), computed once per
//! image pair with rustfft instead of once per point (the per-point FFT-CC of Pan, Li & Tong,
//! Exp. Mech. 53 (2013) costs seconds on a dense grid for large motions).
//!
//! A window of the reference ROI is zero-padded into an L x L frame; the deformed window of the
//! same L x L size starts `max_motion` px before it, so every offset up to `max_motion` in any
//! direction is found without circular wrap-around.

use crate::image::{Image, Roi};
use ffdic_fft::{plan_f32, plan_real_forward_f32, plan_real_inverse_f32, Complex, Direction};
use rayon::prelude::*;

/// Side of the reference window: big enough for a sharp peak, small enough to stay cheap.
const MAX_WINDOW_PX: usize = 384;

/// Integer (dx, dy) such that reference content at p appears at p + (dx, dy) in `deformed`.
/// Returns (0, 0) for images without texture.
pub fn global_offset(
    reference: &Image,
    deformed: &Image,
    roi: Roi,
    max_motion_px: usize,
) -> (i64, i64) {
    let size = (deformed.width(), deformed.height());
    ReferenceSpectrum::of_image(reference, roi, max_motion_px, size)
        .map_or((0, 0), |r| r.offset_in(deformed))
}

/// The reference side of [`global_offset`], transformed once: a prepared reference correlated
/// with many deformed frames (every run of a pattern, every model frame of a diagnosis) pays two
/// 2D FFTs per frame instead of three.
pub(super) struct ReferenceSpectrum {
    /// The forward 2D FFT of the zero-mean window, zero-padded into the L x L frame: its
    /// non-negative x frequencies ([`real_fft2d`]'s layout).
    spectrum: Vec<Complex<f32>>,
    /// L, the frame's side.
    side: usize,
    /// The largest motion searched, px (the setting, clamped to the deformed frame's size).
    motion_px: usize,
    /// Where the window was taken in the reference (its top-left pixel).
    origin: (usize, usize),
    /// The deformed frames' size the motion was clamped to.
    deformed_size: (usize, usize),
}

impl ReferenceSpectrum {
    /// The window of `reference` around `roi` (it may extend beyond it: the rigid offset is a
    /// property of the image pair, and a small template gives a noisy correlation peak),
    /// transformed; `None` when the window has no texture.
    pub(super) fn of_image(
        reference: &Image,
        roi: Roi,
        max_motion_px: usize,
        deformed_size: (usize, usize),
    ) -> Option<Self> {
        let (cx, cy) = (roi.x + roi.width / 2, roi.y + roi.height / 2);
        let (w, h) = (reference.width(), reference.height());
        let kx = w.min(MAX_WINDOW_PX);
        let ky = h.min(MAX_WINDOW_PX);
        let rx = cx.saturating_sub(kx / 2).min(w - kx);
        let ry = cy.saturating_sub(ky / 2).min(h - ky);

        let (ref_mean, ref_std) = reference.crop(Roi::new(rx, ry, kx, ky)).mean_std();
        if ref_std <= 0.0 {
            return None;
        }
        let window: Vec<f32> = (0..kx * ky)
            .map(|k| (reference.get(rx + k % kx, ry + k / kx) as f64 - ref_mean) as f32)
            .collect();
        Some(Self::of_window(
            &window,
            (kx, ky),
            (rx, ry),
            deformed_size,
            max_motion_px,
        ))
    }

    /// The zero-mean `window` (kx x ky, row-major, taken at (rx, ry) of some reference),
    /// transformed for deformed frames of `deformed_size`, searched up to `max_motion_px`.
    pub(super) fn of_window(
        window: &[f32],
        (kx, ky): (usize, usize),
        (rx, ry): (usize, usize),
        deformed_size: (usize, usize),
        max_motion_px: usize,
    ) -> Self {
        // A motion larger than the image leaves no overlap to find: clamping keeps the L x L
        // frame (L ≈ window + 2m) from growing with a careless setting.
        let m = max_motion_px.min(deformed_size.0.max(deformed_size.1));
        let l = fast_fft_len(kx.max(ky) + 2 * m);
        let mut a = vec![0.0f32; l * l];
        for (frame_row, window_row) in a.chunks_exact_mut(l).zip(window.chunks_exact(kx)) {
            frame_row[..kx].copy_from_slice(window_row);
        }
        Self {
            spectrum: real_fft2d(&mut a, l),
            side: l,
            motion_px: m,
            origin: (rx, ry),
            deformed_size,
        }
    }

    /// Integer (dx, dy), each within ±m, at which the window best matches `deformed` (of the
    /// size this spectrum was made for).
    pub(super) fn offset_in(&self, deformed: &Image) -> (i64, i64) {
        assert_eq!(
            (deformed.width(), deformed.height()),
            self.deformed_size,
            "a reference spectrum is made for one size of deformed frame"
        );
        let (l, m) = (self.side, self.motion_px);
        // The deformed window; samples outside the image are filled with its mean (zero after
        // removing the mean) so they add nothing to the correlation.
        let dx0 = self.origin.0 as i64 - m as i64;
        let dy0 = self.origin.1 as i64 - m as i64;
        // The frame's rows and columns that fall inside the image, and each inside row's pixels
        // (the frame's column range of them), row after row as the frame holds them.
        let inside = |origin: i64, size: usize| {
            let lo = (-origin).clamp(0, l as i64) as usize;
            let hi = (size as i64 - origin).clamp(lo as i64, l as i64) as usize;
            lo..hi
        };
        let cols = inside(dx0, deformed.width());
        let rows = if cols.is_empty() {
            0..0
        } else {
            inside(dy0, deformed.height())
        };
        let row_pixels = |r: usize| {
            let y = (dy0 + r as i64) as usize;
            let x0 = (dx0 + cols.start as i64) as usize;
            &deformed.data()[y * deformed.width() + x0..][..cols.len()]
        };
        let (mut sum, mut n) = (0.0f64, 0usize);
        for r in rows.clone() {
            for &v in row_pixels(r) {
                sum += v as f64;
            }
            n += cols.len();
        }
        let def_mean = if n > 0 { sum / n as f64 } else { 0.0 };
        let mut b = vec![0.0f32; l * l];
        for r in rows.clone() {
            let frame_row = &mut b[r * l + cols.start..][..cols.len()];
            for (z, &v) in frame_row.iter_mut().zip(row_pixels(r)) {
                *z = (v as f64 - def_mean) as f32;
            }
        }

        let mut spectrum = real_fft2d(&mut b, l);
        // Half-way whitening (divide by sqrt|X|): sharper than plain cross-correlation, steadier
        // than full phase correlation, whose flat weighting lets the padding edges speak. The
        // product of two real frames' spectra is Hermitian, and so is its whitening: the
        // non-negative x frequencies carry it all.
        for (x, y) in self.spectrum.iter().zip(spectrum.iter_mut()) {
            let cross = x.conj() * *y;
            let mag = cross.norm().sqrt();
            *y = if mag > 1e-20 {
                cross / mag
            } else {
                Complex::new(0.0, 0.0)
            };
        }
        let correlation = real_ifft2d(&mut spectrum, l);

        // Only shifts within ±m: the frame is larger than window + 2m (a 5-smooth length), and
        // a peak in the excess would be a motion the user ruled out.
        let reach = (2 * m + 1).min(l);
        let (mut best, mut best_at) = (f32::NEG_INFINITY, (0usize, 0usize));
        for sy in 0..reach {
            for (sx, &v) in correlation[sy * l..sy * l + reach].iter().enumerate() {
                if v > best {
                    best = v;
                    best_at = (sx, sy);
                }
            }
        }
        (best_at.0 as i64 - m as i64, best_at.1 as i64 - m as i64)
    }
}

/// In-place 2D FFT of an n x n row-major array (rows in parallel, then columns through a
/// transpose), planned from this thread's cache: every image pair of a diagnosis transforms
/// frames of one size.
pub(super) fn fft2d(data: &mut [Complex<f32>], n: usize, direction: Direction) {
    transform_rows(data, n, direction);
    transpose(data, n);
    transform_rows(data, n, direction);
    transpose(data, n);
}

/// Rows of a transform done together: enough work per rayon task (one scratch per task).
const ROWS_PER_TASK: usize = 16;

/// Every row of `len` points of the row-major `data` transformed in place, rows on rayon.
fn transform_rows(data: &mut [Complex<f32>], len: usize, direction: Direction) {
    let fft = plan_f32(len, direction);
    data.par_chunks_mut(len * ROWS_PER_TASK)
        .for_each(|chunk| fft.process(chunk));
}

/// The 2D FFT of a real l x l row-major `frame` (used as scratch), its non-negative x frequencies
/// only: `h = l / 2 + 1` rows of `l`, row kx holding frequencies (kx, 0..l) (the transpose of the
/// usual layout; the rest is the conjugate, X(−kx, −ky) = X̄(kx, ky)). The rows' real transforms,
/// a transpose, then the columns' complex ones: about half the work of [`fft2d`] on a complex
/// frame, which was most of a small frame's correlation (the rigid offset, 12 % of a 640x540
/// diagnosis round).
fn real_fft2d(frame: &mut [f32], l: usize) -> Vec<Complex<f32>> {
    let h = l / 2 + 1;
    let rows = plan_real_forward_f32(l);
    let mut half = vec![Complex::new(0.0f32, 0.0); l * h];
    frame
        .par_chunks_mut(l * ROWS_PER_TASK)
        .zip(half.par_chunks_mut(h * ROWS_PER_TASK))
        .for_each(|(input, output)| {
            let mut scratch = rows.make_scratch_vec();
            for (i, o) in input.chunks_exact_mut(l).zip(output.chunks_exact_mut(h)) {
                rows.process_with_scratch(i, o, &mut scratch)
                    .expect("buffers of the plan's lengths");
            }
        });
    let mut spectrum = transposed(&half, l, h);
    transform_rows(&mut spectrum, l, Direction::Forward);
    spectrum
}

/// The inverse of [`real_fft2d`] (its layout, used as scratch), unnormalised: the real l x l
/// frame, l² times the original. The x frequencies 0 and l/2 of a Hermitian spectrum are real
/// after the columns' inverse: their rounding's imaginary part is dropped, as the real
/// transform requires.
fn real_ifft2d(spectrum: &mut [Complex<f32>], l: usize) -> Vec<f32> {
    let h = l / 2 + 1;
    transform_rows(spectrum, l, Direction::Inverse);
    let mut half = transposed(spectrum, h, l);
    let rows = plan_real_inverse_f32(l);
    let mut frame = vec![0.0f32; l * l];
    half.par_chunks_mut(h * ROWS_PER_TASK)
        .zip(frame.par_chunks_mut(l * ROWS_PER_TASK))
        .for_each(|(input, output)| {
            let mut scratch = rows.make_scratch_vec();
            for (i, o) in input.chunks_exact_mut(h).zip(output.chunks_exact_mut(l)) {
                i[0].im = 0.0;
                if l.is_multiple_of(2) {
                    i[h - 1].im = 0.0;
                }
                rows.process_with_scratch(i, o, &mut scratch)
                    .expect("buffers of the plan's lengths, real ends");
            }
        });
    frame
}

/// The transpose of a `rows` x `cols` row-major array.
fn transposed(data: &[Complex<f32>], rows: usize, cols: usize) -> Vec<Complex<f32>> {
    let mut out = vec![Complex::new(0.0f32, 0.0); rows * cols];
    for (r, row) in data.chunks_exact(cols).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            out[c * rows + r] = v;
        }
    }
    out
}

fn transpose(data: &mut [Complex<f32>], n: usize) {
    for r in 0..n {
        for c in r + 1..n {
            data.swap(r * n + c, c * n + r);
        }
    }
}

/// Smallest length >= n whose only prime factors are 2, 3 and 5.
pub(super) fn fast_fft_len(n: usize) -> usize {
    (n..)
        .find(|&m| {
            let mut k = m;
            for p in [2, 3, 5] {
                while k % p == 0 {
                    k /= p;
                }
            }
            k == 1
        })
        .expect("a 5-smooth number always exists")
}

/// Largest length <= n whose only prime factors are 2, 3 and 5 (n >= 1).
pub(super) fn fast_fft_len_at_most(n: usize) -> usize {
    (1..=n.max(1))
        .rev()
        .find(|&m| fast_fft_len(m) == m)
        .unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texture(w: usize, h: usize, dx: i64, dy: i64) -> Image {
        Image::from_fn(w, h, |c, r| {
            let (x, y) = (c as i64 - dx, r as i64 - dy);
            let mut s = (x.wrapping_mul(73_856_093) ^ y.wrapping_mul(19_349_663)) as u64;
            s ^= s >> 13;
            s = s.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            (s >> 56) as f32
        })
    }

    #[test]
    fn finds_150_px_in_every_direction() {
        let reference = texture(900, 800, 0, 0);
        for (dx, dy) in [
            (150, 0),
            (-150, 0),
            (0, 150),
            (0, -150),
            (150, -150),
            (-149, 148),
            (3, -2),
        ] {
            let deformed = texture(900, 800, dx, dy);
            let roi = Roi::centred(900, 800, 400, 400);
            assert_eq!(global_offset(&reference, &deformed, roi, 160), (dx, dy));
        }
    }

    #[test]
    fn motion_beyond_max_motion_is_not_reported() {
        let reference = texture(600, 600, 0, 0);
        let deformed = texture(600, 600, 40, -30);
        let roi = Roi::centred(600, 600, 300, 300);
        assert_eq!(global_offset(&reference, &deformed, roi, 64), (40, -30));
        let (dx, dy) = global_offset(&reference, &deformed, roi, 20);
        assert!(dx.abs() <= 20 && dy.abs() <= 20, "{dx}, {dy}");
    }

    #[test]
    fn flat_images_give_zero() {
        let flat = Image::filled(128, 128, 7.0);
        assert_eq!(global_offset(&flat, &flat, flat.bounds(), 32), (0, 0));
    }

    /// The real 2D transform against the complex one of the same frame (its non-negative x
    /// frequencies, transposed), and its inverse back to the frame, at an even and an odd side.
    #[test]
    fn the_real_2d_transform_is_the_complex_ones_half() {
        for l in [24usize, 45] {
            let frame: Vec<f32> = (0..l * l)
                .map(|k| ((k * 7919) % 101) as f32 / 101.0 - 0.5)
                .collect();
            let mut full: Vec<Complex<f32>> = frame.iter().map(|&v| Complex::new(v, 0.0)).collect();
            fft2d(&mut full, l, Direction::Forward);
            let half = real_fft2d(&mut frame.clone(), l);
            let scale = full.iter().map(|z| z.norm()).fold(0.0f32, f32::max);
            for kx in 0..l / 2 + 1 {
                for ky in 0..l {
                    let d = half[kx * l + ky] - full[ky * l + kx];
                    assert!(d.norm() < 1e-5 * scale, "l {l}, ({kx}, {ky})");
                }
            }
            let back = real_ifft2d(&mut half.clone(), l);
            for (b, f) in back.iter().zip(&frame) {
                assert!((b / (l * l) as f32 - f).abs() < 1e-5, "l {l}");
            }
        }
    }

    #[test]
    fn fast_lengths() {
        assert_eq!(fast_fft_len(701), 720);
        assert_eq!(fast_fft_len(64), 64);
    }
}
