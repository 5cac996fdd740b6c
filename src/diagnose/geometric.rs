//! The geometric candidates (rotation, scale, lens distortion, target tilt): which basis fields
//! each frees ([`super::basis`]) and how they are fitted (together, or nested: a term joins only
//! when the runs identify it and it pays its price). The fit is
//! [`super::fit_geometric_effect`]; the fitted effect as the model writes it is
//! [`super::write_geometric`].

use super::basis::GeometricParam;
use super::fit_geometric::GeometricFit;
use super::identifiability::Confounded;
use crate::model::{EffectId, Effects};

/// What the geometric fits need beyond the field samples.
pub struct GeometricSetting {
    pub scale_px_per_mm: f64,
    pub working_distance_mm: Option<f64>,
    /// Half diagonal, full-resolution px (distortion's normalising radius).
    pub r0: f64,
    /// Points compared: the BIC's n.
    pub observations: usize,
}

/// How an effect's basis fields are fitted.
pub enum Terms {
    /// All together.
    Joint(&'static [GeometricParam]),
    /// The first group, then each further group when the runs identify it and its Wald χ² pays
    /// the BIC's price.
    Nested(&'static [&'static [GeometricParam]]),
}

/// The geometric effects: those whose signature is a displacement field of known form.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Geometric {
    Rotation,
    Scale,
    LensDistortion,
    TargetTilt,
}

impl Geometric {
    /// Every geometric effect, in vocabulary order.
    pub const ALL: [Geometric; 4] = [
        Geometric::Rotation,
        Geometric::Scale,
        Geometric::LensDistortion,
        Geometric::TargetTilt,
    ];

    /// The catalogue effect it is.
    pub fn effect(self) -> EffectId {
        match self {
            Geometric::Rotation => EffectId::Rotation,
            Geometric::Scale => EffectId::Scale,
            Geometric::LensDistortion => EffectId::LensDistortion,
            Geometric::TargetTilt => EffectId::TargetTilt,
        }
    }

    /// The effect as a geometric one; None for an effect that changes the images rather than
    /// where things are, or that the nominal experiment always fits.
    pub fn of(effect: EffectId) -> Option<Geometric> {
        match effect {
            EffectId::Rotation => Some(Geometric::Rotation),
            EffectId::Scale => Some(Geometric::Scale),
            EffectId::LensDistortion => Some(Geometric::LensDistortion),
            EffectId::TargetTilt => Some(Geometric::TargetTilt),
            EffectId::StageMisalignment
            | EffectId::StageError
            | EffectId::PsfBlur
            | EffectId::FillFactor
            | EffectId::SensorNoise
            | EffectId::FixedPattern
            | EffectId::Quantization
            | EffectId::Vignetting
            | EffectId::IlluminationChange
            | EffectId::MotionBlur => None,
        }
    }

    /// A confounded pair's two sides as geometric effects; None unless both are.
    pub fn pair_of(c: &Confounded) -> Option<[Geometric; 2]> {
        let [a, b] = c
            .effects
            .each_ref()
            .map(|e| e.parse::<EffectId>().ok().and_then(Geometric::of));
        Some([a?, b?])
    }

    /// The basis fields of the effect `model` holds, as a re-estimation frees them: every term
    /// it has a value for (distortion's k1 always). None for a distortion normalised at another
    /// radius than `r0`, whose terms are not the basis's.
    pub fn held_terms(self, model: &Effects, r0: f64) -> Vec<GeometricParam> {
        use GeometricParam as P;
        match self {
            Geometric::Rotation => model.rotation.map(|_| vec![P::Rotation]),
            Geometric::Scale => model.scale.map(|_| vec![P::Scale]),
            Geometric::LensDistortion => model.lens_distortion.and_then(|d| {
                let own_radius = d.norm_radius_px <= 0.0 || (d.norm_radius_px - r0).abs() < 1e-6;
                let centred = d.centre_dx_px == 0.0 && d.centre_dy_px == 0.0;
                (own_radius && centred).then(|| {
                    let mut terms = vec![P::DistortionK1];
                    if d.p1 != 0.0 || d.p2 != 0.0 {
                        terms.extend([P::DistortionP1, P::DistortionP2]);
                    }
                    if d.k2 != 0.0 {
                        terms.push(P::DistortionK2);
                    }
                    terms
                })
            }),
            Geometric::TargetTilt => model
                .target_tilt
                .map(|_| vec![P::TiltSlopeY, P::TiltSlopeX]),
        }
        .unwrap_or_default()
    }

