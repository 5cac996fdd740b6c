//! Speckle made of dots, rendered by exact integration over rectangular pixel apertures: Gaussian
//! dots here, hard-edged disks in `disk.rs`, each a [`Footprint`] over the pixels it reaches.
//!
//! A dot darkens the background by `depth · exp(-((x-xc)²/2σx² + (y-yc)²/2σy²))`. Its integral over
//! the aperture [c - fx/2, c + fx/2] x [r - fy/2, r + fy/2] of pixel (c, r) separates into two
//! one-dimensional erf differences, so a frame is exact for any sub-pixel position and any fill
//! factor. Circular dots stay circular under rotation and translation; an axis-aligned stretch makes
//! them axis-aligned ellipses, which still separate.

use super::normal::cdf;
use crate::image::Image;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// One dot in image coordinates (px).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianDot {
    pub x_px: f64,
    pub y_px: f64,
    pub sigma_x_px: f64,
    pub sigma_y_px: f64,
    /// Darkening at the dot centre, grey levels.
    pub depth: f64,
}

/// A random speckle layout: dots on a jittered square lattice, reproducible from a seed.
#[derive(Clone, Debug)]
pub struct SpeckleLayout {
    pub dots: Vec<GaussianDot>,
}

impl SpeckleLayout {
    /// Dots of standard deviation `sigma_px` at mean spacing `spacing_px` covering
    /// [x0, x1] x [y0, y1] px, each jittered uniformly within its lattice cell; depths vary by
    /// ±`depth_jitter` (a fraction) around `depth`.
    #[allow(clippy::too_many_arguments)]
    pub fn jittered(
        (x0, y0, x1, y1): (f64, f64, f64, f64),
        spacing_px: f64,
        sigma_px: f64,
        depth: f64,
        depth_jitter: f64,
        seed: u64,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let nx = ((x1 - x0) / spacing_px).ceil() as usize + 1;
        let ny = ((y1 - y0) / spacing_px).ceil() as usize + 1;
        let mut dots = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let x = x0 + (i as f64 + rng.gen::<f64>()) * spacing_px;
                let y = y0 + (j as f64 + rng.gen::<f64>()) * spacing_px;
                let d = depth * (1.0 + depth_jitter * (2.0 * rng.gen::<f64>() - 1.0));
                dots.push(GaussianDot {
                    x_px: x,
                    y_px: y,
                    sigma_x_px: sigma_px,
                    sigma_y_px: sigma_px,
                    depth: d,
                });
            }
        }
        Self { dots }
    }

    /// The same dots under the map (x, y) -> f(x, y), each dot's size scaled per axis by `scale`.
    pub fn mapped(&self, f: impl Fn(f64, f64) -> (f64, f64), scale: (f64, f64)) -> Self {
        Self {
            dots: self
                .dots
                .iter()
                .map(|d| {
                    let (x, y) = f(d.x_px, d.y_px);
                    GaussianDot {
                        x_px: x,
                        y_px: y,
                        sigma_x_px: d.sigma_x_px * scale.0,
                        sigma_y_px: d.sigma_y_px * scale.1,
                        depth: d.depth,
                    }
                })
                .collect(),
        }
    }
}

/// A dot the renderer can integrate over pixel apertures: its centre, how far it reaches, and
/// its contribution to the pixels it reaches as a [`Footprint`].
pub trait Dot: Clone + Send + Sync {
    /// The centre's column coordinate, px.
    fn x_px(&self) -> f64;
    /// The centre's row coordinate, px.
    fn y_px(&self) -> f64;
    /// How far the dot reaches from its centre along x and y, px, with an `aperture`.
    fn reach_px(&self, aperture: (f64, f64)) -> (f64, f64);
    /// The dot's darkening of a `size` image; None where it reaches
    /// no pixel.
    fn footprint(&self, size: (usize, usize), aperture: (f64, f64)) -> Option<Footprint>;
}

/// Renders `background - Σ dots`, each pixel the mean over its aperture of fx x fy px (1 = 100 %
/// linear fill factor) centred on the pixel centre.
pub fn render_dots<D: Dot>(
    width: usize,
    height: usize,
    dots: &[D],
    background: f64,
    aperture: (f64, f64),
) -> Image {
    render_dots_until(width, height, dots, background, aperture, &|| false)
        .expect("never asked to stop")
}

