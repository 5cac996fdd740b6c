//! The sensor's read-out: shot and read noise and the ADC per output pixel, at full resolution or
//! with the camera's own binning or decimation.
//!
//! Where binning combines pixels decides how much read noise a binned pixel carries (Janesick,
//! *Photon Transfer*, SPIE 2007, §7 and §11): charge binning (CCDs, and CMOS pixels that share a
//! floating diffusion) sums the photo-electrons of the block and reads them once, so the binned
//! pixel carries one read noise; digital binning (most sCMOS, and the synthesised schemes of
//! `src/reduce`) reads every pixel with its own read noise and averages or sums the digitised
//! values, so an average of n pixels carries σ_read/√n per pixel read. Shot noise is the same
//! either way (the electrons are the same). Decimation reads one pixel of every block.

use super::effects::Effects;
use super::normal_draws::NormalDraws;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::image::Image;

/// How the camera combines the sensor pixels of one binning block.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BinnedValue {
    /// The mean of the block (the output keeps the grey scale of one pixel).
    #[default]
    Average,
    /// The sum of the block (saturates at the ADC's full scale sooner).
    Sum,
}

/// Where binning combines the pixels: before or after the read-out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BinningDomain {
    /// Electrons summed on the sensor, read once: one read noise per binned pixel.
    Charge,
    /// Every pixel read and digitised, then combined: one read noise per sensor pixel.
    #[default]
    Digital,
}

/// One read-out mode of the sensor: per axis, `binning` pixels combined and one pixel of every
/// `decimation` kept (the first); an axis does one or the other. The default reads every pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SensorReadout {
    pub binning: (usize, usize),
    pub decimation: (usize, usize),
    pub value: BinnedValue,
    pub domain: BinningDomain,
}

impl Default for SensorReadout {
    fn default() -> Self {
        Self {
            binning: (1, 1),
            decimation: (1, 1),
            value: BinnedValue::Average,
            domain: BinningDomain::Digital,
        }
    }
}

impl SensorReadout {
    pub fn is_full_resolution(&self) -> bool {
        self.binning == (1, 1) && self.decimation == (1, 1)
    }

    /// Sensor pixels per output pixel along x and y.
    pub fn block(&self) -> (usize, usize) {
        (
            self.binning.0.max(1) * self.decimation.0.max(1),
            self.binning.1.max(1) * self.decimation.1.max(1),
        )
    }

    /// The output frame of a `width` x `height` sensor (a partial block at an edge is dropped).
    pub fn output_size(&self, (width, height): (usize, usize)) -> (usize, usize) {
        let (bx, by) = self.block();
        (width / bx, height / by)
    }

    /// Reads out `irradiance` (DN per sensor pixel, row-major, `size`) through `chain`; rows of
    /// the output in parallel, each with its own noise stream seeded by (`seed`, row).
    pub fn read(
        &self,
        irradiance: &[f64],
        size: (usize, usize),
        chain: &SensorChain,
        seed: u64,
    ) -> Image {
        let (ow, oh) = self.output_size(size);
        let (bx, by) = self.block();
        // Sensor pixels of an output pixel along one axis: the whole block when binned, its
        // first pixel when decimated.
        let (ax, ay) = (self.binning.0.max(1), self.binning.1.max(1));
        let mut out = vec![0.0f32; ow * oh];
        out.par_chunks_mut(ow.max(1))
            .enumerate()
            .for_each(|(orow, line)| {
                let mut noise_draws = SensorChain::row_noise(seed, orow);
                let mut block = Vec::with_capacity(ax * ay);
                for (ocol, px) in line.iter_mut().enumerate() {
                    block.clear();
                    for dy in 0..ay {
                        let row = &irradiance[(orow * by + dy) * size.0..][..size.0];
                        block.extend_from_slice(&row[ocol * bx..][..ax]);
                    }
                    *px = chain.read_block(&block, self, &mut noise_draws) as f32;
                }
            });
        Image::from_vec(ow, oh, out).expect("sized")
    }
}

/// The sensor's noise and ADC as the model's effects state them (`sensor_noise`,
/// `quantization`; without them a pixel reads its irradiance exactly).
pub struct SensorChain {
    noise: Option<super::effects::SensorNoise>,
    full_scale: Option<f64>,
}

impl SensorChain {
    pub fn new(effects: &Effects) -> Self {
        Self {
            noise: effects.sensor_noise,
            full_scale: effects.quantization.map(|q| q.max_dn()),
        }
    }

