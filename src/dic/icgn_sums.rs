//! The one pass over the warped deformed subset that an IC-GN iteration needs.
//!
//! With h = g − c (c: the reference subset's mean, so that no sum cancels badly), f the
//! zero-mean reference subset and J its steepest-descent images, every quantity of the ZNSSD
//! Gauss-Newton step follows from nine sums over the subset:
//!
//! Σh, Σh², Σf·h and Σ J·h (six terms),
//!
//! because the residual r = f − k(h − h̄) is linear in h: Σ J r = Σ J f − k(Σ J h − h̄ Σ J) and
//! Σ r² = 2Δf² − 2k Σ f h for k = Δf/Δg. The interpolation and the accumulation therefore run
//! in a single pass, with no stored warped subset and no dependent reductions (the pass of
//! Pan, Li & Tong, Exp. Mech. 53 (2013), fused).
//!
//! Two kernels compute the same sums: a portable one, and on x86-64 with AVX2 and FMA an
//! eight-lane one (bicubic only) that gathers the 4x4 B-spline taps of eight pixels at once.
//! The choice is made once per process from the CPU, so results do not depend on the number
//! of threads; the two kernels differ only by float rounding (tested).

use super::bspline::{cubic_weights, quintic_weights, BSplineImage};
use super::{Interpolation, Warp};

/// The nine sums of one pass (f64, accumulated row by row from f32 lanes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct WarpedSums {
    /// Σ h.
    pub h: f64,
    /// Σ h².
    pub hh: f64,
    /// Σ f·h.
    pub fh: f64,
    /// Σ J·h in the order of the warp parameters (u, ux, uy, v, vx, vy).
    pub jh: [f64; 6],
}

/// The reference side of a subset as the pass reads it: zero-mean grey values and gradients,
/// row-major, `side` x `side`.
pub(super) struct SubsetArrays<'a> {
    pub f0: &'a [f32],
    pub gx: &'a [f32],
    pub gy: &'a [f32],
    pub half: usize,
    /// Subset centre in the image, px.
    pub centre: (usize, usize),
    /// Subtracted from every interpolated grey value (the reference subset's mean).
    pub shift: f32,
}

