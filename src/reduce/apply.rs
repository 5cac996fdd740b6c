//! Applying a scheme: output rows in parallel; each output row sums the active input rows over
//! whole contiguous lines (vectorises), then averages the active columns of every block.

use super::{ReduceError, Scheme};
use crate::image::Image;
use rayon::prelude::*;

/// Reduces an f32 image.
pub fn reduce(image: &Image, scheme: &Scheme) -> Result<Image, ReduceError> {
    reduce_rows(image.data(), image.width(), image.height(), scheme)
}

/// Reduces a raw 16-bit frame (row-major, `width x height`).
pub fn reduce_u16(
    data: &[u16],
    width: usize,
    height: usize,
    scheme: &Scheme,
) -> Result<Image, ReduceError> {
    assert_eq!(
        data.len(),
        width * height,
        "frame buffer does not match its size"
    );
    reduce_rows(data, width, height, scheme)
}

fn reduce_rows<T: Copy + Into<f32> + Sync>(
    data: &[T],
    width: usize,
    height: usize,
    scheme: &Scheme,
) -> Result<Image, ReduceError> {
    let (ow, oh) = scheme.output_size(width, height)?;
    let (sx, sy) = (scheme.x, scheme.y);
    let norm = 1.0 / (sx.active * sy.active) as f32;
    let mut out = vec![0.0f32; ow * oh];
    out.par_chunks_mut(ow).enumerate().for_each_init(
        || vec![0.0f32; width],
        |line, (j, out_row)| {
            line.iter_mut().for_each(|v| *v = 0.0);
            let top = j * sy.block + sy.first;
            for r in top..top + sy.active {
                for (acc, &v) in line.iter_mut().zip(&data[r * width..(r + 1) * width]) {
                    *acc += v.into();
                }
            }
            for (i, o) in out_row.iter_mut().enumerate() {
                let left = i * sx.block + sx.first;
                *o = line[left..left + sx.active].iter().sum::<f32>() * norm;
            }
        },
    );
    Ok(Image::from_vec(ow, oh, out).expect("sized"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: usize, h: usize, v: &[f32]) -> Image {
        Image::from_vec(w, h, v.to_vec()).unwrap()
    }

    // 4x4 input, values written out:
    //  1  2  3  4
    //  5  6  7  8
    //  9 10 11 12
    // 13 14 15 16
    fn four() -> Image {
        img(4, 4, &(1..=16).map(|v| v as f32).collect::<Vec<_>>())
    }

    #[test]
    fn ff100_is_the_2x2_block_mean() {
        let r = reduce(&four(), &Scheme::preset("ff100").unwrap()).unwrap();
        // (1+2+5+6)/4, (3+4+7+8)/4, (9+10+13+14)/4, (11+12+15+16)/4
        assert_eq!(r.data(), &[3.5, 5.5, 11.5, 13.5]);
    }

    #[test]
    fn ff50_averages_rows_and_keeps_even_columns() {
        let r = reduce(&four(), &Scheme::preset("ff50").unwrap()).unwrap();
        // columns 0 and 2; rows (0,1) and (2,3) averaged: (1+5)/2, (3+7)/2, (9+13)/2, (11+15)/2
        assert_eq!(r.data(), &[3.0, 5.0, 11.0, 13.0]);
    }

    #[test]
    fn ff25_keeps_even_rows_and_columns() {
        let r = reduce(&four(), &Scheme::preset("ff25").unwrap()).unwrap();
        assert_eq!(r.data(), &[1.0, 3.0, 9.0, 11.0]);
    }

    #[test]
    fn general_3x3_apertures_and_trailing_pixels() {
        // 7x3 input: 0..20; blocks of 3 columns (column 6 dropped), one block of 3 rows.
        let v: Vec<f32> = (0..21).map(|v| v as f32).collect();
        let a = img(7, 3, &v);
        let one = reduce(&a, &Scheme::from_block("3x3", "1x3", None).unwrap()).unwrap();
        // middle column of each block (1 and 4), rows 0..3 averaged: (1+8+15)/3, (4+11+18)/3
        assert_eq!((one.width(), one.height()), (2, 1));
        assert_eq!(one.data(), &[8.0, 11.0]);
        let two = reduce(&a, &Scheme::from_block("3x3", "2x3", Some("0x0")).unwrap()).unwrap();
        // columns 0,1 and 3,4: (0+1+7+8+14+15)/6, (3+4+10+11+17+18)/6
        assert_eq!(two.data(), &[7.5, 10.5]);
    }

    /// A linear ramp's box average is the ramp at the box centre, so each reduced pixel must equal
    /// the ramp at `to_full(i, j)`; a full-resolution shift s then reappears as s / block.
    #[test]
    fn reduced_pixel_centres_are_where_the_docs_say() {
        let ramp = |x: f64, y: f64| 3.0 + 0.75 * x - 0.5 * y;
        for s in [0.0, 0.3, 0.5, 1.7] {
            let img = Image::from_fn(24, 18, |c, r| ramp(c as f64 - s, r as f64) as f32);
            for scheme in Scheme::presets().into_iter().chain([
                Scheme::from_block("3x3", "1x3", None).unwrap(),
                Scheme::from_block("3x3", "2x1", Some("1x2")).unwrap(),
            ]) {
                let red = reduce(&img, &scheme).unwrap();
                for j in 0..red.height() {
                    for i in 0..red.width() {
                        let (x, y) = scheme.to_full(i as f64, j as f64);
                        let expect = ramp(x - s, y);
                        assert!(
                            (red.get(i, j) as f64 - expect).abs() < 1e-4,
                            "{} at ({i},{j}) shift {s}",
                            scheme.name
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn u16_path_equals_f32_path() {
        let raw: Vec<u16> = (0..48u16).map(|v| v * 1000 + 7).collect();
        let f = img(8, 6, &raw.iter().map(|&v| v as f32).collect::<Vec<_>>());
        for s in Scheme::presets() {
            assert_eq!(reduce_u16(&raw, 8, 6, &s).unwrap(), reduce(&f, &s).unwrap());
        }
    }
}
