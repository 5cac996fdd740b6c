//! Gaussian low-pass pre-filtering of both images before correlation, after Pan, "Bias error
//! reduction of digital image correlation using Gaussian pre-filtering", Opt. Eng. 52 (2013).
//! Interpolating a noisy deformed image at fractional positions averages its noise while the
//! reference is sampled at whole pixels; the mismatch biases sub-pixel displacements periodically
//! (zero at whole and half pixels, largest near a quarter). A light Gaussian applied to both images
//! equalises them and also damps the interpolation error of high frequencies.

use crate::image::Image;

/// Separable Gaussian blur with kernel radius ceil(3σ) and mirrored borders; σ ≤ 0 is a copy.
pub fn gaussian_blur(image: &Image, sigma_px: f64) -> Image {
    if !(sigma_px > 0.0) {
        return image.clone();
    }
    let radius = (3.0 * sigma_px).ceil() as isize;
    let mut kernel: Vec<f64> = (-radius..=radius)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma_px * sigma_px)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= total);
    let (w, h) = (image.width(), image.height());
    let mirror = |i: isize, n: usize| -> usize {
        let n = n as isize;
        let mut k = i;
        if k < 0 {
            k = -k;
        }
        if k >= n {
            k = 2 * (n - 1) - k;
        }
        k.clamp(0, n - 1) as usize
    };
    let src = image.data();
    let mut tmp = vec![0.0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut acc = 0.0f64;
            for (k, &kv) in kernel.iter().enumerate() {
                let cc = mirror(c as isize + k as isize - radius, w);
                acc += kv * src[r * w + cc] as f64;
            }
            tmp[r * w + c] = acc as f32;
        }
    }
    let mut out = vec![0.0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut acc = 0.0f64;
            for (k, &kv) in kernel.iter().enumerate() {
                let rr = mirror(r as isize + k as isize - radius, h);
                acc += kv * tmp[rr * w + c] as f64;
            }
            out[r * w + c] = acc as f32;
        }
    }
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
