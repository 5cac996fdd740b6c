//! A geometric fit as the model writes it: each effect's parameters from its basis terms (a
//! tilt's angles from its slopes at the stated or an assumed working distance, distortion's
//! coefficients and its centre as derived), with their standard errors and notes; increments of
//! a re-estimation added onto the effects a model holds.

use super::basis::GeometricParam;
use super::fit_geometric::GeometricFit;
use super::geometric::{Geometric, GeometricSetting};
use super::results::{GeometricTerms, ImageFit};
use crate::model::effects::{LensDistortion, Rotation, Scale, TargetTilt};
use crate::model::{EffectId, Effects};
use std::collections::BTreeMap;

/// The working distance a tilt's angles are written at when the dataset states none: one
/// translation identifies only tan θ / Z.
pub const ASSUMED_WORKING_DISTANCE_MM: f64 = 1000.0;

/// The largest angle written at an assumed distance (the model renders up to
/// `MAX_TILT_RAD`).
const ASSUMED_MAX_ANGLE_RAD: f64 = 0.3;

/// A re-estimation's increments, as a candidate's note says them.
pub fn re_estimated_note(again: &GeometricFit) -> String {
    format!(
        "re-estimated beside it: {}",
        again
            .params
            .iter()
            .zip(&again.values)
            .zip(&again.stderr)
            .map(|((p, v), se)| {
                let (e, name) = p.effect_and_name();
                format!("{e}.{name} {v:+.3e} ± {se:.1e}")
            })
            .collect::<Vec<_>>()
            .join(", ")
    )
}

/// The coefficient of `d` that basis term `p` multiplies; `p` a distortion term.
fn distortion_term(d: &mut LensDistortion, p: GeometricParam) -> &mut f64 {
    use GeometricParam as P;
    match p {
        P::DistortionK1 => &mut d.k1,
        P::DistortionK2 => &mut d.k2,
        P::DistortionP1 => &mut d.p1,
        P::DistortionP2 => &mut d.p2,
        P::Rotation
        | P::Scale
        | P::TiltSlopeY
        | P::TiltSlopeX
        | P::TravelScale
        | P::Misalignment => unreachable!("{p:?} is not a distortion term"),
    }
}

/// `model` with the increments of a re-estimation added to the effects it holds (first order:
/// each term's field is linear in it, so increments add).
pub fn with_increments(model: &Effects, fit: &GeometricFit, scale_px_per_mm: f64) -> Effects {
    use GeometricParam as P;
    let mut out = model.clone();
    for (&p, &dv) in fit.params.iter().zip(&fit.values) {
        match p {
            P::Rotation => {
                if let Some(r) = out.rotation.as_mut() {
                    r.angle_rad += dv;
                }
            }
            P::Scale => {
                if let Some(s) = out.scale.as_mut() {
                    s.ds += dv;
                }
            }
            P::DistortionK1 | P::DistortionK2 | P::DistortionP1 | P::DistortionP2 => {
                if let Some(d) = out.lens_distortion.as_mut() {
                    *distortion_term(d, p) += dv;
                }
            }
            // The stage's terms belong to the nominal experiment, which every comparison
            // refits: no effect holds them.
            P::TravelScale | P::Misalignment => {}
            P::TiltSlopeY | P::TiltSlopeX => {
                if let Some(t) = out.target_tilt.as_mut() {
                    let (a, b) = t.slopes_per_px(scale_px_per_mm);
                    let (a, b) = if p == P::TiltSlopeY {
                        (a + dv, b)
                    } else {
                        (a, b + dv)
                    };
                    *t = TargetTilt::from_slopes(a, b, t.working_distance_mm, scale_px_per_mm);
                }
            }
        }
    }
    out
}

/// A joint fit of several geometric effects' terms as the model writes them: one [`ImageFit`]
/// per effect whose terms the fit holds (in vocabulary order), each written onto the model the
/// previous one left, so the last one's `effects` holds them all.
pub fn write_joint(
    fit: &GeometricFit,
    setting: &GeometricSetting,
    model: &Effects,
) -> Vec<ImageFit> {
    let mut effects = model.clone();
    let mut out = Vec::new();
    for geometric in Geometric::ALL {
        let part = fit.part(|g| g == geometric);
        if part.params.is_empty() {
            continue;
        }
        let written = write_fit(
            &part,
            setting,
            &effects,
            (geometric.effect(), geometric),
            &[],
        );
        effects = written.effects.clone();
        out.push(written);
    }
    out
}

