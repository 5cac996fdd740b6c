//! A camera card's correction of measured displacements (issue 33, "use the card"): what the
//! card explains of the geometry — its lens distortion and the target's tilt
//! ([`GeometryCorrection`]) — taken off each valid point, in the coordinates of the scheme the
//! point was measured in, and the corrected field summarised beside the raw one.

use crate::dic::{PoiResult, Stats};
use crate::model::GeometryCorrection;
use crate::reduce::Scheme;
use serde::{Deserialize, Serialize};

/// The corrected displacement's statistics of one study row: px of the row's scheme.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CardStats {
    /// The card's model name.
    pub model: String,
    pub u: Stats,
    pub v: Stats,
}

/// A card's correction for frames of one size, and its name.
pub struct CardCorrection {
    pub model: String,
    /// None when the card holds neither a distortion nor a tilt: nothing to take off.
    pub correction: Option<GeometryCorrection>,
}

impl CardCorrection {
    /// Each point's corrected (u, v) in the px of `scheme` (None: the frames as read, every
    /// pixel), NaN where the point is not valid. A reduced point (x, y) sits at full-resolution
    /// block·x + the light-sensitive aperture's centre, and moves by block·(u, v) there: the
    /// correction acts where the card's fields were fitted.
    pub fn corrected(&self, scheme: Option<&Scheme>, points: &[PoiResult]) -> Vec<(f64, f64)> {
        let ((bx, by), (ox, oy)) = match scheme {
            Some(s) => ((s.x.block as f64, s.y.block as f64), s.centre_offset_px()),
            None => ((1.0, 1.0), (0.0, 0.0)),
        };
        points
            .iter()
            .map(|p| {
                if !p.status.is_valid() {
                    return (f64::NAN, f64::NAN);
                }
                let Some(c) = &self.correction else {
                    return (p.u, p.v);
                };
                let at = (bx * p.x + ox, by * p.y + oy);
                let (u, v) = c.corrected(at, (bx * p.u, by * p.v));
                (u / bx, v / by)
            })
            .collect()
    }

    /// The corrected field's statistics (u, v) of `points`, measured in `scheme`.
    pub fn stats(&self, scheme: Option<&Scheme>, points: &[PoiResult]) -> CardStats {
        let uv = self.corrected(scheme, points);
        CardStats {
            model: self.model.clone(),
            u: Stats::of(uv.iter().map(|p| p.0)),
            v: Stats::of(uv.iter().map(|p| p.1)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dic::PoiStatus;
    use crate::model::effects::LensDistortion;
    use crate::model::Effects;

    fn point(x: f64, y: f64, u: f64, v: f64) -> PoiResult {
        PoiResult {
            u,
            v,
            ..PoiResult::invalid(x, y, PoiStatus::Converged, 1.0, 3)
        }
    }

    /// A 2x2 binning's point at reduced (x, y) moved by (u, v) is the full-resolution point at
    /// (2x + 0.5, 2y + 0.5) moved by (2u, 2v): corrected there and brought back, it is the same
    /// as correcting the full-resolution point directly.
    #[test]
    fn a_reduced_point_is_corrected_where_its_block_sees() {
        let effects = Effects {
            lens_distortion: Some(LensDistortion::radial(2e-2)),
            ..Default::default()
        };
        let card = CardCorrection {
            model: "card".into(),
            correction: GeometryCorrection::of(&effects, 400, 300, 10.0),
        };
        let ff100 = Scheme::preset("ff100").unwrap();
        let (ru, rv) = card.corrected(Some(&ff100), &[point(30.0, 20.0, 6.0, 1.5)])[0];
        let (fu, fv) = card.corrected(None, &[point(60.5, 40.5, 12.0, 3.0)])[0];
        assert!((2.0 * ru - fu).abs() < 1e-9 && (2.0 * rv - fv).abs() < 1e-9);
        // The distortion moved the point: the correction is not the identity.
        assert!((fu - 12.0).abs() > 1e-3, "{fu}");
        // An invalid point stays NaN; a card of nothing leaves the field as measured.
        let bad = PoiResult::invalid(1.0, 1.0, PoiStatus::LowCorrelation, 0.1, 3);
        assert!(card.corrected(None, &[bad])[0].0.is_nan());
        let nothing = CardCorrection {
            model: "none".into(),
            correction: None,
        };
        assert_eq!(
            nothing.corrected(Some(&ff100), &[point(3.0, 4.0, 1.0, 2.0)]),
            vec![(1.0, 2.0)]
        );
    }
}
