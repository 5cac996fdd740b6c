//! Image statistics compared beside DIC: effects that leave a zero-normalised DIC criterion nearly
//! untouched (vignetting, an illumination change) or act through the image's spectrum and noise
//! (blur, pixel aperture, photon transfer) show here.
//!
//! - mean-intensity map: 8x8 block means of the whole frame relative to the frame mean;
//! - contrast: std / mean of the centred analysis crop;
//! - noise against mean (photon transfer, EMVA 1288): from a static repeat frame, per pixel
//!   m = (a+b)/2, σ² = (a−b)²/2; without one, Immerkær's Laplacian-difference estimator
//!   (Immerkær, CVIU 64 (1996)) per pixel against the 3x3 local mean — biased by speckle
//!   structure, which the levelled comparison cancels because the model's frames go through the
//!   same estimator; binned in quantiles of the mean;
//! - power spectrum along x (rows) and along y (columns): Hann-windowed periodograms of the crop,
//!   normalised by the mean², averaged, in log-spaced frequency bins; a pixel aperture fx wide
//!   multiplies the x spectrum by sinc²(fx·f) and leaves y alone, a Gaussian PSF multiplies both
//!   by exp(−4π²σ²f²), which is how an anisotropic aperture is told from an isotropic blur.
//!
//! Every number carries a standard error from the scatter of independent groups (row blocks,
//! sub-blocks, pixels), used by the χ² of [`super::bic`].

use crate::image::Image;
use ffdic_fft::{plan_f64, Complex, Direction};
use serde::{Deserialize, Serialize};

/// Side of the centred crop the spectra and noise are computed on.
pub const STATS_CROP_PX: usize = 512;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeanMap {
    pub nx: usize,
    pub ny: usize,
    /// Block centres, px.
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// Block mean / frame mean, row-major.
    pub values: Vec<f64>,
    pub se: Vec<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PtcPoint {
    pub mean_dn: f64,
    pub variance_dn2: f64,
    pub se: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PsdBin {
    /// Bin centre, cycles/px.
    pub f: f64,
    /// Power per unit frequency relative to the mean², 1/(cycles/px).
    pub value: f64,
    pub se: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameStats {
    pub mean_dn: f64,
    pub contrast: f64,
    pub contrast_se: f64,
    pub mean_map: MeanMap,
    pub ptc: Vec<PtcPoint>,
    /// Whether the noise came from a static repeat frame.
    pub ptc_from_repeat: bool,
    pub psd_x: Vec<PsdBin>,
    pub psd_y: Vec<PsdBin>,
    /// A moved frame's light against its reference's on the same part of the print
    /// ([`light_map`]); none for a reference, or where no move was known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_map: Option<MeanMap>,
}

/// Quantile q in [0, 1] (sorts `v`).
pub fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)]
}

/// Crops the centred window of at most `side` px.
pub fn centre_crop(img: &Image, side: usize) -> Image {
    let (x0, y0, w, h) = centred_crop(img.width(), img.height(), side);
    img.crop(crate::image::Roi {
        x: x0,
        y: y0,
        width: w,
        height: h,
    })
}

/// Per-pixel (local mean, noise variance estimate) and the effective pixels per independent
/// estimate.
fn noise_samples(a: &Image, repeat: Option<&Image>) -> (Vec<(f64, f64)>, f64) {
    let (w, h) = (a.width(), a.height());
    let mut out = Vec::with_capacity(w * h);
    match repeat {
        Some(b) => {
            for (x, y) in a.data().iter().zip(b.data()) {
                let (x, y) = (*x as f64, *y as f64);
                out.push(((x + y) / 2.0, (x - y) * (x - y) / 2.0));
            }
            (out, 1.0)
        }
        None => {
            const M: [[f64; 3]; 3] = [[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]];
            for r in 1..h.saturating_sub(1) {
                for c in 1..w.saturating_sub(1) {
                    let (mut n, mut m) = (0.0, 0.0);
                    for (dr, row) in M.iter().enumerate() {
                        for (dc, k) in row.iter().enumerate() {
                            let v = a.get(c + dc - 1, r + dr - 1) as f64;
                            n += k * v;
                            m += v;
                        }
                    }
                    out.push((m / 9.0, n * n / 36.0));
                }
            }
            (out, 9.0)
        }
    }
}

