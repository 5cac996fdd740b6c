//! Focus per region of one frame, for setting up a camera: the mean gradient energy
//! f_x² + f_y² (central differences) over each cell of a grid that covers the frame — the
//! squared-gradient ("Tenengrad") focus measure (Krotkov, "Focusing", Int. J. Computer Vision
//! 1 (1987) 223; compared with other measures by Pertuz, Puig & Garcia, Pattern Recognition 46
//! (2013) 1415). On one print its value falls as the lens defocuses there: a frame whose cells
//! differ much is focused on one side only (a tilted target or a tilted sensor).
//!
//! Pure numerics: an image in, numbers out.

use super::Image;
use serde::Serialize;

/// The gradient energy of each cell of a `columns` x `rows` grid over a frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FocusMap {
    pub columns: usize,
    pub rows: usize,
    /// Mean f_x² + f_y² over each cell's pixels, DN²/px², row-major from the top left.
    pub energy_dn2_per_px2: Vec<f64>,
}

/// The focus map of `img` over a `columns` x `rows` grid (each at least 1; cells of the
/// interior, a one-pixel border left for the differences; a cell holds its share of the
/// interior, the last ones the remainder).
pub fn focus_map(img: &Image, columns: usize, rows: usize) -> FocusMap {
    let (columns, rows) = (columns.max(1), rows.max(1));
    let (w, h) = (img.width(), img.height());
    let mut sums = vec![(0.0f64, 0usize); columns * rows];
    if w >= 3 && h >= 3 {
        let (iw, ih) = (w - 2, h - 2);
        for r in 1..h - 1 {
            let cell_row = ((r - 1) * rows / ih).min(rows - 1);
            for c in 1..w - 1 {
                let cell_col = ((c - 1) * columns / iw).min(columns - 1);
                let fx = 0.5 * (img.get(c + 1, r) as f64 - img.get(c - 1, r) as f64);
                let fy = 0.5 * (img.get(c, r + 1) as f64 - img.get(c, r - 1) as f64);
                let cell = &mut sums[cell_row * columns + cell_col];
                cell.0 += fx * fx + fy * fy;
                cell.1 += 1;
            }
        }
    }
    FocusMap {
        columns,
        rows,
        energy_dn2_per_px2: sums
            .into_iter()
            .map(|(s, n)| if n > 0 { s / n as f64 } else { 0.0 })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A speckle-like texture: a hash of the pixel (no pattern a grid of cells could alias).
    fn texture(c: usize, r: usize) -> f32 {
        let mut z = (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (r as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 29;
        z = z.wrapping_mul(0x94D0_49BB_1331_11EB);
        1000.0 + (z >> 54) as f32
    }

    /// The right half blurred by a 5x5 box (a defocus there): its cells hold a fraction of the
    /// left half's energy, every left cell about the same; a flat frame has none.
    #[test]
    fn a_blurred_half_has_less_gradient_energy() {
        let (w, h) = (200, 120);
        let sharp = Image::from_fn(w, h, texture);
        let blurred = Image::from_fn(w, h, |c, r| {
            if c < w / 2 || c < 2 || r < 2 || c + 2 >= w || r + 2 >= h {
                return sharp.get(c, r);
            }
            let mut s = 0.0;
            for dr in 0..5 {
                for dc in 0..5 {
                    s += sharp.get(c + dc - 2, r + dr - 2);
                }
            }
            s / 25.0
        });
        let map = focus_map(&blurred, 4, 2);
        assert_eq!(
            (map.columns, map.rows, map.energy_dn2_per_px2.len()),
            (4, 2, 8)
        );
        for row in 0..2 {
            let e = &map.energy_dn2_per_px2[row * 4..row * 4 + 4];
            assert!((e[0] / e[1] - 1.0).abs() < 0.1, "left cells alike: {e:?}");
            assert!(e[3] < 0.2 * e[0], "a blurred cell keeps little: {e:?}");
        }
        let flat = focus_map(&Image::from_fn(50, 40, |_, _| 7.0), 3, 3);
        assert!(flat.energy_dn2_per_px2.iter().all(|&e| e == 0.0));
    }
}