    /// The noise draws of one output row of a frame.
    pub fn row_noise(seed: u64, row: usize) -> NormalDraws<ChaCha8Rng> {
        NormalDraws::new(ChaCha8Rng::seed_from_u64(
            seed ^ (row as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        ))
    }

    /// One pixel of irradiance `dn` read out: shot noise on its electrons (clipped at the full
    /// well), read noise, back to DN (not yet quantised).
    #[inline(always)]
    pub fn read_pixel(&self, dn: f64, noise_draws: &mut NormalDraws<ChaCha8Rng>) -> f64 {
        match self.noise {
            Some(n) => {
                let electrons = (dn * n.gain).clamp(0.0, n.full_well_e);
                self.read_electrons(electrons, n.gain, n.read_noise_e, noise_draws)
            }
            None => dn,
        }
    }

    #[inline(always)]
    fn read_electrons(
        &self,
        electrons: f64,
        gain: f64,
        read_e: f64,
        noise_draws: &mut NormalDraws<ChaCha8Rng>,
    ) -> f64 {
        super::shot_noise::count_plus_read_noise(electrons, read_e, noise_draws) / gain
    }

    /// The ADC: rounds and clips to its range, when the model has one.
    #[inline]
    pub fn quantise(&self, dn: f64) -> f64 {
        match self.full_scale {
            Some(full) => dn.round().clamp(0.0, full),
            None => dn,
        }
    }

    /// One output pixel from the irradiance of the sensor pixels it combines.
    fn read_block(
        &self,
        block: &[f64],
        readout: &SensorReadout,
        noise_draws: &mut NormalDraws<ChaCha8Rng>,
    ) -> f64 {
        let n = block.len() as f64;
        let combine = |sum: f64| match readout.value {
            BinnedValue::Average => sum / n,
            BinnedValue::Sum => sum,
        };
        match (readout.domain, self.noise) {
            (BinningDomain::Charge, Some(noise)) if block.len() > 1 => {
                // Each pixel's well clips on its own; the summed charge is read once.
                let electrons: f64 = block
                    .iter()
                    .map(|&dn| (dn * noise.gain).clamp(0.0, noise.full_well_e))
                    .sum();
                let dn =
                    self.read_electrons(electrons, noise.gain, noise.read_noise_e, noise_draws);
                self.quantise(combine(dn))
            }
            // Without a noise model the charge is summed exactly and digitised once.
            (BinningDomain::Charge, None) => self.quantise(combine(block.iter().sum())),
            (BinningDomain::Charge, Some(_)) | (BinningDomain::Digital, _) => {
                let sum: f64 = block
                    .iter()
                    .map(|&dn| self.quantise(self.read_pixel(dn, noise_draws)))
                    .sum();
                self.quantise(combine(sum))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::{Quantization, SensorNoise};

    fn noisy(read_noise_e: f64) -> Effects {
        Effects {
            sensor_noise: Some(SensorNoise {
                gain: 1.0,
                read_noise_e,
                full_well_e: 1e9,
            }),
            ..Effects::default()
        }
    }

    fn std_of(img: &Image) -> f64 {
        let d = img.data();
        let mean = d.iter().map(|&v| v as f64).sum::<f64>() / d.len() as f64;
        (d.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / (d.len() - 1) as f64).sqrt()
    }

    /// Read noise alone (no signal, so no shot noise): a 2x2 average carries σ/2 when binned
    /// digitally and σ/4 when binned in charge (Janesick 2007); the std of n = 64k output
    /// pixels is known to ±0.3 % (1σ, 1/√(2n)), so the ±1.5 % bounds hold 5σ.
    #[test]
    fn read_noise_per_binned_pixel_follows_the_binning_domain() {
        let (w, h) = (512, 512);
        let dark = vec![0.0; w * h];
        let chain = SensorChain::new(&noisy(8.0));
        let mut readout = SensorReadout {
            binning: (2, 2),
            ..SensorReadout::default()
        };
        let digital = std_of(&readout.read(&dark, (w, h), &chain, 7));
        readout.domain = BinningDomain::Charge;
        let charge = std_of(&readout.read(&dark, (w, h), &chain, 7));
        assert!((digital / 4.0 - 1.0).abs() < 0.015, "digital {digital}");
        assert!((charge / 2.0 - 1.0).abs() < 0.015, "charge {charge}");
        readout.value = BinnedValue::Sum;
        let charge_sum = std_of(&readout.read(&dark, (w, h), &chain, 7));
        assert!(
            (charge_sum / 8.0 - 1.0).abs() < 0.015,
            "charge sum {charge_sum}"
        );
    }

    /// Without noise, binning averages or sums the block and decimation keeps its first pixel,
    /// written out for a 4x2 ramp.
    #[test]
    fn noiseless_binning_and_decimation_combine_the_stated_pixels() {
        let irradiance: Vec<f64> = (0..8).map(f64::from).collect(); // rows [0 1 2 3] [4 5 6 7]
        let chain = SensorChain::new(&Effects::default());
        let bin = SensorReadout {
            binning: (2, 2),
            ..SensorReadout::default()
        };
        assert_eq!(bin.read(&irradiance, (4, 2), &chain, 0).data(), &[2.5, 4.5]);
        let sum = SensorReadout {
            value: BinnedValue::Sum,
            ..bin
        };
        assert_eq!(
            sum.read(&irradiance, (4, 2), &chain, 0).data(),
            &[10.0, 18.0]
        );
        let mixed = SensorReadout {
            binning: (1, 2),
            decimation: (2, 1),
            ..SensorReadout::default()
        };
        assert_eq!(
            mixed.read(&irradiance, (4, 2), &chain, 0).data(),
            &[2.0, 4.0]
        );
        let quantised = Effects {
            quantization: Some(Quantization { bits: 8 }),
            ..Effects::default()
        };
        let big: Vec<f64> = vec![200.0; 8];
        let saturating = sum.read(&big, (4, 2), &SensorChain::new(&quantised), 0);
        assert_eq!(
            saturating.data(),
            &[255.0, 255.0],
            "a sum clips at full scale"
        );
    }
}