/// Pooled noise variance (DN²) of a crop: mean of the per-pixel estimates; without a repeat,
/// over the flattest quarter of the pixels (least speckle structure leaks into the estimate).
///
/// With a repeat, a pixel clipped in either frame (at 0 DN or at `full_scale_dn`) is left out:
/// a pixel clipped in both differs by nothing and would pull the floor down (control 0 of the
/// independent controls: 2.1 % of its reference's pixels at 0 DN, 389.5 DN² over all pixels
/// against 397.7 over the unclipped, its nine unclipped noise bins at 389–405). The model's
/// readout clips the same way, so a floor from the unclipped pixels reproduces the clipping.
pub fn noise_variance(a: &Image, repeat: Option<&Image>, full_scale_dn: f64) -> f64 {
    let a = centre_crop(a, STATS_CROP_PX);
    let b = repeat.map(|r| centre_crop(r, STATS_CROP_PX));
    if let Some(b) = &b {
        let clipped = |v: f32| v <= 0.0 || f64::from(v) >= full_scale_dn;
        let (sum, n) = a
            .data()
            .iter()
            .zip(b.data())
            .filter(|(x, y)| !clipped(**x) && !clipped(**y))
            .fold((0.0, 0usize), |(s, n), (x, y)| {
                let d = f64::from(*x) - f64::from(*y);
                (s + d * d / 2.0, n + 1)
            });
        return if n == 0 { 0.0 } else { sum / n as f64 };
    }
    let (samples, _) = noise_samples(&a, None);
    if samples.is_empty() {
        return 0.0;
    }
    let mut v: Vec<f64> = samples.iter().map(|s| s.1).collect();
    let q = percentile(&mut v, 0.25);
    let low: Vec<f64> = v.into_iter().filter(|x| *x <= q).collect();
    // The lower quarter of a χ²₁-distributed estimate averages to 0.0334 of its mean.
    let mean_low = low.iter().sum::<f64>() / low.len().max(1) as f64;
    mean_low / 0.0334
}

/// Noise variance against mean in ten quantile bins of the mean.
pub fn ptc(a: &Image, repeat: Option<&Image>) -> Vec<PtcPoint> {
    let (mut samples, per) = noise_samples(a, repeat);
    if samples.len() < 100 {
        return Vec::new();
    }
    // Stable, ordered as `total_cmp`: the same bins as a comparison sort, in a tenth of the
    // time (the sort was 10 % of a 640x540 diagnosis round's CPU).
    radsort::sort_by_key(&mut samples, |s| s.0);
    let bins = 10;
    let n = samples.len();
    // Drop the extreme 1 % on both ends (clipping, overlapping dots).
    let (lo, hi) = (n / 100, n - n / 100);
    let per_bin = (hi - lo) / bins;
    (0..bins)
        .filter_map(|b| {
            let chunk = &samples[lo + b * per_bin..lo + (b + 1) * per_bin];
            if chunk.len() < 10 {
                return None;
            }
            let k = chunk.len() as f64;
            let m = chunk.iter().map(|s| s.0).sum::<f64>() / k;
            let v = chunk.iter().map(|s| s.1).sum::<f64>() / k;
            let sv = (chunk.iter().map(|s| (s.1 - v).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
            Some(PtcPoint {
                mean_dn: m,
                variance_dn2: v,
                se: sv / (k / per).sqrt(),
            })
        })
        .collect()
}

/// Power spectrum along x (rows) or y (columns) of a crop, in log-spaced bins.
pub fn psd(img: &Image, along_x: bool) -> Vec<PsdBin> {
    let (w, h) = (img.width(), img.height());
    let (len, count) = if along_x { (w, h) } else { (h, w) };
    if len < 16 || count < 8 {
        return Vec::new();
    }
    let (mean, _) = img.mean_std();
    let mean2 = (mean * mean).max(1e-12);
    let window: Vec<f64> = (0..len)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / len as f64).cos())
        .collect();
    let wsum2: f64 = window.iter().map(|x| x * x).sum();
    // From this thread's plan cache: a print's calibration takes the spectra of some two
    // hundred crops of one size.
    let fft = plan_f64(len, Direction::Forward);
    let mut scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    let nbins = 12usize;
    let (edges, runs) = frequency_bins(len, nbins);
    let groups = 8usize;
    // sums[group][bin], counts[bin]
    let mut sums = vec![vec![0.0f64; nbins]; groups];
    let mut counts = vec![vec![0usize; nbins]; groups];
    let scale = 1.0 / (wsum2 * mean2);
    // The lines one after the other in memory: rows as they are, columns copied out once.
    let lines: std::borrow::Cow<[f32]> = if along_x {
        img.data().into()
    } else {
        (0..w)
            .flat_map(|c| (0..h).map(move |r| img.data()[r * w + c]))
            .collect::<Vec<f32>>()
            .into()
    };
    // One line's mean-removed, windowed values into the real (`im` false) or imaginary part
    // of `buf`.
    let window_into = |buf: &mut [Complex<f64>], line: usize, im: bool| {
        let values = &lines[line * len..][..len];
        let lm = values.iter().map(|&v| v as f64).sum::<f64>() / len as f64;
        for ((z, &v), wv) in buf.iter_mut().zip(values).zip(&window) {
            let x = (v as f64 - lm) * wv;
            if im {
                z.im = x;
            } else {
                z.re = x;
            }
        }
    };
    // Two real lines per complex transform, one in the real part and one in the imaginary:
    // their spectra separate by conjugate symmetry, A_k = (Z_k + conj Z_{N−k})/2 and
    // B_k = (Z_k − conj Z_{N−k})/2i, so |A_k|² = |Z_k + conj Z_{N−k}|²/4 and likewise for B.
    // Half the transforms of one line each; the spectra were most of this function.
    let mut buf = vec![Complex::new(0.0, 0.0); len];
    for first in (0..count).step_by(2) {
        let second = (first + 1 < count).then_some(first + 1);
        window_into(&mut buf, first, false);
        match second {
            Some(second) => window_into(&mut buf, second, true),
            None => buf.iter_mut().for_each(|z| z.im = 0.0),
        }
        fft.process_with_scratch(&mut buf, &mut scratch);
        // The lines' groups, once per transform (not per frequency).
        let ga = first * groups / count;
        let gb = second.map(|second| second * groups / count);
        // 1 ≤ k ≤ len/2: N − k is within the buffer, no wrap.
        let powers = |k: usize| {
            let (zk, zm) = (buf[k], buf[len - k].conj());
            (0.25 * (zk + zm).norm_sqr(), 0.25 * (zk - zm).norm_sqr())
        };
        add_powers(&mut sums, &mut counts, &runs, powers, (ga, gb), scale);
    }
    group_bins(&sums, &counts, &edges)
}