/// The fitted value of `p` and its error, zero where the fit does not hold it.
fn value_of(fit: &GeometricFit, p: GeometricParam) -> (f64, f64) {
    fit.value(p).unwrap_or((0.0, 0.0))
}

/// A geometric fit as the model writes it.
#[derive(Default)]
struct Written {
    params: BTreeMap<String, f64>,
    stderr: BTreeMap<String, f64>,
    derived: BTreeMap<String, f64>,
    notes: Vec<String>,
}

impl Written {
    fn param(&mut self, name: &str, value: f64, se: f64) {
        self.params.insert(name.into(), value);
        self.stderr.insert(name.into(), se);
    }
}

/// A tilt from its slopes, its angles at the stated (or assumed) working distance.
fn write_tilt(fit: &GeometricFit, setting: &GeometricSetting, out: &mut Written) -> TargetTilt {
    let (a, sa) = value_of(fit, GeometricParam::TiltSlopeY);
    let (b, sb) = value_of(fit, GeometricParam::TiltSlopeX);
    // Without a stated distance, the angles are written at the assumed one, or nearer when the
    // tilt would otherwise exceed what the model renders (the first-order field is the same).
    let largest = a.abs().max(b.abs()) * setting.scale_px_per_mm;
    let z = setting.working_distance_mm.unwrap_or_else(|| {
        let fits = if largest > 0.0 {
            ASSUMED_MAX_ANGLE_RAD.tan() / largest
        } else {
            f64::INFINITY
        };
        ASSUMED_WORKING_DISTANCE_MM.min(fits)
    });
    let tilt = TargetTilt::from_slopes(a, b, z, setting.scale_px_per_mm);
    let k = z * setting.scale_px_per_mm;
    // d atan(u)/du = 1/(1 + u²): the angles' standard errors from the slopes'.
    let se = |slope: f64, se: f64| se * k / (1.0 + (slope * k).powi(2));
    out.param("angle_about_y_rad", tilt.angle_about_y_rad, se(a, sa));
    out.param("angle_about_x_rad", tilt.angle_about_x_rad, se(b, sb));
    out.derived.insert("working_distance_mm".into(), z);
    out.derived.insert(
        "tan_about_y_per_m".into(),
        a * setting.scale_px_per_mm * 1e3,
    );
    out.derived.insert(
        "tan_about_x_per_m".into(),
        b * setting.scale_px_per_mm * 1e3,
    );
    if setting.working_distance_mm.is_none() {
        out.notes.push(format!(
            "the dataset states no working_distance_mm: the angles are those at an assumed {z:.0} mm (a translation identifies tan θ over the distance: tan_about_*_per_m)"
        ));
    }
    tilt
}

/// Brown–Conrady terms as fitted, and the centre p1, p2 stand for.
fn write_distortion(
    fit: &GeometricFit,
    setting: &GeometricSetting,
    out: &mut Written,
) -> LensDistortion {
    use GeometricParam as P;
    let d = LensDistortion {
        k1: value_of(fit, P::DistortionK1).0,
        k2: value_of(fit, P::DistortionK2).0,
        p1: value_of(fit, P::DistortionP1).0,
        p2: value_of(fit, P::DistortionP2).0,
        ..LensDistortion::radial(0.0)
    };
    for ((p, v), se) in fit.params.iter().zip(&fit.values).zip(&fit.stderr) {
        out.param(p.effect_and_name().1, *v, *se);
    }
    let (k1, k1_se) = value_of(fit, P::DistortionK1);
    if fit.params.contains(&P::DistortionP1) && k1.abs() > 2.0 * k1_se {
        // p2 = −k1·cx/r0, p1 = −k1·cy/r0 to first order (`basis`).
        out.derived
            .insert("centre_dx_px".into(), -d.p2 * setting.r0 / k1);
        out.derived
            .insert("centre_dy_px".into(), -d.p1 * setting.r0 / k1);
        out.notes.push("p1, p2 are also what radial distortion about a centre off the image centre gives (centre_dx_px, centre_dy_px): translations cannot tell the two apart".into());
    }
    d
}

