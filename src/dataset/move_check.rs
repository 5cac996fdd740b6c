//! A run's stated stage move against what its frames show: the rigid offset between reference and
//! deformed frame by phase correlation (`dic::global_offset`), trusted only where the matched
//! windows correlate (NCC ≥ [`MIN_NCC`]). A statement off by an order of magnitude — frames moved
//! 0.5 mm, manifest says 0.001 mm — or in direction — the wrong sign, x and y swapped — is
//! refused with the measured figure before any model is fitted to it (a fit would otherwise chase
//! a travel scale of hundreds, or a misalignment of thousands of radians).

use crate::dic::global_offset;
use crate::image::{Image, Roi};

/// The normalised correlation of the matched windows below which the offset is not a
/// measurement (no texture, or a move beyond the search range).
pub const MIN_NCC: f64 = 0.5;
/// A contradiction: measured and stated magnitudes differ by more than this factor (each floored
/// at 1 px, so sub-pixel moves never count) and by more than [`MIN_DIFFERENCE_PX`].
pub const MAX_RATIO: f64 = 10.0;
pub const MIN_DIFFERENCE_PX: f64 = 5.0;
/// The least search range, px.
const SEARCH_PX: usize = 256;
/// The widest search on the frames as read, px: the phase correlation's L x L buffers grow with
/// the square of the reach (L ≈ 384 + 2·reach), and the reach with the *stated* move, which the
/// client chooses. A wider reach is searched on block-averaged copies, so the buffers stay
/// under ≈ 8 MB whatever the manifest says.
const MAX_FULL_RES_REACH_PX: usize = 256;
/// Side of the centred window the offset is measured on.
const WINDOW_PX: usize = 256;

/// What the frames of one run show.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredMove {
    /// Integer offset of the deformed frame's content, px (x, y).
    pub measured_px: (f64, f64),
    /// Normalised correlation of the matched windows at that offset.
    pub ncc: f64,
}

/// A stated move within this fraction of its length (plus [`MIN_DIFFERENCE_PX`]) of the measured
/// one is a stage's travel error, misalignment and landing; beyond it, a sign, an axis or a unit
/// stated wrong (a move stated with the wrong sign differs by twice its length, with x and y
/// swapped by √2 of it).
pub const MAX_VECTOR_ERROR: f64 = 0.25;

/// The stated and the measured move disagree by an order of magnitude, or in direction.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "the frames show a move of {measured_px:.1} px, ({:.1}, {:.1}) px = ({:.4}, {:.4}) mm at {scale_px_per_mm} px/mm; the manifest says ({:.4}, {:.4}) mm = ({:.1}, {:.1}) px: check the run's stage move (its sign, its axes, its units) and the dataset's scale",
    measured_xy_px.0, measured_xy_px.1, measured_xy_px.0 / scale_px_per_mm, measured_xy_px.1 / scale_px_per_mm,
    stated_xy_mm.0, stated_xy_mm.1, stated_xy_mm.0 * scale_px_per_mm, stated_xy_mm.1 * scale_px_per_mm
)]
pub struct MoveContradiction {
    pub measured_px: f64,
    pub measured_mm: f64,
    pub stated_px: f64,
    pub stated_mm: f64,
    pub scale_px_per_mm: f64,
    /// The measured offset, px (x, y).
    pub measured_xy_px: (f64, f64),
    /// The stated move, mm (x, y).
    pub stated_xy_mm: (f64, f64),
}