/// One transform's powers (`powers(k)`: its first and second line's at frequency k) added,
/// times `scale`, to the sums and counts of the lines' groups `ga` and `gb` (no second line:
/// None) per bin, over the bins' runs of frequencies.
fn add_powers(
    sums: &mut [Vec<f64>],
    counts: &mut [Vec<usize>],
    runs: &[(usize, std::ops::Range<usize>)],
    powers: impl Fn(usize) -> (f64, f64) + Copy,
    (ga, gb): (usize, Option<usize>),
    scale: f64,
) {
    // A bin's sum held in a register over its run of frequencies, added to in the order a
    // sum per frequency in memory was (both lines' terms in turn where they share a group):
    // the same sums to the bit, without a store and a load between two additions to one bin
    // (that chain was most of `psd`'s own time).
    for (bin, ks) in runs {
        let (bin, n) = (*bin, ks.len());
        match gb {
            Some(gb) if gb == ga => {
                let mut sum = sums[ga][bin];
                for (power_a, power_b) in ks.clone().map(powers) {
                    sum += power_a * scale;
                    sum += power_b * scale;
                }
                sums[ga][bin] = sum;
                counts[ga][bin] += 2 * n;
            }
            Some(gb) => {
                let (mut sum_a, mut sum_b) = (sums[ga][bin], sums[gb][bin]);
                for (power_a, power_b) in ks.clone().map(powers) {
                    sum_a += power_a * scale;
                    sum_b += power_b * scale;
                }
                (sums[ga][bin], sums[gb][bin]) = (sum_a, sum_b);
                counts[ga][bin] += n;
                counts[gb][bin] += n;
            }
            None => {
                let mut sum = sums[ga][bin];
                for (power_a, _) in ks.clone().map(powers) {
                    sum += power_a * scale;
                }
                sums[ga][bin] = sum;
                counts[ga][bin] += n;
            }
        }
    }
}