/// [`render_dots`], asking `stop` before each band of rows: `None` once it said so (a frame of
/// a large sensor takes seconds; the job that wants it may have been cancelled).
pub fn render_dots_until<D: Dot>(
    width: usize,
    height: usize,
    dots: &[D],
    background: f64,
    aperture: (f64, f64),
    stop: &(dyn Fn() -> bool + Sync),
) -> Option<Image> {
    const BAND: usize = 32;
    let mut sorted: Vec<D> = dots.to_vec();
    sorted.sort_by(|a, b| a.y_px().total_cmp(&b.y_px()));
    // Each dot's profiles once, not once per band it crosses (a paper-size dot crosses two or
    // three): the erf evaluations were a fifth of a diagnosis round.
    let footprints: Vec<Option<Footprint>> = sorted
        .par_iter()
        .map(|d| d.footprint((width, height), aperture))
        .collect();
    if stop() {
        return None;
    }
    let max_reach_y = sorted
        .iter()
        .map(|d| d.reach_px(aperture).1)
        .fold(0.0, f64::max);
    let mut data = vec![0.0f32; width * height];
    data.par_chunks_mut(BAND * width)
        .enumerate()
        .for_each(|(band, chunk)| {
            if stop() {
                return;
            }
            let r0 = band * BAND;
            let rows = chunk.len() / width;
            let mut acc = vec![0.0f64; rows * width];
            let lo = sorted.partition_point(|d| d.y_px() < r0 as f64 - max_reach_y);
            for (d, f) in sorted[lo..].iter().zip(&footprints[lo..]) {
                if d.y_px() > (r0 + rows) as f64 + max_reach_y {
                    break;
                }
                if let Some(f) = f {
                    f.add_to(&mut acc, width, r0, rows);
                }
            }
            for (o, a) in chunk.iter_mut().zip(&acc) {
                *o = (background - a) as f32;
            }
        });
    if stop() {
        return None;
    }
    Some(Image::from_vec(width, height, data).expect("buffer sized to the image"))
}

impl Dot for GaussianDot {
    fn x_px(&self) -> f64 {
        self.x_px
    }

    fn y_px(&self) -> f64 {
        self.y_px
    }

    /// 5σ (exp(-12.5) ≈ 4e-6 of the depth) plus an aperture.
    fn reach_px(&self, (fx, fy): (f64, f64)) -> (f64, f64) {
        (5.0 * self.sigma_x_px + fx, 5.0 * self.sigma_y_px + fy)
    }

    fn footprint(&self, size: (usize, usize), aperture: (f64, f64)) -> Option<Footprint> {
        let (c_lo, c_hi, r_lo, r_hi) = Footprint::span(self, size, aperture)?;
        let (fx, fy) = aperture;
        let wy = box_gauss_span(r_lo, r_hi, fy, self.y_px, self.sigma_y_px);
        Some(Footprint {
            c_lo,
            r_lo,
            weights: Weights::Separable {
                wx: box_gauss_span(c_lo, c_hi, fx, self.x_px, self.sigma_x_px),
                wy: wy.into_iter().map(|v| v * self.depth).collect(),
            },
        })
    }
}

/// A dot's darkening of the pixels from column `c_lo` and row `r_lo` on, clipped to the image.
pub struct Footprint {
    pub(super) c_lo: usize,
    pub(super) r_lo: usize,
    pub(super) weights: Weights,
}

/// How a [`Footprint`] holds its pixels' darkening.
pub(super) enum Weights {
    /// A product of one profile along the rows and one along the columns: the darkening of pixel
    /// (c, r) is wx[c − c_lo] · wy[r − r_lo] (the depth held in wy). A Gaussian dot.
    Separable { wx: Vec<f64>, wy: Vec<f64> },
    /// Every pixel's darkening, row after row, `columns` per row: a disk ([`super::disk`]), hard
    /// (its coverage of each pixel in closed form) or blurred (a sum of strips).
    Dense { values: Vec<f64>, columns: usize },
}

impl Footprint {
    /// The columns `c_lo..=c_hi` and rows `r_lo..=r_hi` a dot reaches, None outside the image.
    pub(super) fn span<D: Dot>(
        d: &D,
        (width, height): (usize, usize),
        aperture: (f64, f64),
    ) -> Option<(usize, usize, usize, usize)> {
        let (rx, ry) = d.reach_px(aperture);
        let span = |centre: f64, r: f64, size: usize| {
            let lo = (centre - r).floor().max(0.0);
            let hi = (centre + r).ceil().min(size as f64 - 1.0);
            (hi >= lo).then_some((lo as usize, hi as usize))
        };
        let (c_lo, c_hi) = span(d.x_px(), rx, width)?;
        let (r_lo, r_hi) = span(d.y_px(), ry, height)?;
        Some((c_lo, c_hi, r_lo, r_hi))
    }