/// The fit as the model's effect: parameters in the model's units, their standard errors, what
/// follows from them, and the model with it.
pub fn write_fit(
    fit: &GeometricFit,
    setting: &GeometricSetting,
    model: &Effects,
    (effect, geometric): (EffectId, Geometric),
    left_out: &[String],
) -> ImageFit {
    let mut out = Written {
        notes: left_out.to_vec(),
        ..Written::default()
    };
    let mut effects = model.clone();
    let beyond_null = fit
        .values
        .iter()
        .zip(&fit.stderr)
        .any(|(v, se)| v.abs() > 2.0 * se);
    let (v, se) = (fit.values[0], fit.stderr[0]);
    match geometric {
        Geometric::TargetTilt => effects.target_tilt = Some(write_tilt(fit, setting, &mut out)),
        Geometric::LensDistortion => {
            effects.lens_distortion = Some(write_distortion(fit, setting, &mut out))
        }
        Geometric::Rotation => {
            out.param("angle_rad", v, se);
            effects.rotation = Some(Rotation { angle_rad: v });
        }
        Geometric::Scale => {
            out.param("ds", v, se);
            effects.scale = Some(Scale { ds: v });
        }
    }
    let Written {
        params,
        mut stderr,
        derived,
        notes,
    } = out;
    stderr.retain(|_, se: &mut f64| se.is_finite());
    ImageFit {
        effect: effect.into(),
        params,
        stderr,
        effects,
        k: fit.params.len(),
        beyond_null,
        geometric: GeometricTerms {
            field: fit.params.iter().copied().zip(fit.values.clone()).collect(),
            derived,
            notes,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use GeometricParam as P;

    fn setting(working_distance_mm: Option<f64>) -> GeometricSetting {
        GeometricSetting {
            scale_px_per_mm: 26.0,
            working_distance_mm,
            r0: 1000.0,
            observations: 10_000,
        }
    }

    fn fit(params: &[P], values: &[f64], stderr: &[f64]) -> GeometricFit {
        GeometricFit {
            params: params.to_vec(),
            values: values.to_vec(),
            stderr: stderr.to_vec(),
            chi2_drop: f64::NAN,
        }
    }

    #[test]
    fn a_tilt_is_written_as_angles_at_the_stated_distance() {
        // Slopes a = 2e-7, b = −1e-7 per px at 26 px/mm and 500 mm: tan θ = slope × 13,000 px,
        // and d atan(u)/du = 1/(1 + u²) carries the slopes' errors to the angles.
        let f = fit(
            &[P::TiltSlopeY, P::TiltSlopeX],
            &[2e-7, -1e-7],
            &[1e-8, 2e-8],
        );
        let written = write_fit(
            &f,
            &setting(Some(500.0)),
            &Effects::default(),
            (EffectId::TargetTilt, Geometric::TargetTilt),
            &[],
        );
        let tilt = written.effects.target_tilt.unwrap();
        assert!((tilt.angle_about_y_rad - 2.6e-3f64.atan()).abs() < 1e-15);
        assert!((tilt.angle_about_x_rad - (-1.3e-3f64).atan()).abs() < 1e-15);
        let se_y = written.stderr["angle_about_y_rad"];
        assert!((se_y - 1e-8 * 13_000.0 / (1.0 + 2.6e-3f64.powi(2))).abs() < 1e-18);
        let derived = &written.geometric.derived;
        assert!((derived["tan_about_y_per_m"] - 2e-7 * 26.0 * 1e3).abs() < 1e-15);
        assert_eq!(derived["working_distance_mm"], 500.0);
        assert!(written.beyond_null, "20 and 5 errors from zero");
        assert!(written.geometric.notes.is_empty());
    }

    #[test]
    fn without_a_stated_distance_a_large_tilt_is_written_nearer_and_said_so() {
        // Slope 1e-4 per px would be atan(2.6) = 1.2 rad at the assumed 1,000 mm; the distance
        // is brought in to where the angle is the largest written, 0.3 rad: tan 0.3 / 2.6e-3 mm.
        let f = fit(&[P::TiltSlopeY, P::TiltSlopeX], &[1e-4, 0.0], &[1e-6, 1e-6]);
        let written = write_fit(
            &f,
            &setting(None),
            &Effects::default(),
            (EffectId::TargetTilt, Geometric::TargetTilt),
            &[],
        );
        let tilt = written.effects.target_tilt.unwrap();
        assert!((tilt.angle_about_y_rad - 0.3).abs() < 1e-12);
        assert!((tilt.working_distance_mm - 0.3f64.tan() / 2.6e-3).abs() < 1e-9);
        assert!(written.geometric.notes[0].contains("no working_distance_mm"));
        let small = fit(&[P::TiltSlopeY, P::TiltSlopeX], &[1e-8, 0.0], &[1e-9, 1e-9]);
        let at_assumed = write_fit(
            &small,
            &setting(None),
            &Effects::default(),
            (EffectId::TargetTilt, Geometric::TargetTilt),
            &[],
        );
        assert_eq!(
            at_assumed.effects.target_tilt.unwrap().working_distance_mm,
            ASSUMED_WORKING_DISTANCE_MM
        );
    }

    #[test]
    fn decentring_terms_are_also_written_as_the_centre_they_stand_for() {
        // Radial k1 about a centre (cx, cy) = (60, −45) px shows, to first order, as
        // p2 = −k1·cx/r0 and p1 = −k1·cy/r0 (Brown's model expanded about the image centre).
        let (k1, r0, cx, cy) = (1e-3, 1000.0, 60.0, -45.0);
        let params = [P::DistortionK1, P::DistortionP1, P::DistortionP2];
        let f = fit(
            &params,
            &[k1, -k1 * cy / r0, -k1 * cx / r0],
            &[1e-5, 1e-7, 1e-7],
        );
        let written = write_fit(
            &f,
            &setting(None),
            &Effects::default(),
            (EffectId::LensDistortion, Geometric::LensDistortion),
            &[],
        );
        let derived = &written.geometric.derived;
        assert!((derived["centre_dx_px"] - cx).abs() < 1e-9);
        assert!((derived["centre_dy_px"] - cy).abs() < 1e-9);
        let d = written.effects.lens_distortion.unwrap();
        assert_eq!(
            (d.k1, d.p1, d.p2, d.k2),
            (k1, -k1 * cy / r0, -k1 * cx / r0, 0.0)
        );
        // A k1 within two errors of zero stands for no centre.
        let faint = fit(&params, &[1e-5, 1e-7, 1e-7], &[1e-5, 1e-7, 1e-7]);
        let written = write_fit(
            &faint,
            &setting(None),
            &Effects::default(),
            (EffectId::LensDistortion, Geometric::LensDistortion),
            &[],
        );
        assert!(!written.geometric.derived.contains_key("centre_dx_px"));
    }

    #[test]
    fn increments_add_to_the_effects_the_model_holds_and_to_no_other() {
        let model = Effects {
            rotation: Some(Rotation { angle_rad: 1e-4 }),
            target_tilt: Some(TargetTilt {
                angle_about_y_rad: 0.01,
                angle_about_x_rad: 0.0,
                working_distance_mm: 500.0,
            }),
            ..Effects::default()
        };
        let f = fit(
            &[P::Rotation, P::Scale, P::TiltSlopeY],
            &[2e-5, 3e-5, 1e-7],
            &[1e-6; 3],
        );
        let out = with_increments(&model, &f, 26.0);
        assert!((out.rotation.unwrap().angle_rad - 1.2e-4).abs() < 1e-18);
        assert!(out.scale.is_none(), "a scale the model lacks is not added");
        // The tilt's slope is tan θ / (Z · scale): tan 0.01 / 13,000 + 1e-7 per px.
        let tilt = out.target_tilt.unwrap();
        let expected = (0.01f64.tan() + 1e-7 * 13_000.0).atan();
        assert!((tilt.angle_about_y_rad - expected).abs() < 1e-15);
        assert_eq!(tilt.working_distance_mm, 500.0);
        assert!(re_estimated_note(&f)
            .starts_with("re-estimated beside it: rotation.angle_rad +2.000e-5"));
    }
}