/// A spectrum's `nbins` log-spaced bin edges from 2/`len` to 0.5 cycles/px, and the bins as
/// runs of consecutive FFT frequencies k (from 1 to `len`/2, in k's order; a frequency on an
/// edge in the lower bin): the same for every line.
fn frequency_bins(len: usize, nbins: usize) -> (Vec<f64>, Vec<(usize, std::ops::Range<usize>)>) {
    let (fmin, fmax) = (2.0 / len as f64, 0.5);
    let edges: Vec<f64> = (0..=nbins)
        .map(|k| fmin * (fmax / fmin).powf(k as f64 / nbins as f64))
        .collect();
    let mut runs: Vec<(usize, std::ops::Range<usize>)> = Vec::new();
    for k in 1..=len / 2 {
        let f = k as f64 / len as f64;
        if f < fmin || f > fmax {
            continue;
        }
        let Some(bin) = (0..nbins).find(|&b| f >= edges[b] && f <= edges[b + 1]) else {
            continue;
        };
        match runs.last_mut() {
            Some((b, ks)) if *b == bin && ks.end == k => ks.end = k + 1,
            _ => runs.push((bin, k..k + 1)),
        }
    }
    (edges, runs)
}

/// Each bin's mean over the groups of lines that reached it (`sums[group][bin]` over
/// `counts[group][bin]` lines), with the groups' scatter as its standard error; a bin at the
/// geometric centre of `edges[b]..edges[b + 1]`, left out where fewer than two groups reached it.
fn group_bins(sums: &[Vec<f64>], counts: &[Vec<usize>], edges: &[f64]) -> Vec<PsdBin> {
    (0..edges.len() - 1)
        .filter_map(|b| {
            let means: Vec<f64> = sums
                .iter()
                .zip(counts)
                .filter(|(_, n)| n[b] > 0)
                .map(|(s, n)| s[b] / n[b] as f64)
                .collect();
            if means.len() < 2 {
                return None;
            }
            let k = means.len() as f64;
            let m = means.iter().sum::<f64>() / k;
            let sd = (means.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
            Some(PsdBin {
                f: (edges[b] * edges[b + 1]).sqrt(),
                value: m,
                se: sd / k.sqrt(),
            })
        })
        .collect()
}

/// The centres (px) of `blocks` equal blocks over `n_px` pixels.
fn block_centres(n_px: usize, blocks: usize) -> Vec<f64> {
    (0..blocks)
        .map(|i| (i as f64 + 0.5) * n_px as f64 / blocks as f64 - 0.5)
        .collect()
}

/// The mean of `v` and its standard error (0 from fewer than two values).
fn mean_and_se(v: &[f64]) -> (f64, f64) {
    let k = v.len() as f64;
    let m = v.iter().sum::<f64>() / k.max(1.0);
    if v.len() < 2 {
        return (m, 0.0);
    }
    let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
    (m, sd / k.sqrt())
}

impl MeanMap {
    /// An 8×8 map over a `w`×`h` frame: `block` gives each block's value and standard error
    /// from its columns and rows.
    fn over_blocks(
        (w, h): (usize, usize),
        block: impl Fn((usize, usize), (usize, usize)) -> (f64, f64),
    ) -> MeanMap {
        let (nx, ny) = (8usize, 8usize);
        let (mut values, mut se) = (Vec::with_capacity(nx * ny), Vec::with_capacity(nx * ny));
        for j in 0..ny {
            for i in 0..nx {
                let columns = (i * w / nx, (i + 1) * w / nx);
                let rows = (j * h / ny, (j + 1) * h / ny);
                let (v, e) = block(columns, rows);
                values.push(v);
                se.push(e);
            }
        }
        MeanMap {
            nx,
            ny,
            xs: block_centres(w, nx),
            ys: block_centres(h, ny),
            values,
            se,
        }
    }
}

fn mean_map(img: &Image) -> MeanMap {
    let n = img.mean();
    MeanMap::over_blocks((img.width(), img.height()), |(c0, c1), (r0, r1)| {
        // Four sub-blocks give the scatter of the block mean.
        let mut subs = [0.0f64; 4];
        let mut cnt = [0usize; 4];
        let mid = (c0 + c1) / 2;
        for r in r0..r1 {
            let row = img.row(r);
            let sr = usize::from(r >= (r0 + r1) / 2) * 2;
            // Each half-row summed in a register, its pixels in the order a pass over the
            // whole row gave each quarter (the same sums to the bit): a sum picked per pixel
            // was added to in memory, and was 4 % of a paper-size round's CPU.
            for (s, half) in [(sr, &row[c0..mid]), (sr + 1, &row[mid..c1])] {
                let mut sum = subs[s];
                for v in half {
                    sum += *v as f64;
                }
                subs[s] = sum;
                cnt[s] += half.len();
            }
        }
        let means: Vec<f64> = (0..4)
            .filter(|&s| cnt[s] > 0)
            .map(|s| subs[s] / cnt[s] as f64)
            .collect();
        let (m, se) = mean_and_se(&means);
        (m / n, se / n)
    })
}

/// The light of a moved frame against its reference's on the same part of the print: per block
/// of an 8×8 grid over the moved frame, the moved block's mean over the mean of the reference's
/// pixels `shift_px` (the move, rounded to whole px) back, where both frames hold them. The
/// print's texture is the same on both sides and divides out, so what varies over the map is
/// the light that changed between the frames (a lamp that drifted, a shadow) and the noise; a
/// whole-pixel shift leaves at most half a pixel of texture at the blocks' edges. The scatter of
/// the four quarter-blocks' ratios gives each block's standard error; a block the two frames
/// do not share is NaN.
pub fn light_map(reference: &Image, moved: &Image, shift_px: (f64, f64)) -> MeanMap {
    let (w, h) = (moved.width(), moved.height());
    let (sx, sy) = (shift_px.0.round() as i64, shift_px.1.round() as i64);
    // The moved frame's pixels whose reference pixel (c − sx, r − sy) lies in the frame.
    let inside = |c: usize, n: usize, s: i64| {
        let c = c as i64 - s;
        c >= 0 && c < n as i64
    };
    // The columns c whose reference column c − sx lies in the frame.
    let cols_inside =
        (sx.clamp(0, w as i64) as usize)..((w as i64 + sx).clamp(0, w as i64) as usize);
    MeanMap::over_blocks((w, h), |(c0, c1), (r0, r1)| {
        let (mut moved_sum, mut reference_sum) = ([0.0f64; 4], [0.0f64; 4]);
        let mid = (c0 + c1) / 2;
        let halves = [(0, c0..mid), (1, mid..c1)].map(|(side, cols)| {
            (
                side,
                cols.start.max(cols_inside.start)..cols.end.min(cols_inside.end),
            )
        });
        for r in (r0..r1).filter(|&r| inside(r, h, sy)) {
            let (row, source) = (moved.row(r), reference.row((r as i64 - sy) as usize));
            let half = usize::from(r >= (r0 + r1) / 2) * 2;
            // Each quarter's two sums in registers, its pixels in the order a pass over the
            // whole row gave them (the same sums to the bit): a sum picked per pixel was added
            // to in memory.
            for (side, cols) in halves.iter().filter(|(_, cols)| !cols.is_empty()) {
                let q = half + side;
                let (mut m, mut s) = (moved_sum[q], reference_sum[q]);
                let from = (cols.start as i64 - sx) as usize;
                for (&v, &u) in row[cols.clone()].iter().zip(&source[from..]) {
                    m += f64::from(v);
                    s += f64::from(u);
                }
                (moved_sum[q], reference_sum[q]) = (m, s);
            }
        }
        quarter_ratios(&moved_sum, &reference_sum)
    })
}

/// A light-map block's value and its SE: the mean of its quarters' ratios of moved to reference
/// sums (the quarters the reference lit), NaN with fewer than two.
fn quarter_ratios(moved_sum: &[f64; 4], reference_sum: &[f64; 4]) -> (f64, f64) {
    let ratios: Vec<f64> = (0..4)
        .filter(|&q| reference_sum[q] > 0.0)
        .map(|q| moved_sum[q] / reference_sum[q])
        .collect();
    if ratios.len() < 2 {
        (f64::NAN, f64::NAN)
    } else {
        mean_and_se(&ratios)
    }
}

/// One block of a moved frame's light change beyond the model ([`light_change`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightBlock {
    /// The block's centre, px (image coordinates).
    pub x: f64,
    pub y: f64,
    /// The measured light map's value over the model's.
    pub q: f64,
    pub se: f64,
}