    /// Adds the darkening to `acc`, the `rows` rows from `r0` of a `width`-wide image.
    fn add_to(&self, acc: &mut [f64], width: usize, r0: usize, rows: usize) {
        let (columns, patch_rows) = match &self.weights {
            Weights::Separable { wx, wy } => (wx.len(), wy.len()),
            Weights::Dense { values, columns } => (*columns, values.len() / columns),
        };
        for r in self.r_lo.max(r0)..(self.r_lo + patch_rows).min(r0 + rows) {
            let row = &mut acc[(r - r0) * width + self.c_lo..][..columns];
            match &self.weights {
                Weights::Separable { wx, wy } => {
                    let a = wy[r - self.r_lo];
                    for (cell, &v) in row.iter_mut().zip(wx) {
                        *cell += a * v;
                    }
                }
                Weights::Dense { values, .. } => {
                    let weights = &values[(r - self.r_lo) * columns..][..columns];
                    for (cell, &v) in row.iter_mut().zip(weights) {
                        *cell += v;
                    }
                }
            }
        }
    }
}

/// [`box_gauss`] of the pixels `lo..=hi`. With a full aperture a pixel's upper edge is the next
/// one's lower edge, so each Φ is evaluated once (the same arguments, the same values).
fn box_gauss_span(lo: usize, hi: usize, a: f64, m: f64, sigma: f64) -> Vec<f64> {
    if a != 1.0 {
        return (lo..=hi)
            .map(|c| box_gauss(c as f64, a, m, sigma))
            .collect();
    }
    let edge = |c: usize| cdf((c as f64 - 0.5 - m) / sigma);
    let mut below = edge(lo);
    (lo..=hi)
        .map(|c| {
            let above = edge(c + 1);
            let v = sigma * SQRT_TAU * (above - below) / a;
            below = above;
            v
        })
        .collect()
}

/// √(2π): ∫ exp(−x²/2σ²) dx = σ√(2π).
const SQRT_TAU: f64 = 2.506_628_274_631_000_7;

/// Mean of exp(-(x-m)²/2σ²) over [c - a/2, c + a/2]: σ√(2π) times the difference of Φ across
/// the aperture, over its width.
fn box_gauss(c: f64, a: f64, m: f64, sigma: f64) -> f64 {
    let hi = (c + 0.5 * a - m) / sigma;
    let lo = (c - 0.5 * a - m) / sigma;
    sigma * SQRT_TAU * (cdf(hi) - cdf(lo)) / a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_gauss_tends_to_the_point_value_for_tiny_apertures() {
        let v = box_gauss(1.0, 1e-4, 0.3, 1.5);
        let point = (-(0.7f64 * 0.7) / (2.0 * 1.5 * 1.5)).exp();
        assert!((v - point).abs() < 1e-6);
    }

    /// The full-aperture span shares each pixel's edges with its neighbours: the same arguments
    /// to Φ, so the same values as one box_gauss per pixel, bit for bit.
    #[test]
    fn a_full_aperture_span_is_box_gauss_per_pixel() {
        for (m, sigma) in [(20.3f64, 2.0f64), (0.49, 0.7), (1234.567, 9.3)] {
            let lo = (m - 6.0 * sigma).floor().max(0.0) as usize;
            let hi = (m + 6.0 * sigma).ceil() as usize;
            for a in [1.0, 0.5, 0.25] {
                let span = box_gauss_span(lo, hi, a, m, sigma);
                for (k, v) in span.iter().enumerate() {
                    assert_eq!(
                        *v,
                        box_gauss((lo + k) as f64, a, m, sigma),
                        "{m} {sigma} {a}"
                    );
                }
            }
        }
    }

    #[test]
    fn dot_integral_is_conserved() {
        // Σ over pixels of a full-aperture rendering = depth · 2πσxσy (the dot's integral).
        let dot = GaussianDot {
            x_px: 20.3,
            y_px: 19.7,
            sigma_x_px: 2.0,
            sigma_y_px: 1.5,
            depth: 100.0,
        };
        let img = render_dots(40, 40, &[dot], 0.0, (1.0, 1.0));
        let total: f64 = img.data().iter().map(|&v| -v as f64).sum();
        let expect = 100.0 * 2.0 * std::f64::consts::PI * 2.0 * 1.5;
        assert!(
            (total - expect).abs() / expect < 1e-5,
            "{total} vs {expect}"
        );
    }

    #[test]
    fn rendering_is_band_independent() {
        let layout = SpeckleLayout::jittered((0.0, 0.0, 70.0, 70.0), 5.0, 1.2, 80.0, 0.2, 3);
        let a = render_dots(70, 70, &layout.dots, 200.0, (1.0, 1.0));
        // A pixel rendered alone equals the same pixel rendered in the full frame.
        let mut sum = 0.0;
        for d in &layout.dots {
            sum += d.depth
                * box_gauss(33.0, 1.0, d.x_px, d.sigma_x_px)
                * box_gauss(40.0, 1.0, d.y_px, d.sigma_y_px);
        }
        assert!((a.get(33, 40) as f64 - (200.0 - sum)).abs() < 1e-3);
    }
}