/// Whether the eight-lane kernel runs on this CPU (decided once).
pub(super) fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::sync::OnceLock;
        static AVAILABLE: OnceLock<bool> = OnceLock::new();
        *AVAILABLE
            .get_or_init(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// The sums for `warp`, or None when a corner of the warped subset leaves the image (an affine
/// map of a square is a parallelogram, so the corners bound it).
pub(super) fn warped_sums(
    def: &BSplineImage,
    subset: &SubsetArrays,
    warp: &Warp,
) -> Option<WarpedSums> {
    let h = subset.half as f64;
    // Pixel (c, r) covers [c-0.5, c+0.5]: the image spans [-0.5, w-0.5], where the mirror-
    // boundary interpolant is still defined by the edge pixels themselves.
    let (w_max, h_max) = (def.width() as f64 - 0.5, def.height() as f64 - 0.5);
    let (x0, y0) = (subset.centre.0 as f64, subset.centre.1 as f64);
    for (dx, dy) in [(-h, -h), (h, -h), (-h, h), (h, h)] {
        let (lx, ly) = warp.apply(dx, dy);
        let (x, y) = (x0 + lx, y0 + ly);
        if !(x >= -0.5 && y >= -0.5 && x <= w_max && y <= h_max) {
            return None;
        }
    }
    Some(match def.kind() {
        Interpolation::Bspline3 => {
            #[cfg(target_arch = "x86_64")]
            if simd_available() && def.coeffs().len() <= i32::MAX as usize {
                // SAFETY: the CPU has AVX2 and FMA (checked above) and every tap index fits
                // an i32 (checked above); the corner test keeps every tap inside the padding.
                return Some(unsafe { avx2::cubic_sums(def, subset, warp) });
            }
            portable_sums::<4>(def, subset, warp)
        }
        Interpolation::Bspline5 => portable_sums::<6>(def, subset, warp),
    })
}

/// Start (f32, relative to the subset centre) of row `r` and the per-column step.
#[inline(always)]
fn row_start(warp: &Warp, half: usize, r: usize) -> (f32, f32) {
    let h = half as f64;
    // Positions relative to the subset centre keep f32 precision (~1e-5 px) on any image.
    let (lx0, ly0) = warp.apply(-h, r as f64 - h);
    (lx0 as f32, ly0 as f32)
}

/// Adds one row's f32 sums to the totals (the dy moments in f64).
#[inline(always)]
fn add_row(total: &mut WarpedSums, row: [f32; 7], dy: f64) {
    let [h, hh, fh, gxh, gxh_dx, gyh, gyh_dx] = row.map(|v| v as f64);
    total.h += h;
    total.hh += hh;
    total.fh += fh;
    total.jh[0] += gxh;
    total.jh[1] += gxh_dx;
    total.jh[2] += dy * gxh;
    total.jh[3] += gyh;
    total.jh[4] += gyh_dx;
    total.jh[5] += dy * gyh;
}

/// The portable kernel: N = 4 (bicubic) or 6 (biquintic) taps per axis.
fn portable_sums<const N: usize>(
    def: &BSplineImage,
    subset: &SubsetArrays,
    warp: &Warp,
) -> WarpedSums {
    let half = subset.half;
    let side = 2 * half + 1;
    let coeffs = def.coeffs();
    let stride = def.stride();
    let kind = def.kind();
    let (sx, sy) = ((1.0 + warp.ux) as f32, warp.vx as f32);
    let (x0, y0) = (subset.centre.0 as isize, subset.centre.1 as isize);
    let mut total = WarpedSums::default();
    for r in 0..side {
        let (lx0, ly0) = row_start(warp, half, r);
        let range = r * side..(r + 1) * side;
        let (f0, gx, gy) = (
            &subset.f0[range.clone()],
            &subset.gx[range.clone()],
            &subset.gy[range],
        );
        let mut row = [0.0f32; 7];
        for c in 0..side {
            let lx = lx0 + c as f32 * sx;
            let ly = ly0 + c as f32 * sy;
            let (fx, fy) = (floor_i32(lx), floor_i32(ly));
            let (tx, ty) = (lx - fx as f32, ly - fy as f32);
            let base = def.tap_base(x0 + fx as isize, y0 + fy as isize, kind);
            let g = if N == 4 {
                taps4(coeffs, base, stride, &cubic_weights(tx), &cubic_weights(ty))
            } else {
                taps6(
                    coeffs,
                    base,
                    stride,
                    &quintic_weights(tx),
                    &quintic_weights(ty),
                )
            };
            let hv = g - subset.shift;
            let dx = c as f32 - half as f32;
            let (gxh, gyh) = (gx[c] * hv, gy[c] * hv);
            row[0] += hv;
            row[1] += hv * hv;
            row[2] += f0[c] * hv;
            row[3] += gxh;
            row[4] += gxh * dx;
            row[5] += gyh;
            row[6] += gyh * dx;
        }
        add_row(&mut total, row, r as f64 - half as f64);
    }
    total
}

/// floor() as an integer without a libm call (x86-64's baseline has no rounding instruction).
#[inline(always)]
pub(super) fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t - ((x < t as f32) as i32)
}

/// Σ_j wy_j Σ_i wx_i c[j][i] over a 4x4 tap block. Each tap row is 4 contiguous floats, summed
/// column-wise first so the compiler keeps the four rows in one vector register.
#[inline(always)]
fn taps4(c: &[f32], base: usize, stride: usize, wx: &[f32; 4], wy: &[f32; 4]) -> f32 {
    let row = |k: usize| -> [f32; 4] {
        c[base + k * stride..base + k * stride + 4]
            .try_into()
            .expect("4 taps")
    };
    let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
    let mut col = [0.0f32; 4];
    for i in 0..4 {
        col[i] = wy[0] * r0[i] + wy[1] * r1[i] + wy[2] * r2[i] + wy[3] * r3[i];
    }
    (col[0] * wx[0] + col[1] * wx[1]) + (col[2] * wx[2] + col[3] * wx[3])
}

