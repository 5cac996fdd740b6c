use exmex::prelude::*;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::collections::BTreeMap;

/// An effect the catalogue lacks, written down by a user in a model file (`[effects.user.NAME]`):
/// either the extra displacement of a moved frame against its reference, as expressions `u` and
/// `v` (full-resolution px), or a change of the moved frame's irradiance, as an expression
/// `intensity` (relative: the moved frame's pixel is multiplied by 1 + `intensity`), of
///
/// - `x`, `y`: for `u`, `v` the point's position in the reference frame, for `intensity` the
///   pixel's, px from the optical axis (the image centre), x to the right and y down;
/// - `tx`, `ty`: the run's actual move, px (the stage's move as the camera sees it);
/// - the effect's named parameters (`[effects.user.NAME.params.P]`, each with a unit, a range and,
///   once known, a value).
///
/// A bowed print, for instance (its depth κ|q|²/2 moves with it, so through a pinhole at distance
/// Z a move t changes the displacement by −t·κ|p|²/(2 Z s²) at p px from the axis, s px/mm):
///
/// ```toml
/// [effects.user.bow]
/// u = "c * (x^2 + y^2) * tx"
/// v = "c * (x^2 + y^2) * ty"
/// [effects.user.bow.params.c]
/// unit = "1/px^2"
/// min = -1e-7
/// max = 1e-7
/// ```
///
/// A lamp that drifted between the reference and the moved frames, lighting the field with a
/// ramp, is an intensity effect:
///
/// ```toml
/// [effects.user.lamp]
/// intensity = "gx * x + gy * y"
/// [effects.user.lamp.params.gx]
/// unit = "1/px"
/// min = -1e-4
/// max = 1e-4
/// [effects.user.lamp.params.gy]
/// unit = "1/px"
/// min = -1e-4
/// max = 1e-4
/// ```
///
/// One effect is one of the two kinds ([`UserKind`]): the diagnosis fits a displacement on the
/// measured fields and an intensity on the image statistics, so an effect with both would be
/// judged on half of its evidence; a user writes two effects instead.
///
/// An effect whose parameters all have a value is part of the model: the renderer adds its field
/// to every moved frame. One with a parameter still without a value is proposed: the model renders
/// without it and `diagnose` fits it as a candidate beside the catalogue's, within the ranges.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserEffect {
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// Extra displacement along x, px; absent means none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u: Option<Expression>,
    /// Extra displacement along y, px; absent means none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub v: Option<Expression>,
    /// Relative change of the moved frame's irradiance at a pixel (0 is none); absent means none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intensity: Option<Expression>,
    #[serde(default)]
    pub params: BTreeMap<String, UserParam>,
}

/// One parameter of a [`UserEffect`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserParam {
    /// The value the model renders with; none while the effect is proposed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// What the value is measured in, as the user writes it (shown beside fitted values).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub unit: String,
    /// The range a fit may take it to.
    pub min: f64,
    pub max: f64,
}

/// What a user effect changes, which is also the evidence its fit reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UserKind {
    /// `u`, `v`: the moved frame's displacement, fitted on the measured fields.
    Displacement,
    /// `intensity`: the moved frame's irradiance, fitted on the image statistics.
    Intensity,
}

/// The variables every expression may use beside the parameters, in the order of
/// [`UserEffect::displacement`]'s arguments.
pub const COORDINATES: [&str; 4] = ["x", "y", "tx", "ty"];

/// The most parameters an effect may have (each a column of a least-squares fit).
pub const MAX_USER_PARAMS: usize = 12;

/// An expression as written and parsed once; compared and written back as its text.
///
/// The parsed form is boxed: exmex keeps its operators and nodes in inline arrays, so a
/// `FlatEx<f64>` is 19,672 bytes (exmex 0.21), and an effect holds up to three. Held by value,
/// every move of an effect (deserialising one, cloning a model) copied them through the stack:
/// compiled without optimisation, `toml`'s deserialiser of an effect took frames of some 600 KB
/// and a test thread's 2 MiB stack overflowed.
#[derive(Clone, Debug)]
pub struct Expression {
    text: String,
    parsed: Box<FlatEx<f64>>,
}

impl PartialEq for Expression {
    fn eq(&self, other: &Self) -> bool {
        self.text == other.text
    }
}

impl Expression {
    pub fn parse(text: &str) -> Result<Self, String> {
        let parsed = Box::new(FlatEx::<f64>::parse(text).map_err(|e| format!("'{text}': {e}"))?);
        Ok(Self {
            text: text.to_string(),
            parsed,
        })
    }

    pub fn text(&self) -> &str {
        &self.text
    }

    /// The variables it reads, by name.
    pub fn variables(&self) -> &[String] {
        self.parsed.var_names()
    }
}

impl Serialize for Expression {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.text)
    }
}

impl<'de> Deserialize<'de> for Expression {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Expression::parse(&text).map_err(serde::de::Error::custom)
    }
}