/// The light change of a moved frame beyond the model's: per block, the measured
/// [`light_map`] over the model's. Where the model lights the moved frame as the measurement
/// does, q is one constant over the frame within its errors (a uniform change between the
/// frames is the catalogue's `illumination_change`); a lamp that drifted, a shadow, light that
/// changed across the field make it vary. `moved` is (measured, model); empty without both
/// maps or when they differ in size.
pub fn light_change(moved: (&FrameStats, &FrameStats)) -> Vec<LightBlock> {
    let (Some(m), Some(o)) = (&moved.0.light_map, &moved.1.light_map) else {
        return Vec::new();
    };
    if m.nx != o.nx || m.ny != o.ny || m.values.len() != o.values.len() {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(m.values.len());
    for j in 0..m.ny {
        for i in 0..m.nx {
            let k = j * m.nx + i;
            let q = m.values[k] / o.values[k];
            let se = q * (m.se[k] / m.values[k]).hypot(o.se[k] / o.values[k]);
            if q.is_finite() && se > 0.0 {
                out.push(LightBlock {
                    x: m.xs[i],
                    y: m.ys[j],
                    q,
                    se,
                });
            }
        }
    }
    out
}

/// Statistics of one frame: the mean map over `full` (when given, else over the crop), the rest
/// over the centred crop `crop` with its static repeat crop when there is one. The parts side by
/// side: each is serial inside, and outside the candidates' lanes (the measured side, a
/// comparison run alone) one part at a time left a core idle.
pub fn frame_stats(full: Option<&Image>, crop: &Image, repeat_crop: Option<&Image>) -> FrameStats {
    let (mean, std) = crop.mean_std();
    let n_eff = (crop.width() * crop.height()) as f64 / 64.0;
    let ((mean_map, ptc), (psd_x, psd_y)) = rayon::join(
        || rayon::join(|| mean_map(full.unwrap_or(crop)), || ptc(crop, repeat_crop)),
        || rayon::join(|| psd(crop, true), || psd(crop, false)),
    );
    FrameStats {
        mean_dn: full.map_or(mean, |f| f.mean()),
        contrast: std / mean,
        contrast_se: std / mean / (2.0 * n_eff).sqrt(),
        mean_map,
        ptc,
        ptc_from_repeat: repeat_crop.is_some(),
        psd_x,
        psd_y,
        light_map: None,
    }
}

/// [`frame_stats`] of a moved frame with its light map against `reference` ([`light_map`]),
/// the two side by side.
pub fn moved_frame_stats(
    reference: &Image,
    moved: &Image,
    crop: &Image,
    shift_px: (f64, f64),
) -> FrameStats {
    let (light, stats) = rayon::join(
        || light_map(reference, moved, shift_px),
        || frame_stats(Some(moved), crop, None),
    );
    FrameStats {
        light_map: Some(light),
        ..stats
    }
}

/// The centred crop window (x0, y0, w, h) of at most `side` px per axis, with the same centre as
/// the frame (so a crop renders with the frame's optical axis).
pub fn centred_crop(width: usize, height: usize, side: usize) -> (usize, usize, usize, usize) {
    let fit = |n: usize| {
        let c = side.min(n);
        // Same parity as n keeps the centre exactly.
        let c = if (n - c) % 2 == 1 { c - 1 } else { c };
        ((n - c) / 2, c)
    };
    let (x0, w) = fit(width);
    let (y0, h) = fit(height);
    (x0, y0, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The light map's sums per quarter are the ones a pass over every pixel with its own
    /// bounds check gives, to the bit, for shifts inside, outside and beyond the frame.
    #[test]
    fn a_light_maps_quarter_sums_are_a_pass_over_every_pixel() {
        let (w, h) = (203usize, 157usize);
        let pixel = |c: usize, r: usize, k: usize| {
            (1000.0 + 500.0 * ((c * 7 + r * 13 + k) as f32 * 0.41).sin()).round()
        };
        let reference = Image::from_fn(w, h, |c, r| pixel(c, r, 0));
        let moved = Image::from_fn(w, h, |c, r| pixel(c, r, 5));
        for shift in [
            (0.0f64, 0.0f64),
            (13.4, -7.6),
            (-40.0, 22.0),
            (250.0, 3.0),
            (-3.0, -300.0),
        ] {
            let (sx, sy) = (shift.0.round() as i64, shift.1.round() as i64);
            let inside = |c: usize, n: usize, s: i64| (0..n as i64).contains(&(c as i64 - s));
            let expected = MeanMap::over_blocks((w, h), |(c0, c1), (r0, r1)| {
                let (mut m, mut s) = ([0.0f64; 4], [0.0f64; 4]);
                for r in (r0..r1).filter(|&r| inside(r, h, sy)) {
                    for c in (c0..c1).filter(|&c| inside(c, w, sx)) {
                        let q =
                            usize::from(r >= (r0 + r1) / 2) * 2 + usize::from(c >= (c0 + c1) / 2);
                        m[q] += f64::from(moved.get(c, r));
                        s[q] += f64::from(
                            reference.get((c as i64 - sx) as usize, (r as i64 - sy) as usize),
                        );
                    }
                }
                quarter_ratios(&m, &s)
            });
            let got = light_map(&reference, &moved, shift);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got.values), bits(&expected.values), "{shift:?}");
            assert_eq!(bits(&got.se), bits(&expected.se), "{shift:?}");
        }
    }

    /// The moved frame is the reference's texture shifted by (13, −7) px and lit by a ramp of
    /// ±5 % across the frame: the light map gives the ramp at every block's centre, the texture
    /// (contrast 50 %) divided out; without the ramp every block is 1 within 1e-6.
    #[test]
    fn a_light_map_divides_out_the_print_and_keeps_the_light() {
        let (w, h) = (320usize, 240usize);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let texture: Vec<f32> = (0..w * h)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                1000.0 * (1.0 + 0.5 * ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5))
            })
            .collect();
        let reference = Image::from_vec(w, h, texture.clone()).unwrap();
        let (sx, sy) = (13i64, -7i64);
        let ramp = |c: usize| 1.0 + 0.1 * (c as f64 / (w - 1) as f64 - 0.5);
        let shifted = |lit: bool| {
            let data = (0..w * h)
                .map(|k| {
                    let (c, r) = ((k % w) as i64, (k / w) as i64);
                    let (rc, rr) = ((c - sx).rem_euclid(w as i64), (r - sy).rem_euclid(h as i64));
                    let v = texture[rr as usize * w + rc as usize];
                    if lit {
                        (f64::from(v) * ramp(c as usize)) as f32
                    } else {
                        v
                    }
                })
                .collect();
            Image::from_vec(w, h, data).unwrap()
        };
        let flat = light_map(&reference, &shifted(false), (13.2, -6.8));
        assert!(
            flat.values.iter().all(|v| (v - 1.0).abs() < 1e-6),
            "{:?}",
            flat.values
        );
        let lit = light_map(&reference, &shifted(true), (13.2, -6.8));
        for (k, v) in lit.values.iter().enumerate() {
            let expected = ramp(lit.xs[k % 8].round() as usize);
            // The block's mean of a ramp lit texture: its centre's value within the texture's
            // weight on the ramp (under 0.2 %).
            assert!(
                (v - expected).abs() < 2e-3,
                "block {k}: {v} against {expected}"
            );
        }
    }

    proptest::proptest! {
        /// A centred crop keeps the frame's centre exactly and is never larger than asked or
        /// than the frame.
        #[test]
        fn a_centred_crop_keeps_the_centre(w in 1usize..3000, h in 1usize..3000, side in 1usize..1024) {
            let (x0, y0, cw, ch) = centred_crop(w, h, side);
            proptest::prop_assert!(cw <= side.min(w) && ch <= side.min(h));
            proptest::prop_assert_eq!(2 * x0 + cw, w);
            proptest::prop_assert_eq!(2 * y0 + ch, h);
        }
    }

    #[test]
    fn a_percentile_reads_the_sorted_values() {
        let mut v: Vec<f64> = (0..101).rev().map(f64::from).collect();
        assert_eq!(percentile(&mut v, 0.0), 0.0);
        assert_eq!(percentile(&mut v, 0.5), 50.0);
        assert_eq!(percentile(&mut v, 0.995), 100.0);
        assert!(percentile(&mut [], 0.5).is_nan());
    }

    /// Half of the pixels far outside the range (clipped in both frames, at 0 DN or at full
    /// scale), half inside it with a σ of 10 DN: the floor is the unclipped half's 100 DN², not
    /// the 50 of all pixels.
    #[test]
    fn clipped_pixels_do_not_pull_the_noise_floor_down() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = Normal::new(0.0, 10.0).unwrap();
        for (outside, full) in [(-100.0, 65535.0), (1100.0, 1000.0)] {
            let mut frame = || {
                Image::from_fn(256, 256, |c, _| {
                    let truth = if c % 2 == 0 { 500.0 } else { outside };
                    (truth + n.sample(&mut rng) as f32).clamp(0.0, full)
                })
            };
            let (a, b) = (frame(), frame());
            let v = noise_variance(&a, Some(&b), f64::from(full));
            assert!(
                (v / 100.0 - 1.0).abs() < 0.03,
                "{outside} DN clipped at {full}: {v}"
            );
        }
    }

    #[test]
    fn white_noise_has_a_flat_spectrum_and_the_right_variance() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let n = Normal::new(1000.0, 10.0).unwrap();
        let a = Image::from_fn(256, 256, |_, _| n.sample(&mut rng) as f32);
        let b = Image::from_fn(256, 256, |_, _| n.sample(&mut rng) as f32);
        let v = noise_variance(&a, Some(&b), 65535.0);
        assert!((v / 100.0 - 1.0).abs() < 0.03, "{v}");
        let single = noise_variance(&a, None, 65535.0);
        assert!((single / 100.0 - 1.0).abs() < 0.1, "{single}");
        let s = frame_stats(None, &a, Some(&b));
        // White noise: σ²/mean² per unit frequency over 1 cycle/px → 1e-4 everywhere.
        for bin in &s.psd_x {
            assert!((bin.value / 1e-4 - 1.0).abs() < 0.2, "{bin:?}");
        }
        assert!(s
            .ptc
            .iter()
            .all(|p| (p.variance_dn2 / 100.0 - 1.0).abs() < 0.15));
    }

    /// The spectra of two lines from one transform against each line's own discrete Fourier
    /// sum, written out (O(N²), no FFT): an image whose rows and columns differ (a sinusoid
    /// along x, another along y, a ramp, noise), an odd count of lines so one goes alone.
    #[test]
    fn two_lines_per_transform_give_each_line_its_own_spectrum() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (w, h) = (64usize, 45usize);
        let img = Image::from_fn(w, h, |c, r| {
            let (x, y) = (c as f64, r as f64);
            (500.0
                + 40.0 * (0.9 * x).sin()
                + 25.0 * (0.31 * y + 0.2 * x).cos()
                + 0.5 * y
                + rng.gen::<f64>() * 20.0) as f32
        });
        for along_x in [true, false] {
            let (len, count) = if along_x { (w, h) } else { (h, w) };
            let (mean, _) = img.mean_std();
            let window: Vec<f64> = (0..len)
                .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / len as f64).cos())
                .collect();
            let wsum2: f64 = window.iter().map(|x| x * x).sum();
            // Each line's power at each frequency k, directly.
            let power = |line: usize, k: usize| {
                let v: Vec<f64> = (0..len)
                    .map(|i| {
                        let (c, r) = if along_x { (i, line) } else { (line, i) };
                        img.get(c, r) as f64
                    })
                    .collect();
                let lm = v.iter().sum::<f64>() / len as f64;
                let (mut re, mut im) = (0.0, 0.0);
                for (i, (x, wv)) in v.iter().zip(&window).enumerate() {
                    let phase = -2.0 * std::f64::consts::PI * (k * i) as f64 / len as f64;
                    re += (x - lm) * wv * phase.cos();
                    im += (x - lm) * wv * phase.sin();
                }
                (re * re + im * im) / wsum2 / (mean * mean)
            };
            let got = psd(&img, along_x);
            assert!(!got.is_empty());
            let (fmin, fmax) = (2.0 / len as f64, 0.5);
            let nbins = 12;
            let edge = |b: usize| fmin * (fmax / fmin).powf(b as f64 / nbins as f64);
            for bin in &got {
                let b = (0..nbins)
                    .find(|&b| (edge(b) * edge(b + 1)).sqrt() == bin.f)
                    .expect("a bin of the layout");
                // The bin's value: the mean over 8 groups of lines of each group's mean power.
                let mut means = Vec::new();
                for g in 0..8 {
                    let (mut sum, mut n) = (0.0, 0usize);
                    for line in (0..count).filter(|&l| l * 8 / count == g) {
                        for k in 1..=len / 2 {
                            let f = k as f64 / len as f64;
                            if f >= edge(b) && f <= edge(b + 1) && (0..b).all(|p| f > edge(p + 1)) {
                                sum += power(line, k);
                                n += 1;
                            }
                        }
                    }
                    if n > 0 {
                        means.push(sum / n as f64);
                    }
                }
                let expect = means.iter().sum::<f64>() / means.len() as f64;
                assert!(
                    (bin.value - expect).abs() <= 1e-9 * expect.abs(),
                    "along_x {along_x}, f {}: {} vs {expect}",
                    bin.f,
                    bin.value
                );
            }
        }
    }
}