    /// The basis fields it frees, and how they are fitted.
    pub fn terms(self) -> Terms {
        use GeometricParam as P;
        match self {
            Geometric::Rotation => Terms::Joint(&[P::Rotation]),
            Geometric::Scale => Terms::Joint(&[P::Scale]),
            Geometric::LensDistortion => Terms::Nested(&[
                &[P::DistortionK1],
                &[P::DistortionP1, P::DistortionP2],
                &[P::DistortionK2],
            ]),
            Geometric::TargetTilt => Terms::Joint(&[P::TiltSlopeY, P::TiltSlopeX]),
        }
    }
}

impl GeometricFit {
    /// The terms of the effects `keep` selects, with their values and standard errors.
    pub fn part(&self, keep: impl Fn(Geometric) -> bool) -> GeometricFit {
        let own: Vec<usize> = (0..self.params.len())
            .filter(|&i| Geometric::of(self.params[i].effect_and_name().0).is_some_and(&keep))
            .collect();
        GeometricFit {
            params: own.iter().map(|&i| self.params[i]).collect(),
            values: own.iter().map(|&i| self.values[i]).collect(),
            stderr: own.iter().map(|&i| self.stderr[i]).collect(),
            chi2_drop: f64::NAN,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::{LensDistortion, Rotation, TargetTilt};
    use GeometricParam as P;

    #[test]
    fn the_four_geometric_effects_and_no_other() {
        for effect in EffectId::ALL {
            match Geometric::of(effect) {
                Some(g) => assert_eq!(g.effect(), effect),
                None => assert!(!Geometric::ALL.iter().any(|g| g.effect() == effect)),
            }
        }
        assert_eq!(
            EffectId::ALL
                .iter()
                .filter(|e| Geometric::of(**e).is_some())
                .count(),
            4
        );
    }

    #[test]
    fn a_model_frees_the_terms_it_holds_and_only_in_the_basis_own_units() {
        let r0 = 1000.0;
        let with = |d: LensDistortion| Effects {
            lens_distortion: Some(d),
            ..Effects::default()
        };
        let lens = Geometric::LensDistortion;
        assert!(lens.held_terms(&Effects::default(), r0).is_empty());
        assert_eq!(
            lens.held_terms(&with(LensDistortion::radial(1e-3)), r0),
            [P::DistortionK1]
        );
        let decentred = LensDistortion {
            p2: 1e-5,
            k2: 2e-4,
            ..LensDistortion::radial(1e-3)
        };
        assert_eq!(
            lens.held_terms(&with(decentred), r0),
            [
                P::DistortionK1,
                P::DistortionP1,
                P::DistortionP2,
                P::DistortionK2
            ]
        );
        // About a centre of its own, or normalised at another radius, its terms are not the
        // basis's: nothing is re-estimated.
        let off_centre = LensDistortion {
            centre_dx_px: 30.0,
            ..LensDistortion::radial(1e-3)
        };
        assert!(lens.held_terms(&with(off_centre), r0).is_empty());
        let other_radius = LensDistortion {
            norm_radius_px: 800.0,
            ..LensDistortion::radial(1e-3)
        };
        assert!(lens.held_terms(&with(other_radius), r0).is_empty());
        let tilted = Effects {
            target_tilt: Some(TargetTilt {
                angle_about_y_rad: 0.01,
                angle_about_x_rad: 0.0,
                working_distance_mm: 500.0,
            }),
            rotation: Some(Rotation { angle_rad: 1e-4 }),
            ..Effects::default()
        };
        assert_eq!(
            Geometric::TargetTilt.held_terms(&tilted, r0),
            [P::TiltSlopeY, P::TiltSlopeX]
        );
        assert_eq!(Geometric::Rotation.held_terms(&tilted, r0), [P::Rotation]);
        assert!(Geometric::Scale.held_terms(&tilted, r0).is_empty());
    }

    #[test]
    fn a_part_keeps_the_chosen_effects_terms_with_their_values_and_errors() {
        let fit = GeometricFit {
            params: vec![P::Rotation, P::DistortionK1, P::Scale, P::DistortionP1],
            values: vec![1.0, 2.0, 3.0, 4.0],
            stderr: vec![0.1, 0.2, 0.3, 0.4],
            chi2_drop: 9.0,
        };
        let lens = fit.part(|g| g == Geometric::LensDistortion);
        assert_eq!(lens.params, [P::DistortionK1, P::DistortionP1]);
        assert_eq!((lens.values, lens.stderr), (vec![2.0, 4.0], vec![0.2, 0.4]));
        let rest = fit.part(|g| g != Geometric::LensDistortion);
        assert_eq!(rest.params, [P::Rotation, P::Scale]);
        assert_eq!(rest.values, [1.0, 3.0]);
    }
}