#[inline(always)]
fn taps6(c: &[f32], base: usize, stride: usize, wx: &[f32; 6], wy: &[f32; 6]) -> f32 {
    let mut col = [0.0f32; 6];
    for (j, &wyj) in wy.iter().enumerate() {
        let row = &c[base + j * stride..base + j * stride + 6];
        for i in 0..6 {
            col[i] += wyj * row[i];
        }
    }
    col.iter().zip(wx).map(|(a, b)| a * b).sum()
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! Eight pixels per step: positions, floors and cubic B-spline weights in vector registers,
    //! the sixteen taps of each pixel fetched by sixteen contiguous loads where the pixels sit
    //! on consecutive cells (near a translation: almost always) and by sixteen gathers where
    //! not, the nine sums in lanes.

    use super::{add_row, row_start, SubsetArrays, WarpedSums};
    use crate::dic::bspline::BSplineImage;
    use crate::dic::Warp;
    use std::arch::x86_64::*;

    /// Sums of the eight lanes of `v`, in a fixed order.
    #[inline(always)]
    unsafe fn lane_sum(v: __m256) -> f32 {
        let quad = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
        let pair = _mm_add_ps(quad, _mm_movehl_ps(quad, quad));
        _mm_cvtss_f32(_mm_add_ss(pair, _mm_shuffle_ps(pair, pair, 1)))
    }

    /// The four cubic B-spline weights of fractions `t` (Thévenaz, Blu & Unser 2000), as in
    /// `bspline::cubic_weights`.
    #[inline(always)]
    unsafe fn cubic_weights(t: __m256) -> [__m256; 4] {
        let sixth = _mm256_set1_ps(1.0 / 6.0);
        let half = _mm256_set1_ps(0.5);
        let one = _mm256_set1_ps(1.0);
        let two = _mm256_set1_ps(2.0);
        let w3 = _mm256_mul_ps(_mm256_mul_ps(sixth, t), _mm256_mul_ps(t, t));
        let w0 = _mm256_sub_ps(
            _mm256_fmadd_ps(_mm256_mul_ps(half, t), _mm256_sub_ps(t, one), sixth),
            w3,
        );
        let w2 = _mm256_fnmadd_ps(two, w3, _mm256_add_ps(t, w0));
        let w1 = _mm256_sub_ps(_mm256_sub_ps(_mm256_sub_ps(one, w0), w2), w3);
        [w0, w1, w2, w3]
    }

    /// The interpolated values of eight pixels whose 4x4 taps start at eight consecutive
    /// coefficients from `first`: one unaligned load per tap column.
    ///
    /// # Safety
    /// AVX2 and FMA; every tap inside the coefficients.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn contiguous_taps(
        first: *const f32,
        stride: usize,
        wx: &[__m256; 4],
        wy: &[__m256; 4],
    ) -> __m256 {
        let mut g = _mm256_setzero_ps();
        for (j, wyj) in wy.iter().enumerate() {
            let row = first.add(j * stride);
            let mut v = _mm256_mul_ps(wx[0], _mm256_loadu_ps(row));
            v = _mm256_fmadd_ps(wx[1], _mm256_loadu_ps(row.add(1)), v);
            v = _mm256_fmadd_ps(wx[2], _mm256_loadu_ps(row.add(2)), v);
            v = _mm256_fmadd_ps(wx[3], _mm256_loadu_ps(row.add(3)), v);
            g = _mm256_fmadd_ps(*wyj, v, g);
        }
        g
    }

    /// The interpolated values of eight pixels whose taps start at the coefficient indices
    /// `base`, gathered; lanes outside `read` are not read (and are 0).
    ///
    /// # Safety
    /// AVX2 and FMA; every tap of a read lane inside the coefficients.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn gathered_taps(
        coeffs: *const f32,
        base: __m256i,
        vstride: __m256i,
        read: __m256i,
        wx: &[__m256; 4],
        wy: &[__m256; 4],
    ) -> __m256 {
        let readf = _mm256_castsi256_ps(read);
        let mut g = _mm256_setzero_ps();
        let mut row_idx = base;
        for wyj in wy {
            let mut v = _mm256_setzero_ps();
            for (i, wxi) in wx.iter().enumerate() {
                let idx = _mm256_add_epi32(row_idx, _mm256_set1_epi32(i as i32));
                let taps = _mm256_mask_i32gather_ps::<4>(_mm256_setzero_ps(), coeffs, idx, readf);
                v = _mm256_fmadd_ps(*wxi, taps, v);
            }
            g = _mm256_fmadd_ps(*wyj, v, g);
            row_idx = _mm256_add_epi32(row_idx, vstride);
        }
        g
    }

    /// # Safety
    /// The CPU must support AVX2 and FMA, every tap of the warped subset must lie inside the
    /// padded coefficients (the caller's corner test), and their indices must fit an i32.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn cubic_sums(
        def: &BSplineImage,
        subset: &SubsetArrays,
        warp: &Warp,
    ) -> WarpedSums {
        let half = subset.half;
        let side = 2 * half + 1;
        let coeffs = def.coeffs().as_ptr();
        let stride = def.stride() as i32;
        let first_tap = def.tap_base(0, 0, def.kind()) as i32;
        let (x0, y0) = (subset.centre.0 as i32, subset.centre.1 as i32);
        let (sx, sy) = (
            _mm256_set1_ps((1.0 + warp.ux) as f32),
            _mm256_set1_ps(warp.vx as f32),
        );
        let lanes = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
        let lane_ids = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let shift = _mm256_set1_ps(subset.shift);
        let half_f = _mm256_set1_ps(half as f32);
        let vstride = _mm256_set1_epi32(stride);
        let mut total = WarpedSums::default();
        for r in 0..side {
            let (lx0, ly0) = row_start(warp, half, r);
            let (lx0, ly0) = (_mm256_set1_ps(lx0), _mm256_set1_ps(ly0));
            let row_off = r * side;
            let mut acc = [_mm256_setzero_ps(); 7];
            // Chunks of eight columns; the last one ends at the row's end and overlaps the one
            // before it, its repeated lanes masked out of the sums (a narrow subset, side < 8,
            // has one partial chunk whose missing lanes are never read).
            let mut done = 0usize;
            while done < side {
                let c0 = if side >= 8 { done.min(side - 8) } else { 0 };
                let live = _mm256_and_si256(
                    _mm256_cmpgt_epi32(_mm256_set1_epi32((side - c0) as i32), lane_ids),
                    _mm256_cmpgt_epi32(lane_ids, _mm256_set1_epi32(done as i32 - c0 as i32 - 1)),
                );
                let in_subset = side - c0 >= 8;
                let col = _mm256_add_ps(_mm256_set1_ps(c0 as f32), lanes);
                let lx = _mm256_fmadd_ps(col, sx, lx0);
                let ly = _mm256_fmadd_ps(col, sy, ly0);
                let (fx, fy) = (_mm256_floor_ps(lx), _mm256_floor_ps(ly));
                let (tx, ty) = (_mm256_sub_ps(lx, fx), _mm256_sub_ps(ly, fy));
                let ix = _mm256_add_epi32(_mm256_cvttps_epi32(fx), _mm256_set1_epi32(x0));
                let iy = _mm256_add_epi32(_mm256_cvttps_epi32(fy), _mm256_set1_epi32(y0));
                // tap_base(ix, iy) = tap_base(0, 0) + iy·stride + ix.
                let base = _mm256_add_epi32(
                    _mm256_add_epi32(_mm256_mullo_epi32(iy, vstride), ix),
                    _mm256_set1_epi32(first_tap),
                );
                let wx = cubic_weights(tx);
                let wy = cubic_weights(ty);
                // Near a translation the eight pixels sit on consecutive columns of one row
                // of cells: then the taps of column i of every pixel are eight contiguous
                // coefficients, one unaligned load instead of a gather.
                let base0 = _mm256_broadcastd_epi32(_mm256_castsi256_si128(base));
                let consecutive = in_subset
                    && _mm256_movemask_epi8(_mm256_cmpeq_epi32(
                        base,
                        _mm256_add_epi32(base0, lane_ids),
                    )) == -1;
                let g = if consecutive {
                    let first = coeffs.add(_mm256_cvtsi256_si32(base) as usize);
                    contiguous_taps(first, stride as usize, &wx, &wy)
                } else {
                    // Lanes beyond a narrow subset are never read.
                    let read = if in_subset {
                        _mm256_set1_epi32(-1)
                    } else {
                        _mm256_cmpgt_epi32(_mm256_set1_epi32((side - c0) as i32), lane_ids)
                    };
                    gathered_taps(coeffs, base, vstride, read, &wx, &wy)
                };
                let [f0, gx, gy] = [&subset.f0, &subset.gx, &subset.gy].map(|a| {
                    let at = a.as_ptr().add(row_off + c0);
                    if in_subset {
                        _mm256_loadu_ps(at)
                    } else {
                        _mm256_maskload_ps(at, live)
                    }
                });
                let hv = _mm256_and_ps(_mm256_sub_ps(g, shift), _mm256_castsi256_ps(live));
                let dx = _mm256_sub_ps(col, half_f);
                let gxh = _mm256_mul_ps(gx, hv);
                let gyh = _mm256_mul_ps(gy, hv);
                acc[0] = _mm256_add_ps(acc[0], hv);
                acc[1] = _mm256_fmadd_ps(hv, hv, acc[1]);
                acc[2] = _mm256_fmadd_ps(f0, hv, acc[2]);
                acc[3] = _mm256_add_ps(acc[3], gxh);
                acc[4] = _mm256_fmadd_ps(gxh, dx, acc[4]);
                acc[5] = _mm256_add_ps(acc[5], gyh);
                acc[6] = _mm256_fmadd_ps(gyh, dx, acc[6]);
                done = c0 + 8;
            }
            let row = acc.map(|v| lane_sum(v));
            add_row(&mut total, row, r as f64 - half as f64);
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    fn speckle(w: usize, h: usize) -> Image {
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                100.0
                    + 40.0 * (0.71 * x + 0.13 * y).sin() * (0.37 * y - 0.21 * x).cos()
                    + 25.0 * (1.3 * x).sin() * (0.9 * y + 0.4).sin()
            })
            .collect();
        Image::from_vec(w, h, data).unwrap()
    }

    /// The sums straight from their definition, in f64, sample by sample, and the same sums
    /// of absolute terms (the scale of their rounding).
    fn direct_sums(def: &BSplineImage, s: &SubsetArrays, warp: &Warp) -> (WarpedSums, WarpedSums) {
        let side = 2 * s.half + 1;
        let h = s.half as f64;
        let (mut out, mut abs) = (WarpedSums::default(), WarpedSums::default());
        for r in 0..side {
            for c in 0..side {
                let (dx, dy) = (c as f64 - h, r as f64 - h);
                let (lx, ly) = warp.apply(dx, dy);
                let g = def.sample(s.centre.0 as f64 + lx, s.centre.1 as f64 + ly) as f64;
                let hv = g - s.shift as f64;
                let i = r * side + c;
                let (f, gx, gy) = (s.f0[i] as f64, s.gx[i] as f64, s.gy[i] as f64);
                let j = [gx, gx * dx, gx * dy, gy, gy * dx, gy * dy];
                for (sums, m) in [(&mut out, 1.0), (&mut abs, -1.0)] {
                    // m = −1: absolute values of the same terms.
                    let a = |v: f64| if m < 0.0 { v.abs() } else { v };
                    sums.h += a(hv);
                    sums.hh += hv * hv;
                    sums.fh += a(f * hv);
                    for (o, jk) in sums.jh.iter_mut().zip(j) {
                        *o += a(jk * hv);
                    }
                }
            }
        }
        (out, abs)
    }

    /// Agreement to 1e-5 of the sum of the absolute terms: f32 lanes against f64.
    fn assert_close(a: &WarpedSums, (b, scale): &(WarpedSums, WarpedSums), what: &str) {
        let flat = |s: &WarpedSums| {
            [
                [s.h, s.hh, s.fh],
                [s.jh[0], s.jh[1], s.jh[2]],
                [s.jh[3], s.jh[4], s.jh[5]],
            ]
            .concat()
        };
        for (k, ((x, y), sc)) in flat(a)
            .into_iter()
            .zip(flat(b))
            .zip(flat(scale))
            .enumerate()
        {
            assert!(
                (x - y).abs() <= 1e-5 * sc,
                "{what}: sum {k} differs: {x} vs {y} (scale {sc})"
            );
        }
    }

    #[test]
    fn both_kernels_match_the_definition() {
        let img = speckle(120, 100);
        // 21 px: chunks of eight and an overlapping last one; 5 px: one partial chunk.
        for half in [10, 2] {
            let side = 2 * half + 1;
            let n = side * side;
            // Arbitrary reference arrays: the sums are bilinear in them, any values test the pass.
            let f0: Vec<f32> = (0..n).map(|i| ((i * 37 % 101) as f32) - 50.0).collect();
            let gx: Vec<f32> = (0..n).map(|i| ((i * 53 % 97) as f32) * 0.1 - 4.0).collect();
            let gy: Vec<f32> = (0..n).map(|i| ((i * 29 % 89) as f32) * 0.1 - 4.5).collect();
            let subset = SubsetArrays {
                f0: &f0,
                gx: &gx,
                gy: &gy,
                half,
                centre: (60, 50),
                shift: 100.0,
            };
            let warps = [
                Warp::translation(0.0, 0.0),
                Warp::translation(3.37, -2.81),
                Warp::from_array([1.25, 0.04, -0.08, -0.6, 0.07, -0.03]),
                Warp::from_array([-7.9, -0.1, 0.17, 4.4, -0.17, 0.1]),
            ];
            for kind in [Interpolation::Bspline3, Interpolation::Bspline5] {
                let def = BSplineImage::new(&img, kind);
                for warp in &warps {
                    let direct = direct_sums(&def, &subset, warp);
                    let portable = match kind {
                        Interpolation::Bspline3 => portable_sums::<4>(&def, &subset, warp),
                        Interpolation::Bspline5 => portable_sums::<6>(&def, &subset, warp),
                    };
                    assert_close(&portable, &direct, "portable");
                    let dispatched = warped_sums(&def, &subset, warp).expect("inside");
                    assert_close(&dispatched, &direct, "dispatched");
                }
            }
        }
        if !simd_available() {
            eprintln!("this CPU has no AVX2+FMA: only the portable kernel was tested");
        }
    }

    #[test]
    fn leaving_the_image_is_reported() {
        let img = speckle(60, 60);
        let def = BSplineImage::new(&img, Interpolation::Bspline3);
        let z = vec![0.0f32; 21 * 21];
        let subset = SubsetArrays {
            f0: &z,
            gx: &z,
            gy: &z,
            half: 10,
            centre: (30, 30),
            shift: 0.0,
        };
        assert!(warped_sums(&def, &subset, &Warp::translation(19.0, 0.0)).is_some());
        assert!(warped_sums(&def, &subset, &Warp::translation(20.0, 0.0)).is_none());
        assert!(warped_sums(&def, &subset, &Warp::translation(0.0, -20.6)).is_none());
    }

    #[test]
    fn floor_matches_std() {
        for x in [-2.5f32, -1.0, -0.3, 0.0, 0.7, 3.0, 12.9999] {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
        }
    }
}
