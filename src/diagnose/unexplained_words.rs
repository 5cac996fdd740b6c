//! What a comparison leaves unexplained (`super::unexplained`) in words a user reads: what
//! remains, in which run, how it grows, and which physical effects leave that signature (a hint,
//! never a verdict).

use super::residual_shape::{RunShape, Shape};

/// A strain component counts when it is more than three standard errors from zero.
fn clear(value: f64, se: f64) -> bool {
    value.abs() > 3.0 * se
}

/// The run whose affine part is most significant.
fn strongest(shape: &Shape) -> Option<&RunShape> {
    let score = |r: &RunShape| {
        [r.exx, r.eyy, r.shear, r.rotation]
            .iter()
            .zip(r.se)
            .map(|(v, se)| if se > 0.0 { (v / se).powi(2) } else { 0.0 })
            .sum::<f64>()
    };
    shape
        .runs
        .iter()
        .filter(|r| r.move_px[0].hypot(r.move_px[1]) > 0.0)
        .max_by(|a, b| score(a).total_cmp(&score(b)))
}

/// The affine part of one run in words, with what leaves such a signature.
fn describe(r: &RunShape) -> Option<String> {
    let [se_xx, se_yy, se_shear, se_rot] = r.se;
    let (exx, eyy) = (clear(r.exx, se_xx), clear(r.eyy, se_yy));
    let mut parts = Vec::new();
    if exx || eyy {
        let iso = (r.exx - r.eyy).abs() < 3.0 * se_xx.hypot(se_yy);
        parts.push(if iso {
            format!(
                "an isotropic strain of {:.2e} (a magnification change)",
                0.5 * (r.exx + r.eyy)
            )
        } else {
            format!(
                "an anisotropic strain of {:.2e} in x and {:.2e} in y",
                r.exx, r.eyy
            )
        });
    }
    if clear(r.shear, se_shear) {
        parts.push(format!("a shear of {:.2e}", r.shear));
    }
    if clear(r.rotation, se_rot) {
        parts.push(format!("a rotation of {:.2e} rad", r.rotation));
    }
    if parts.is_empty() {
        return None;
    }
    let mut text = format!(
        "{} remains in run {} (move {:.1}, {:.1} px)",
        parts.join(", "),
        r.run,
        r.move_px[0],
        r.move_px[1]
    );
    if let Some(hint) = hint(r) {
        text += &format!(": {hint}");
    }
    Some(text)
}

/// A run whose field is mostly beyond affine, in words: radial distortion and a target that is
/// not flat both leave such fields, distortion's fixed to the sensor, a bow's moving with the
/// target.
fn quadratic(r: &RunShape) -> Option<String> {
    (r.quadratic_px > 2.0 * r.affine_px && r.quadratic_px > 0.0).then(|| {
        format!(
            "a field beyond affine (quadratic part {:.4} px RMS against an affine part of {:.4} px) remains in run {} (move {:.1}, {:.1} px): radial distortion about another centre, or a target that is not flat, leave such fields",
            r.quadratic_px, r.affine_px, r.run, r.move_px[0], r.move_px[1]
        )
    })
}

/// Which effects leave this signature along the run's move: the ratio of the strain across the
/// move to the strain along it is 1/2 for a tilt about the other axis, 1/3 for decentring
/// distortion (or radial distortion about a centre off the image centre), 1 for a scale change.
fn hint(r: &RunShape) -> Option<String> {
    let along_x = r.move_px[0].abs() >= r.move_px[1].abs();
    let (along, across, se) = if along_x {
        (r.exx, r.eyy, r.se[0])
    } else {
        (r.eyy, r.exx, r.se[1])
    };
    // The ratio is read only when the strain along the move is known to a tenth.
    if !(along.abs() > 10.0 * se) {
        return None;
    }
    let ratio = across / along;
    let axis = if along_x { "vertical" } else { "horizontal" };
    // The nearest signature, when within 0.08 (half the gap between 1/3 and 1/2).
    let signatures = [
        (
            0.5,
            format!("consistent with a target tilted about the image's {axis} axis (target_tilt)"),
        ),
        (
            1.0 / 3.0,
            "consistent with decentring lens distortion or radial distortion about a centre off the image centre (lens_distortion p1, p2)".to_string(),
        ),
        (1.0, "consistent with a magnification change (scale)".to_string()),
    ];
    let Some((_, what)) = signatures
        .into_iter()
        .filter(|(r, _)| (ratio - r).abs() < 0.08)
        .min_by(|a, b| (ratio - a.0).abs().total_cmp(&(ratio - b.0).abs()))
    else {
        return Some(format!(
            "the strain across the move is {ratio:.2} of the strain along it, which no catalogue effect gives (a tilt 0.5, decentring 0.33, scale 1)"
        ));
    };
    Some(format!(
        "the strain across the move is {ratio:.2} of the strain along it, {what}"
    ))
}

