//! Where each run's stage landed, as fitted (`stage::fit_stage`): part of the nominal experiment
//! the model renders.

use crate::model::effects::StageError;
use serde::{Deserialize, Serialize};

/// Where the repeatability that bounds the landing offsets came from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RepeatabilitySource {
    /// The model's `stage_error` effect.
    Model,
    /// The dataset's `stage_repeatability_um`.
    Dataset,
    /// Neither: offsets are free.
    #[default]
    Unstated,
}

/// The fitted landing of every run (indexed as the manifest's runs).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageLanding {
    /// The repeatability (1σ per axis, µm) that bounds the offsets, and its source.
    pub repeatability_um: Option<f64>,
    pub source: RepeatabilitySource,
    /// What the data say each run's stage did beyond travel and misalignment, px (x, y).
    pub landing_px: Vec<[f64; 2]>,
    /// Standard error of each landing (per axis), px.
    pub landing_se_px: Vec<f64>,
    /// The offset the model renders, px: the landing clipped to the envelope.
    pub offsets_px: Vec<[f64; 2]>,
}

impl StageLanding {
    pub fn applied_offset_px(&self, run: usize) -> [f64; 2] {
        self.offsets_px.get(run).copied().unwrap_or([0.0, 0.0])
    }

    /// The envelope half-width per axis, px (infinite when no repeatability is known).
    pub fn envelope_px(&self, scale_px_per_mm: f64) -> f64 {
        self.repeatability_um.map_or(f64::INFINITY, |r| {
            StageError::ENVELOPE_SIGMAS * r * scale_px_per_mm / 1000.0
        })
    }

    /// The repeatability the landings show, 1σ per axis, µm, with its standard error: the RMS of
    /// the landings over 2·runs − 2 degrees of freedom (travel and misalignment took two), the
    /// landings' own measurement noise removed.
    pub fn observed_repeatability_um(&self, scale_px_per_mm: f64) -> Option<(f64, f64)> {
        let n = self.landing_px.len();
        if n < 2 {
            return None;
        }
        let dof = (2 * n - 2) as f64;
        let ss: f64 = self
            .landing_px
            .iter()
            .zip(&self.landing_se_px)
            .map(|(l, se)| l[0] * l[0] + l[1] * l[1] - 2.0 * se * se)
            .sum();
        let sigma_px = (ss / dof).max(0.0).sqrt();
        let to_um = 1000.0 / scale_px_per_mm;
        // A χ² with `dof` degrees of freedom: SE(σ) ≈ σ/√(2·dof), never below the landings' noise.
        let noise = self.landing_se_px.iter().copied().fold(0.0, f64::max);
        let se_px = (sigma_px / (2.0 * dof).sqrt()).max(noise);
        Some((sigma_px * to_um, se_px * to_um))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn the_envelope_is_the_stated_repeatability_in_px() {
        let mut l = StageLanding::default();
        assert_eq!(l.envelope_px(26.0), f64::INFINITY);
        l.repeatability_um = Some(2.0);
        let expected = StageError::ENVELOPE_SIGMAS * 2.0 * 26.0 / 1000.0;
        assert!((l.envelope_px(26.0) - expected).abs() < 1e-12);
        // A run the fit has not placed lands where commanded.
        assert_eq!(l.applied_offset_px(3), [0.0, 0.0]);
    }

    #[test]
    fn landings_from_synthetic_offsets_give_back_the_repeatability() {
        // 400 runs landing N(0, σ) per axis, σ = 1.5 µm at 26 px/mm, each measured with an
        // independent error of 0.0005 px (below the estimate's own sampling error, which is then
        // its standard error): the estimate is within 3 of its standard errors.
        let (sigma_um, scale, noise_px) = (1.5, 26.0, 0.0005);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let land = Normal::new(0.0, sigma_um * scale / 1000.0).unwrap();
        let noise = Normal::new(0.0, noise_px).unwrap();
        let n = 400;
        let l = StageLanding {
            landing_px: (0..n)
                .map(|_| [0, 1].map(|_| land.sample(&mut rng) + noise.sample(&mut rng)))
                .collect(),
            landing_se_px: vec![noise_px; n],
            ..StageLanding::default()
        };
        let (est, se) = l.observed_repeatability_um(scale).unwrap();
        assert!(
            (est - sigma_um).abs() < 3.0 * se,
            "{est} ± {se} against {sigma_um}"
        );
        // σ/√(2·dof) with dof = 798.
        assert!((se / est - 1.0 / (2.0 * 798f64).sqrt()).abs() < 1e-9);
        // One run has no degrees of freedom left.
        let one = StageLanding {
            landing_px: vec![[0.1, 0.0]],
            landing_se_px: vec![0.0],
            ..StageLanding::default()
        };
        assert!(one.observed_repeatability_um(scale).is_none());
    }
}
