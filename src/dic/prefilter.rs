//! Gaussian low-pass pre-filtering of both images before correlation, after Pan, "Bias error
//! reduction of digital image correlation using Gaussian pre-filtering", Opt. Eng. 52 (2013).
//! Interpolating a noisy deformed image at fractional positions averages its noise while the
//! reference is sampled at whole pixels; the mismatch biases sub-pixel displacements periodically
//! (zero at whole and half pixels, largest near a quarter). A light Gaussian applied to both images
//! equalises them and also damps the interpolation error of high frequencies.

use super::bspline::mirror;
use crate::image::{Image, ImageView};
use rayon::prelude::*;

/// Separable Gaussian blur with kernel radius ceil(3σ) and mirrored borders; σ ≤ 0 is a copy.
pub fn gaussian_blur<'a>(image: impl Into<ImageView<'a>>, sigma_px: f64) -> Image {
    let image = image.into();
    if !(sigma_px > 0.0) {
        return image.to_image();
    }
    let radius = (3.0 * sigma_px).ceil() as isize;
    let mut kernel: Vec<f64> = (-radius..=radius)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma_px * sigma_px)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= total);
    let kernel: Vec<f32> = kernel.iter().map(|&k| k as f32).collect();
    let (w, h) = (image.width(), image.height());
    let r = radius as usize;
    // Horizontal pass, row-parallel, on a mirror-padded copy of each row.
    let src = image.data();
    let mut tmp = vec![0.0f32; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each_init(
        || vec![0.0f32; w + 2 * r],
        |line, (row, out)| {
            // The row in the middle, the mirror only for the 2r samples beyond its ends.
            let own = &src[row * w..(row + 1) * w];
            line[r..r + w].copy_from_slice(own);
            for i in (0..r).chain(r + w..w + 2 * r) {
                line[i] = own[mirror(i as isize - radius, w)];
            }
            for (c, o) in out.iter_mut().enumerate() {
                *o = kernel
                    .iter()
                    .zip(&line[c..c + 2 * r + 1])
                    .map(|(k, v)| k * v)
                    .sum();
            }
        },
    );
    // Vertical pass: each output row is a weighted sum of whole input rows (vectorises).
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(row, o)| {
        for (k, &kv) in kernel.iter().enumerate() {
            let rr = mirror(row as isize + k as isize - radius, h);
            for (dst, &s) in o.iter_mut().zip(&tmp[rr * w..(rr + 1) * w]) {
                *dst += kv * s;
            }
        }
    });
    Image::from_vec(w, h, out).expect("same shape")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preserves_constants_and_mean_of_a_ramp() {
        let flat = Image::filled(9, 7, 5.0);
        let b = gaussian_blur(&flat, 0.8);
        assert!(b.data().iter().all(|&v| (v - 5.0).abs() < 1e-5));
        let ramp = Image::from_fn(20, 5, |c, _| c as f32);
        let b = gaussian_blur(&ramp, 0.8);
        // A symmetric kernel leaves a linear ramp unchanged away from the border.
        assert!((b.get(10, 2) - 10.0).abs() < 1e-4);
    }
}
