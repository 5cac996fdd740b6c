//! A perpendicularity check's request (`POST /perpendicularity-checks`, the dashboard's button):
//! the mounted target moved once along +x and once along −x from the reference position, the
//! frames correlated and the tilt read from their fields (`diagnose::read_perpendicularity`). A
//! setup aid pressed again and again while the mount is adjusted: no static frames, no phase scan,
//! no diagnosis, and no frames kept.

use super::calibration_plan::CalibrationPlan;
use super::request::{field_error, ExperimentRequest, FieldError};
use super::spec::{MoveSpec, PatternSpec};
use crate::bench::BenchLimits;
use crate::dic::DicSettings;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PerpendicularityCheck {
    /// The mounted target: a preset (`a`, `b`, `c`) or a full description.
    #[schema(value_type = Object)]
    pub pattern: PatternSpec,
    /// The move, mm, made along +x and along −x; 0: a calibration's larger default size (10 % of
    /// the field's width, within the travel and 75 % of `dic.max_motion_px`). A tilt's field grows
    /// with it.
    pub move_mm: f64,
    /// DIC settings; without a `roi`, the whole frame (a tilt's field grows towards the edges).
    #[schema(value_type = Object)]
    pub dic: DicSettings,
    /// Seed of the mock bench's speckle and noise.
    pub seed: u64,
}

impl Default for PerpendicularityCheck {
    fn default() -> Self {
        Self {
            pattern: PatternSpec::Preset("a".into()),
            move_mm: 0.0,
            dic: DicSettings::default(),
            seed: 1,
        }
    }
}

impl PerpendicularityCheck {
    /// The move along x, mm: the request's, or the calibration's larger default size.
    pub fn move_for(&self, limits: &BenchLimits, width_px: u32) -> f64 {
        if self.move_mm != 0.0 {
            return self.move_mm;
        }
        let sizes = self.calibration().sizes_mm(limits, width_px);
        sizes.into_iter().fold(0.0, f64::max)
    }

    /// The experiment that captures the check on a bench with `limits` and a sensor of `size`
    /// px: runs `xp` (+move) and `xm` (−move) of one reference, in the camera's own resolution.
    pub fn experiment(
        &self,
        limits: &BenchLimits,
        size: (u32, u32),
    ) -> Result<ExperimentRequest, FieldError> {
        let d = self.move_for(limits, size.0);
        if !(d.is_finite() && d > 0.0) {
            let reason = if self.move_mm == 0.0 {
                format!(
                    "the default move is {d} mm here (10 % of the field, within the stage's travel and 75 % of dic.max_motion_px, {}): state a positive move_mm",
                    self.dic.max_motion_px
                )
            } else {
                format!("must be a positive number of mm (or 0: the default), got {d}")
            };
            return Err(field_error("move_mm", reason));
        }
        let moves = vec![
            MoveSpec {
                id: "xp".into(),
                dx_mm: d,
                dy_mm: 0.0,
            },
            MoveSpec {
                id: "xm".into(),
                dx_mm: -d,
                dy_mm: 0.0,
            },
        ];
        self.calibration()
            .experiment_with_moves(limits, size, moves)
            .map_err(|e| match e.field.as_str() {
                "move_sizes_mm" => FieldError {
                    field: "move_mm".into(),
                    reason: e.reason,
                },
                _ => e,
            })
    }

    /// The check as a calibration plan of no phase scan and no static frames (its sizes, its
    /// DIC over the whole frame).
    fn calibration(&self) -> CalibrationPlan {
        CalibrationPlan {
            name: "perpendicularity".into(),
            pattern: self.pattern.clone(),
            move_sizes_mm: Vec::new(),
            phase_scan_count: Some(0),
            static_frames: 0,
            dic: self.dic.clone(),
            seed: self.seed,
            ..CalibrationPlan::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> BenchLimits {
        BenchLimits {
            scale_px_per_mm: 26.0,
            target_field_mm: None,
            travel_x_mm: Some((-25.0, 25.0)),
            travel_y_mm: Some((-25.0, 25.0)),
            stage_resolution_mm: None,
            exposure_us: (10.0, 1e6),
            hardware_schemes: Vec::new(),
        }
    }

    #[test]
    fn the_check_moves_back_and_forth_along_x_and_nothing_else() {
        let request = PerpendicularityCheck::default()
            .experiment(&paper(), (2560, 2160))
            .unwrap();
        let moves: Vec<(&str, f64, f64)> = request
            .moves
            .iter()
            .map(|m| (m.id.as_str(), m.dx_mm, m.dy_mm))
            .collect();
        // The calibration's larger default at the paper's bench: 75 % of the DIC's 160 px.
        assert_eq!(moves, [("xp", 4.62, 0.0), ("xm", -4.62, 0.0)]);
        assert!(request.step_series.is_empty() && request.static_frames == 0);
        assert!(request.plan(&paper()).is_ok());
    }

    #[test]
    fn a_move_beyond_what_the_dic_tracks_or_not_positive_is_named() {
        // A default that comes out as nothing: the DIC tracks no motion.
        let still = PerpendicularityCheck {
            dic: DicSettings {
                max_motion_px: 0,
                ..DicSettings::default()
            },
            ..PerpendicularityCheck::default()
        };
        let e = still.experiment(&paper(), (2560, 2160)).unwrap_err();
        assert!(
            e.field == "move_mm" && e.reason.contains("default"),
            "{e:?}"
        );
        for bad in [9.85, -1.0, f64::NAN] {
            let check = PerpendicularityCheck {
                move_mm: bad,
                ..PerpendicularityCheck::default()
            };
            let e = check.experiment(&paper(), (2560, 2160)).unwrap_err();
            assert_eq!(e.field, "move_mm", "{bad}: {e:?}");
        }
    }
}
