//! Per-point integer refinement of the initial guess: ZNCC of the reference subset against the
//! deformed image at whole-pixel offsets around a predicted displacement (the classical integer
//! search that precedes sub-pixel registration; Pan, Qian, Xie & Asundi, "Two-dimensional digital
//! image correlation for in-plane displacement and strain measurement: a review", Meas. Sci.
//! Technol. 20 (2009)). Rows are contiguous in memory, so the inner loops vectorise.

use crate::image::Image;

/// The best whole-pixel displacement and its ZNCC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntegerMatch {
    pub u: i64,
    pub v: i64,
    pub zncc: f64,
}

/// Searches offsets `centre ± radius` for the subset of half-width `half` centred at (x0, y0).
/// `f0` is the zero-mean reference subset (row-major, side 2·half+1) and `df` its norm
/// sqrt(Σ f0²). Offsets whose subset leaves the image are skipped; None when all do.
pub fn integer_search(
    f0: &[f32],
    df: f64,
    deformed: &Image,
    (x0, y0): (usize, usize),
    half: usize,
    centre: (i64, i64),
    radius: i64,
) -> Option<IntegerMatch> {
    let side = 2 * half + 1;
    let n = (side * side) as f64;
    let (w, h) = (deformed.width() as i64, deformed.height() as i64);
    let mut best: Option<IntegerMatch> = None;
    for dv in -radius..=radius {
        for du in -radius..=radius {
            let (u, v) = (centre.0 + du, centre.1 + dv);
            let left = x0 as i64 + u - half as i64;
            let top = y0 as i64 + v - half as i64;
            if left < 0 || top < 0 || left + side as i64 > w || top + side as i64 > h {
                continue;
            }
            let (mut sg, mut sgg, mut sfg) = (0.0f64, 0.0f64, 0.0f64);
            for r in 0..side {
                let row = &deformed.row(top as usize + r)[left as usize..left as usize + side];
                let fr = &f0[r * side..(r + 1) * side];
                let (mut a, mut b, mut c) = (0.0f32, 0.0f32, 0.0f32);
                for (&g, &f) in row.iter().zip(fr) {
                    a += g;
                    b += g * g;
                    c += f * g;
                }
                sg += a as f64;
                sgg += b as f64;
                sfg += c as f64;
            }
            let var_g = sgg - sg * sg / n;
            if var_g <= 0.0 {
                continue;
            }
            // Σ f0 (g - gm) = Σ f0 g because Σ f0 = 0.
            let zncc = sfg / (df * var_g.sqrt());
            if best.is_none_or(|b| zncc > b.zncc) {
                best = Some(IntegerMatch { u, v, zncc });
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_an_integer_shift() {
        let tex = |x: i64, y: i64| ((x * 37 + y * 91) % 17) as f32 + ((x * x + 3 * y) % 5) as f32;
        let reference = Image::from_fn(80, 80, |c, r| tex(c as i64, r as i64));
        let deformed = Image::from_fn(80, 80, |c, r| tex(c as i64 - 3, r as i64 + 2));
        let half = 5;
        let side = 2 * half + 1;
        let (x0, y0) = (40usize, 40usize);
        let mut f0: Vec<f32> = (0..side * side)
            .map(|k| reference.get(x0 - half + k % side, y0 - half + k / side))
            .collect();
        let mean = f0.iter().sum::<f32>() / f0.len() as f32;
        f0.iter_mut().for_each(|v| *v -= mean);
        let df = f0.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt();
        let m = integer_search(&f0, df, &deformed, (x0, y0), half, (0, 0), 4).unwrap();
        assert_eq!((m.u, m.v), (3, -2));
        assert!((m.zncc - 1.0).abs() < 1e-5);
    }
}