/// The rigid offset between `reference` and `deformed`, searched up to `max_motion_px`; `None`
/// when the frames differ in size or the match is not trustworthy.
pub fn measure_move(
    reference: &Image,
    deformed: &Image,
    max_motion_px: usize,
) -> Option<MeasuredMove> {
    let (w, h) = (reference.width(), reference.height());
    if (w, h) != (deformed.width(), deformed.height()) || w < 16 || h < 16 {
        return None;
    }
    let side = WINDOW_PX.min(w).min(h);
    let roi = Roi::new((w - side) / 2, (h - side) / 2, side, side);
    let (dx, dy) = global_offset(reference, deformed, roi, max_motion_px);
    // NCC of the reference window and the deformed window at the offset, over their overlap.
    let (mut sa, mut sb, mut saa, mut sbb, mut sab, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for r in roi.y..roi.y + roi.height {
        for c in roi.x..roi.x + roi.width {
            let (c2, r2) = (c as i64 + dx, r as i64 + dy);
            if c2 < 0 || r2 < 0 || c2 >= w as i64 || r2 >= h as i64 {
                continue;
            }
            let a = reference.get(c, r) as f64;
            let b = deformed.get(c2 as usize, r2 as usize) as f64;
            sa += a;
            sb += b;
            saa += a * a;
            sbb += b * b;
            sab += a * b;
            n += 1.0;
        }
    }
    if n < (side * side / 4) as f64 {
        return None;
    }
    let cov = sab - sa * sb / n;
    let var = (saa - sa * sa / n) * (sbb - sb * sb / n);
    let ncc = if var > 0.0 { cov / var.sqrt() } else { 0.0 };
    (ncc >= MIN_NCC).then_some(MeasuredMove {
        measured_px: (dx as f64, dy as f64),
        ncc,
    })
}

/// Checks a stated move (`dx_mm`, `dy_mm` at `scale_px_per_mm`) against the frames. Frames whose
/// offset cannot be measured pass: the check refuses only what it can show is wrong.
pub fn check_stated_move(
    reference: &Image,
    deformed: &Image,
    (dx_mm, dy_mm): (f64, f64),
    scale_px_per_mm: f64,
) -> Result<Option<MeasuredMove>, MoveContradiction> {
    let stated_mm = dx_mm.hypot(dy_mm);
    let stated_px = stated_mm * scale_px_per_mm;
    if !stated_px.is_finite() {
        return Ok(None);
    }
    // Past the stated move, and at least SEARCH_PX whatever it says (a move stated far too small
    // is the common mislabel), within half the frame; the FFT grows with the square of it.
    let half = reference.width().min(reference.height()) / 2;
    let reach = ((3.0 * stated_px).min(1e9).ceil() as usize)
        .max(SEARCH_PX)
        .min(half.max(16));
    let block = reach.div_ceil(MAX_FULL_RES_REACH_PX);
    let measured = if block <= 1 {
        measure_move(reference, deformed, reach)
    } else {
        // Accurate to ±block px, ample for an order-of-magnitude check of a move this large.
        let (a, b) = (block_mean(reference, block), block_mean(deformed, block));
        measure_move(&a, &b, reach / block).map(|m| MeasuredMove {
            measured_px: (
                m.measured_px.0 * block as f64,
                m.measured_px.1 * block as f64,
            ),
            ..m
        })
    };
    let Some(m) = measured else {
        return Ok(None);
    };
    let measured_px = m.measured_px.0.hypot(m.measured_px.1);
    let (hi, lo) = (
        measured_px.max(stated_px).max(1.0),
        measured_px.min(stated_px).max(1.0),
    );
    let stated_xy_px = (dx_mm * scale_px_per_mm, dy_mm * scale_px_per_mm);
    let apart = (m.measured_px.0 - stated_xy_px.0).hypot(m.measured_px.1 - stated_xy_px.1);
    let magnitude = hi / lo > MAX_RATIO && (measured_px - stated_px).abs() > MIN_DIFFERENCE_PX;
    let direction = apart > MIN_DIFFERENCE_PX + MAX_VECTOR_ERROR * stated_px.max(measured_px);
    if magnitude || direction {
        return Err(MoveContradiction {
            measured_px,
            measured_mm: measured_px / scale_px_per_mm,
            stated_px,
            stated_mm,
            scale_px_per_mm,
            measured_xy_px: m.measured_px,
            stated_xy_mm: (dx_mm, dy_mm),
        });
    }
    Ok(Some(m))
}

/// Means of `block` x `block` tiles (the partial tiles at the right and bottom edges dropped).
fn block_mean(image: &Image, block: usize) -> Image {
    let (w, h) = (image.width() / block, image.height() / block);
    let norm = 1.0 / (block * block) as f32;
    Image::from_fn(w.max(1), h.max(1), |c, r| {
        let mut sum = 0.0f32;
        for y in r * block..((r + 1) * block).min(image.height()) {
            sum += image.row(y)[c * block..((c + 1) * block).min(image.width())]
                .iter()
                .sum::<f32>();
        }
        sum * norm
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Smoothed white noise (a hash per pixel, 3x3 box-blurred) and its copy shifted by
    /// whole pixels (dx, dy): no renderer of ours involved.
    fn pair(dx: i64, dy: i64) -> (Image, Image) {
        sized_pair(320, 300, dx, dy)
    }

    fn sized_pair(w: usize, h: usize, dx: i64, dy: i64) -> (Image, Image) {
        let noise = |x: i64, y: i64| {
            let mut z = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            (z >> 40) as f64 / (1u64 << 24) as f64
        };
        let tex = |x: i64, y: i64| {
            let mut s = 0.0;
            for j in -1..=1 {
                for i in -1..=1 {
                    s += noise(x + i, y + j);
                }
            }
            1000.0 + 400.0 * s
        };
        (
            Image::from_fn(w, h, |c, r| tex(c as i64, r as i64) as f32),
            Image::from_fn(w, h, |c, r| tex(c as i64 - dx, r as i64 - dy) as f32),
        )
    }

    #[test]
    fn an_honest_move_passes_and_is_measured() {
        let (a, b) = pair(13, -4);
        let m = check_stated_move(&a, &b, (0.5, -0.154), 26.0)
            .unwrap()
            .expect("measured");
        assert_eq!(m.measured_px, (13.0, -4.0));
        assert!(m.ncc > 0.99);
    }

    #[test]
    fn a_move_stated_far_too_small_or_large_is_refused_with_the_measured_figure() {
        // The reproducer: frames moved 0.5 mm (13 px), the manifest says 0.001 mm.
        let (a, b) = pair(13, 0);
        let e = check_stated_move(&a, &b, (0.001, 0.0), 26.0).unwrap_err();
        assert_eq!(e.measured_px, 13.0);
        assert!(e.to_string().contains("13.0 px"), "{e}");
        // A stated 5 mm (130 px) on frames that did not move.
        let (a, b) = pair(0, 0);
        assert!(check_stated_move(&a, &b, (5.0, 0.0), 26.0).is_err());
    }

    /// Issue 36: a stated move of thousands of px once sized the correlation window from it
    /// (2.3 GB for 3,000 px). Now a large reach is searched on block-averaged copies: a true
    /// 130 px move stated as 0.2 mm is still refused, an honest one still passes, and a 3,000 px
    /// statement on unmoved frames is refused with the small measured figure.
    #[test]
    fn a_large_stated_move_is_measured_on_block_averaged_copies() {
        let (a, b) = sized_pair(1200, 1100, 130, 0);
        let m = check_stated_move(&a, &b, (130.0 / 26.0, 0.0), 26.0)
            .unwrap()
            .expect("measured");
        assert!((m.measured_px.0 - 130.0).abs() <= 2.0, "{m:?}");
        let e = check_stated_move(&a, &b, (0.2, 0.0), 26.0).unwrap_err();
        assert!((e.measured_px - 130.0).abs() <= 2.0, "{e}");
        let (big, same) = sized_pair(1200, 1100, 0, 0);
        let e = check_stated_move(&big, &same, (3000.0 / 26.0, 0.0), 26.0).unwrap_err();
        assert!(e.measured_px < 5.0, "{e}");
    }

    /// Issue 32: a move stated with the wrong sign or with x and y swapped has the right size
    /// and was once absorbed (misalignment −3378.7 rad, travel scale 0.0, landings of 5 mm).
    #[test]
    fn a_move_stated_with_the_wrong_sign_or_axes_is_refused() {
        let (a, b) = pair(40, 3);
        let stated = (40.0 / 26.0, 3.0 / 26.0);
        assert!(check_stated_move(&a, &b, stated, 26.0).is_ok());
        let e = check_stated_move(&a, &b, (-stated.0, stated.1), 26.0).unwrap_err();
        assert_eq!(e.measured_xy_px, (40.0, 3.0));
        assert!(e.to_string().contains("(40.0, 3.0) px"), "{e}");
        assert!(check_stated_move(&a, &b, (stated.1, stated.0), 26.0).is_err());
        // A stage 10 % short with a 2 px landing is a stage, not a mislabel.
        assert!(check_stated_move(&a, &b, (0.9 * stated.0, stated.1 + 2.0 / 26.0), 26.0).is_ok());
    }

    #[test]
    fn block_means_average_whole_tiles() {
        let img = Image::from_fn(5, 4, |c, r| (c + 10 * r) as f32);
        let m = block_mean(&img, 2);
        assert_eq!((m.width(), m.height()), (2, 2));
        assert_eq!(m.get(0, 0), (0.0 + 1.0 + 10.0 + 11.0) / 4.0);
        assert_eq!(m.get(1, 1), (22.0 + 23.0 + 32.0 + 33.0) / 4.0);
    }

    #[test]
    fn small_moves_and_untextured_frames_pass() {
        let (a, b) = pair(1, 0);
        assert!(check_stated_move(&a, &b, (0.0004, 0.0), 26.0).is_ok());
        let flat = Image::from_fn(128, 128, |_, _| 500.0);
        assert_eq!(check_stated_move(&flat, &flat, (5.0, 0.0), 26.0), Ok(None));
    }
}
