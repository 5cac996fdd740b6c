//! The model's frames read out with the dataset's noise floor (a model without `sensor_noise`):
//! each sensor pixel gets its own signal-independent noise before the capture mode combines the
//! pixels — digital binning, since the floor measured on the frames cannot tell shot from read
//! noise (see `capture_mode`).

use crate::image::Image;
use crate::model::normal_draws::NormalDraws;
use crate::model::{BinnedValue, SensorReadout};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Reads `irradiance` (a noise-free full-resolution frame, DN) out as `readout` combines the
/// sensor's pixels, each sensor pixel with its own signal-independent noise of σ `sigma_dn`
/// (module doc), then the ADC's rounding to `0..=full_dn`. Output rows in
/// parallel, each with its own noise stream from (`seed`, row).
pub fn read_out_with_floor(
    irradiance: &Image,
    readout: &SensorReadout,
    sigma_dn: f64,
    full_dn: f64,
    seed: u64,
) -> Image {
    let (w, h) = (irradiance.width(), irradiance.height());
    let (ow, oh) = readout.output_size((w, h));
    let (bx, by) = readout.block();
    let (ax, ay) = (readout.binning.0.max(1), readout.binning.1.max(1));
    let n = (ax * ay) as f64;
    let data = irradiance.data();
    let mut out = vec![0.0f32; ow * oh];
    out.par_chunks_mut(ow.max(1))
        .enumerate()
        .for_each(|(orow, line)| {
            let mut noise = NormalDraws::new(ChaCha8Rng::seed_from_u64(
                seed ^ (orow as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ));
            let sigma_dn = sigma_dn.max(0.0);
            for (ocol, px) in line.iter_mut().enumerate() {
                let mut sum = 0.0;
                for dy in 0..ay {
                    let row = &data[(orow * by + dy) * w..][..w];
                    for &v in &row[ocol * bx..][..ax] {
                        sum += v as f64 + sigma_dn * noise.standard();
                    }
                }
                let value = match readout.value {
                    BinnedValue::Average => sum / n,
                    BinnedValue::Sum => sum,
                };
                *px = value.round().clamp(0.0, full_dn) as f32;
            }
        });
    Image::from_vec(ow, oh, out).expect("sized")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Averaging n pixels of independent noise divides its σ by √n; decimation keeps it; the
    /// mean of a flat frame is kept by an average and multiplied by n by a sum.
    #[test]
    fn the_noise_floor_reads_out_as_digital_binning() {
        let flat = Image::from_vec(256, 256, vec![1000.0; 256 * 256]).unwrap();
        let sigma = 8.0;
        let mode = |binning, decimation, value| SensorReadout {
            binning,
            decimation,
            value,
            ..SensorReadout::default()
        };
        for (readout, mean, std) in [
            (
                mode((2, 2), (1, 1), BinnedValue::Average),
                1000.0,
                sigma / 2.0,
            ),
            (mode((1, 1), (2, 2), BinnedValue::Average), 1000.0, sigma),
            (mode((2, 2), (1, 1), BinnedValue::Sum), 4000.0, sigma * 2.0),
        ] {
            let img = read_out_with_floor(&flat, &readout, sigma, 65535.0, 7);
            assert_eq!((img.width(), img.height()), (128, 128));
            let (m, s) = img.mean_std();
            // Standard errors over 16,384 pixels: σ/128 for the mean, σ/181 for the std (plus
            // the rounding's 1/√12 DN in quadrature).
            let s_expected = (std * std + 1.0 / 12.0f64).sqrt();
            assert!(
                (m - mean).abs() < 4.0 * std / 128.0,
                "{readout:?}: mean {m}"
            );
            assert!(
                (s - s_expected).abs() < 4.0 * s_expected / 181.0,
                "{readout:?}: std {s} vs {s_expected}"
            );
        }
    }
}