/// An expression bound to an effect's variables: where each of its own (alphabetical) variables
/// sits in `[x, y, tx, ty, parameters in name order]`.
#[derive(Clone, Debug)]
struct Bound {
    expression: Box<FlatEx<f64>>,
    slots: Vec<usize>,
}

impl Bound {
    fn new(e: &Expression, names: &[&str]) -> Result<Self, String> {
        let slots = e
            .variables()
            .iter()
            .map(|v| {
                names.iter().position(|n| n == v).ok_or_else(|| {
                    format!(
                        "'{}' reads '{v}', which is neither a coordinate (x, y, tx, ty) nor one of its parameters ({})",
                        e.text,
                        names[COORDINATES.len()..].join(", ")
                    )
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            expression: e.parsed.clone(),
            slots,
        })
    }

    fn eval(&self, all: &[f64]) -> f64 {
        let mut own = [0.0; COORDINATES.len() + MAX_USER_PARAMS];
        for (o, &s) in own.iter_mut().zip(&self.slots) {
            *o = all[s];
        }
        // Parsing checked the arity; a domain error (log of a negative) gives NaN, which the
        // caller sees as a field it cannot use.
        self.expression
            .eval(&own[..self.slots.len()])
            .unwrap_or(f64::NAN)
    }
}

/// A user effect ready to evaluate: its expressions bound to its variables.
#[derive(Clone, Debug)]
pub struct UserField {
    u: Option<Bound>,
    v: Option<Bound>,
    intensity: Option<Bound>,
    names: Vec<String>,
}

impl UserField {
    /// The parameters' names, in the order [`UserField::displacement`] takes their values.
    pub fn param_names(&self) -> &[String] {
        &self.names
    }

    pub fn kind(&self) -> UserKind {
        if self.intensity.is_some() {
            UserKind::Intensity
        } else {
            UserKind::Displacement
        }
    }

    fn all_values(
        p: (f64, f64),
        t: (f64, f64),
        values: &[f64],
    ) -> [f64; COORDINATES.len() + MAX_USER_PARAMS] {
        let mut all = [0.0; COORDINATES.len() + MAX_USER_PARAMS];
        all[..4].copy_from_slice(&[p.0, p.1, t.0, t.1]);
        all[4..4 + values.len()].copy_from_slice(values);
        all
    }

    /// The relative change of the moved frame's irradiance at pixel `p` (px from the axis) for
    /// the move `t` (px); 0 for a displacement effect.
    pub fn relative_intensity(&self, p: (f64, f64), t: (f64, f64), values: &[f64]) -> f64 {
        let all = Self::all_values(p, t, values);
        self.intensity.as_ref().map_or(0.0, |b| b.eval(&all))
    }

    /// The extra displacement (px) at `p` (px from the axis, reference frame) for the move `t`
    /// (px) with parameter values `values` (in [`UserField::param_names`] order).
    pub fn displacement(&self, p: (f64, f64), t: (f64, f64), values: &[f64]) -> (f64, f64) {
        let all = Self::all_values(p, t, values);
        let at = |b: &Option<Bound>| b.as_ref().map_or(0.0, |b| b.eval(&all));
        (at(&self.u), at(&self.v))
    }
}

impl UserEffect {
    /// The expressions bound to the coordinates and the parameters; errs naming what is wrong
    /// (a variable that is neither, a range that is empty, a value outside it, too many
    /// parameters, nothing to compute).
    pub fn field(&self) -> Result<UserField, String> {
        let displaces = self.u.is_some() || self.v.is_some();
        if !displaces && self.intensity.is_none() {
            return Err(
                "needs u or v (or both): the displacement it adds, px; or intensity: the relative change of the moved frame's irradiance".into(),
            );
        }
        if displaces && self.intensity.is_some() {
            return Err("has both a displacement (u, v) and an intensity: the diagnosis fits the one on the fields and the other on the image statistics, so write two effects".into());
        }
        if self.params.len() > MAX_USER_PARAMS {
            return Err(format!(
                "has {} parameters; at most {MAX_USER_PARAMS}",
                self.params.len()
            ));
        }
        for (name, p) in &self.params {
            if COORDINATES.contains(&name.as_str()) || !is_identifier(name) {
                return Err(format!(
                    "parameter '{name}': a name of letters, digits and '_' that starts with a letter and is not x, y, tx or ty"
                ));
            }
            if !(p.min.is_finite() && p.max.is_finite() && p.min < p.max) {
                return Err(format!(
                    "parameter '{name}': min < max, both finite (got {} and {})",
                    p.min, p.max
                ));
            }
            if let Some(v) = p.value.filter(|v| !(p.min..=p.max).contains(v)) {
                return Err(format!(
                    "parameter '{name}': value {v} outside [{}, {}]",
                    p.min, p.max
                ));
            }
        }
        let mut names: Vec<&str> = COORDINATES.to_vec();
        names.extend(self.params.keys().map(String::as_str));
        let bind = |e: &Option<Expression>| e.as_ref().map(|e| Bound::new(e, &names)).transpose();
        Ok(UserField {
            u: bind(&self.u)?,
            v: bind(&self.v)?,
            intensity: bind(&self.intensity)?,
            names: self.params.keys().cloned().collect(),
        })
    }

    /// The parameters' values when every one has one (the effect is part of the model), in name
    /// order.
    pub fn values(&self) -> Option<Vec<f64>> {
        self.params.values().map(|p| p.value).collect()
    }

    /// Proposed: some parameter has no value yet, so `diagnose` fits it.
    pub fn is_proposed(&self) -> bool {
        self.values().is_none()
    }

    /// The effect with `values` (name order) as its parameters' values.
    pub fn with_values(&self, values: &[f64]) -> Self {
        let mut e = self.clone();
        for (p, v) in e.params.values_mut().zip(values) {
            p.value = Some(*v);
        }
        e
    }
}

/// A user effect's name: also its candidate's (`user.NAME`).
pub fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The user effects of a model that are part of it (every value set), bound and valued, for the
/// renderer.
pub fn rendered_fields(effects: &BTreeMap<String, UserEffect>) -> Vec<(UserField, Vec<f64>)> {
    effects
        .values()
        .filter_map(|e| Some((e.field().ok()?, e.values()?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bow() -> UserEffect {
        toml::from_str(
            "u = \"c * (x^2 + y^2) * tx\"\nv = \"c * (x^2 + y^2) * ty + d\"\n[params.c]\nmin = -1.0\nmax = 1.0\n[params.d]\nvalue = 0.5\nmin = 0.0\nmax = 1.0\nunit = \"px\"\n",
        )
        .unwrap()
    }

    #[test]
    fn an_expression_reads_coordinates_and_parameters_by_name() {
        let e = bow();
        let f = e.field().unwrap();
        assert_eq!(f.param_names(), ["c", "d"]);
        let (u, v) = f.displacement((3.0, 4.0), (2.0, -1.0), &[0.01, 0.5]);
        assert!((u - 0.01 * 25.0 * 2.0).abs() < 1e-12, "{u}");
        assert!((v - (-0.01 * 25.0 + 0.5)).abs() < 1e-12, "{v}");
        assert!(e.is_proposed());
        let set = e.with_values(&[0.02, 0.1]);
        assert_eq!(set.values(), Some(vec![0.02, 0.1]));
        assert!(!set.is_proposed());
    }

    #[test]
    fn mistakes_are_named() {
        let mut e = bow();
        e.u = Some(Expression::parse("c * z").unwrap());
        let err = e.field().unwrap_err();
        assert!(err.contains("'z'") && err.contains("c, d"), "{err}");
        let mut e = bow();
        e.params.get_mut("c").unwrap().min = 2.0;
        assert!(e.field().unwrap_err().contains("min < max"));
        let mut e = bow();
        e.params.get_mut("d").unwrap().value = Some(3.0);
        assert!(e.field().unwrap_err().contains("outside"));
        let mut e = bow();
        e.u = None;
        e.v = None;
        assert!(e.field().unwrap_err().contains("needs u or v"));
        let mut e = bow();
        e.intensity = Some(Expression::parse("d * x").unwrap());
        assert!(e.field().unwrap_err().contains("write two effects"));
        assert!(Expression::parse("c * (x +").is_err());
        assert!(!is_identifier("1a") && is_identifier("bow_2"));
    }

    #[test]
    fn an_intensity_effect_changes_the_moved_frame_at_a_pixel() {
        let e: UserEffect = toml::from_str(
            "intensity = \"g * x + h * ty\"\n[params.g]\nmin = -1.0\nmax = 1.0\n[params.h]\nmin = -1.0\nmax = 1.0\n",
        )
        .unwrap();
        let f = e.field().unwrap();
        assert_eq!(f.kind(), UserKind::Intensity);
        let i = f.relative_intensity((100.0, 7.0), (3.0, 2.0), &[1e-4, 0.01]);
        assert!((i - (1e-2 + 0.02)).abs() < 1e-12, "{i}");
        // It displaces nothing; a displacement effect changes no intensity.
        assert_eq!(
            f.displacement((100.0, 7.0), (3.0, 2.0), &[1e-4, 0.01]),
            (0.0, 0.0)
        );
        let bow = bow().field().unwrap();
        assert_eq!(bow.kind(), UserKind::Displacement);
        assert_eq!(
            bow.relative_intensity((1.0, 1.0), (1.0, 1.0), &[0.1, 0.2]),
            0.0
        );
    }

    #[test]
    fn round_trips_through_toml_as_written() {
        let e = bow();
        let back: UserEffect = toml::from_str(&toml::to_string(&e).unwrap()).unwrap();
        assert_eq!(back, e);
        assert_eq!(back.u.unwrap().text(), "c * (x^2 + y^2) * tx");
    }
}