/// What the tests found, for the words.
pub struct Finding<'a> {
    pub significant: bool,
    pub false_alarm_rate: f64,
    /// The field test's F and threshold, when two renderings were made, and whether it fired.
    pub field: Option<(f64, f64)>,
    pub field_fired: bool,
    /// The light test's F and threshold, and whether it fired.
    pub light: Option<(f64, f64)>,
    pub light_fired: bool,
    /// The rigid part (RMS over runs), whether it fired, and what a right model stays below, px.
    pub rigid_px: f64,
    pub rigid_fired: bool,
    pub expected_px: f64,
    pub random_error_ratio: Option<f64>,
    pub implausible_stage: &'a [String],
    pub shape: &'a Shape,
}

/// The whole finding in one paragraph.
pub fn summary(f: &Finding) -> String {
    let rate = 100.0 * f.false_alarm_rate;
    let field = f.field.map_or(
        "no second rendering of the model to test its low-order field against".to_string(),
        |(v, t)| {
            format!(
                "its low-order field is {v:.2} times that between two renderings of the model (threshold {t:.2})"
            )
        },
    );
    let rigid = format!(
        "its rigid part {:.5} px against {:.5} px a right model stays below",
        f.rigid_px, f.expected_px
    );
    let mut text = if f.significant {
        format!(
            "Something the model lacks remains ({rate:.0} % false-alarm rate): {field}; {rigid}."
        )
    } else {
        format!(
            "What remains is consistent with noise and the model's own scatter ({rate:.0} % false-alarm rate): {field}; {rigid}."
        )
    };
    if f.field_fired {
        text += &field_words(f.shape);
    }
    if let Some((v, t)) = f.light.filter(|_| f.light_fired) {
        text += &format!(
            " The light changed across the field between the references and their moved frames beyond the model: the change is {v:.1} times that between two renderings of the model (threshold {t:.2}) — a lamp that drifted, a shadow, a reflection; the model's catalogue holds only a uniform change (illumination_change): write it as a user intensity effect."
        );
    }
    if f.rigid_fired {
        if let Some(r) = f
            .shape
            .runs
            .iter()
            .max_by(|a, b| a.rigid_px.total_cmp(&b.rigid_px))
        {
            text += &format!(
                " The largest rigid part is {:.5} px in run {}: a landing beyond the stage's stated envelope, or a sub-pixel bias the model's print does not have.",
                r.rigid_px, r.run
            );
        }
    }
    if let Some(ratio) = f.random_error_ratio.filter(|r| (r - 1.0).abs() > 0.1) {
        text += &format!(
            " The measured random error is {ratio:.2} times the model's: the print (its gradients and contrast under the frames' noise) is not what the model draws."
        );
    }
    if !f.implausible_stage.is_empty() {
        text += &format!(" {}.", capitalise(&f.implausible_stage.join("; ")));
    }
    if !f.shape.image.is_empty() {
        let kinds: Vec<String> = f
            .shape
            .image
            .iter()
            .map(|m| format!("{} (χ²/n {:.1})", m.kind, m.chi2_per_observation))
            .collect();
        text += &format!(
            " Image statistics the model does not match: {}.",
            kinds.join(", ")
        );
    }
    text
}

/// The low-order field's shape in words: the strongest run's, and how it grows.
fn field_words(shape: &Shape) -> String {
    let mut text = String::new();
    if let Some(words) = strongest(shape)
        .and_then(quadratic)
        .or_else(|| strongest(shape).and_then(describe))
    {
        text += &format!(" {}", capitalise(&words));
        text += match shape.grows_with_move {
            Some(true) => "; it grows with the move.",
            Some(false) => "; it does not grow with the move.",
            None => ".",
        };
    }
    let quad = shape
        .runs
        .iter()
        .map(|r| r.quadratic_px)
        .fold(0.0, f64::max);
    if quad > 0.0 {
        text += &format!(
            " The quadratic part beyond the affine one reaches {quad:.4} px RMS in one run."
        );
    }
    text
}

fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::run_shape;

    fn run(exx: f64, eyy: f64, move_px: [f64; 2]) -> RunShape {
        run_shape(move_px, exx, eyy, 0.0)
    }

    #[test]
    fn a_tilts_signature_is_named_as_a_hint() {
        let r = run(-2.5e-4, -1.25e-4, [130.0, 0.0]);
        let text = describe(&r).unwrap();
        assert!(
            text.contains("anisotropic") && text.contains("target_tilt"),
            "{text}"
        );
        let d = run(-3e-4, -1e-4, [130.0, 0.0]);
        assert!(describe(&d).unwrap().contains("decentring"));
        let y = run(-1.25e-4, -2.5e-4, [0.0, 130.0]);
        assert!(describe(&y).unwrap().contains("horizontal"));
    }

    #[test]
    fn nothing_clear_has_no_words() {
        assert_eq!(describe(&run(1e-6, -2e-6, [130.0, 0.0])), None);
    }
}
