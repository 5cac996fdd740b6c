//! A calibration's move plan (`ffdic calibrate --plan FILE`, `POST /calibrations`): moves of
//! several sizes along +x, −x, +y and −y, a sub-pixel phase scan along each axis, static repeats.
//! Each kind of run separates effects the others cannot: two move sizes tell lens distortion
//! (quadratic in the move) from a scale change (linear), moves along both axes tell a tilt from
//! decentring distortion and map the stage's axes, the phase scan tells the pixel aperture from
//! lens blur (their bias against the sub-pixel phase differs) when the print is characterised
//! (against a print calibrated to the frames neither is fitted, so the scan is captured only when
//! asked for), the repeats give the noise floor.
//! Plans are TOML files like experiments; unknown keys are refused with the key named.

use super::request::{field_error, ExperimentRequest, FieldError, SchemeSpec};
use super::spec::{MoveSpec, PatternSpec, StepSeries};
use crate::bench::BenchLimits;
use crate::dic::DicSettings;
use serde::{Deserialize, Serialize};

/// The default large move, as a fraction of the field's width.
pub const DEFAULT_LARGE_MOVE_FIELD_FRACTION: f64 = 0.1;
/// The default large move over the small one: a field quadratic in the move (distortion) then
/// differs from one linear in it (scale) by this factor.
pub const DEFAULT_MOVE_SIZE_RATIO: f64 = 5.0;
/// The phase scan's steps along each axis when a plan with a characterised print leaves them unset.
pub const DEFAULT_PHASE_SCAN_COUNT: usize = 4;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationPlan {
    /// The calibration's name: the experiment's, and the card model's prefix (`NAME-HASH`).
    pub name: String,
    /// The mounted target: a preset (`a`, `b`, `c`) or a full description.
    #[schema(value_type = Object)]
    pub pattern: PatternSpec,
    /// The target is characterised: its dots are as `pattern` describes them (as an experiment's
    /// `print_characterised`). Only then can the card fit the lens blur and the pixel aperture,
    /// which a print calibrated to the frames absorbs.
    pub print_characterised: bool,
    /// Move sizes, mm, each made along +x, −x, +y and −y from the reference position. Empty: 10 %
    /// of the field's width (within the stage's travel and 75 % of `dic.max_motion_px`) and a
    /// fifth of that.
    pub move_sizes_mm: Vec<f64>,
    /// The phase scan's step along each axis, px of the sensor (0 or a count of 0: no scan).
    pub phase_scan_step_px: f64,
    /// Steps of the phase scan along each axis. Unset: 4 with a characterised print
    /// (`DEFAULT_PHASE_SCAN_COUNT`), none without (the scan tells the aperture from the blur, and
    /// a print calibrated to the frames absorbs both).
    pub phase_scan_count: Option<usize>,
    /// Static frames of the reference position (the noise floor).
    pub static_frames: usize,
    /// Diagnosis rounds before the card is written (1–8, checked where the job is submitted).
    #[schema(minimum = 1, maximum = 8)]
    pub rounds: usize,
    /// The model the calibration starts from (a name from `GET /models`).
    pub model: String,
    /// DIC settings of the analyses (the camera's own resolution, `native`). Without a `roi`, the
    /// whole frame: distortion shows most at the corners.
    #[schema(value_type = Object)]
    pub dic: DicSettings,
    /// Seed of the mock bench's speckle and noise, and of the model's.
    pub seed: u64,
}

impl Default for CalibrationPlan {
    fn default() -> Self {
        Self {
            name: "camera-card".into(),
            pattern: PatternSpec::Preset("a".into()),
            print_characterised: false,
            move_sizes_mm: Vec::new(),
            phase_scan_step_px: 0.25,
            phase_scan_count: None,
            static_frames: 2,
            rounds: 4,
            model: "baseline".into(),
            dic: DicSettings::default(),
            seed: 1,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    #[error("cannot read calibration plan {path}: {source}")]
    Read {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("calibration plan {path}: {message}")]
    Parse {
        path: std::path::PathBuf,
        message: String,
    },
}

impl CalibrationPlan {
    pub fn load(path: &std::path::Path) -> Result<Self, PlanError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlanError::Read {
            path: path.to_owned(),
            source,
        })?;
        toml::from_str(&text).map_err(|e| PlanError::Parse {
            path: path.to_owned(),
            message: e.message().to_string(),
        })
    }

    /// The move sizes, mm: the plan's, or the defaults for a sensor `width_px` wide — the larger
    /// 10 % of the field's width, within the stage's travel and within 75 % of the DIC's
    /// `max_motion_px`, the smaller a fifth of it.
    pub fn sizes_mm(&self, limits: &BenchLimits, width_px: u32) -> Vec<f64> {
        if !self.move_sizes_mm.is_empty() {
            return self.move_sizes_mm.clone();
        }
        let field_mm = f64::from(width_px) / limits.scale_px_per_mm;
        let reach_mm = [limits.travel_x_mm, limits.travel_y_mm]
            .into_iter()
            .flatten()
            .map(|(lo, hi)| (-lo).min(hi))
            .fold(f64::INFINITY, f64::min);
        let tracked_mm = 0.75 * self.dic.max_motion_px as f64 / limits.scale_px_per_mm;
        let large_mm = (DEFAULT_LARGE_MOVE_FIELD_FRACTION * field_mm)
            .min(reach_mm)
            .min(tracked_mm);
        let round = |mm: f64| (mm * 100.0).round() / 100.0;
        vec![round(large_mm / DEFAULT_MOVE_SIZE_RATIO), round(large_mm)]
    }

    /// The DIC settings for a sensor of `width` x `height` px: the plan's, over the whole frame
    /// when they name no ROI.
    pub fn dic_for(&self, (width, height): (u32, u32)) -> DicSettings {
        let mut dic = self.dic.clone();
        if dic.roi.is_none() {
            dic.roi = Some(crate::image::Roi::new(
                0,
                0,
                width as usize,
                height as usize,
            ));
        }
        dic
    }

    /// The experiment that captures the plan on a bench with `limits` and a sensor of `size` px;
    /// the experiment's own checks (travel, counts) follow when it is planned.
    pub fn experiment(
        &self,
        limits: &BenchLimits,
        size: (u32, u32),
    ) -> Result<ExperimentRequest, FieldError> {
        let sizes = self.sizes_mm(limits, size.0);
        if let Some(s) = sizes.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(field_error(
                "move_sizes_mm",
                format!("every size must be a positive number of mm, got {s}"),
            ));
        }
        let mut moves = Vec::new();
        for (k, size) in sizes.iter().enumerate() {
            for (axis, sign, dx, dy) in [
                ("x", "p", 1.0, 0.0),
                ("x", "m", -1.0, 0.0),
                ("y", "p", 0.0, 1.0),
                ("y", "m", 0.0, -1.0),
            ] {
                moves.push(MoveSpec {
                    id: format!("{axis}{sign}{}", k + 1),
                    dx_mm: dx * size,
                    dy_mm: dy * size,
                });
            }
        }
        self.experiment_with_moves(limits, size, moves)
    }

    /// The phase scan's steps along each axis: as set, else [`DEFAULT_PHASE_SCAN_COUNT`] with a
    /// characterised print and none without.
    pub fn phase_scan_steps(&self) -> usize {
        self.phase_scan_count
            .unwrap_or(if self.print_characterised {
                DEFAULT_PHASE_SCAN_COUNT
            } else {
                0
            })
    }

    /// The plan with its phase scan's count stated ([`Self::phase_scan_steps`]): what a run
    /// captures, as its record keeps it, so a reader of the record need not know the default.
    pub fn with_phase_scan_stated(mut self) -> Self {
        self.phase_scan_count = Some(self.phase_scan_steps());
        self
    }

    /// [`Self::experiment`] with `moves` in place of the plan's sizes' (an on-bench diagnosis's
    /// designed moves): the plan's target, phase scan, static frames and DIC; every move within
    /// what the DIC tracks.
    pub fn experiment_with_moves(
        &self,
        limits: &BenchLimits,
        size: (u32, u32),
        moves: Vec<MoveSpec>,
    ) -> Result<ExperimentRequest, FieldError> {
        let max_px = self.dic.max_motion_px as f64;
        let length_mm = |m: &MoveSpec| m.dx_mm.hypot(m.dy_mm);
        if let Some(s) = moves
            .iter()
            .map(length_mm)
            .find(|s| *s * limits.scale_px_per_mm > max_px)
        {
            return Err(field_error(
                "move_sizes_mm",
                format!(
                    "a {s} mm move is {:.0} px at {} px/mm, beyond what the DIC tracks (dic.max_motion_px, {max_px:.0})",
                    s * limits.scale_px_per_mm,
                    limits.scale_px_per_mm
                ),
            ));
        }
        if !(self.phase_scan_step_px.is_finite() && self.phase_scan_step_px >= 0.0) {
            return Err(field_error(
                "phase_scan_step_px",
                "must be a non-negative number of px",
            ));
        }
        let step_mm = self.phase_scan_step_px / limits.scale_px_per_mm;
        let count = self.phase_scan_steps();
        let step_series = if count > 0 && step_mm > 0.0 {
            vec![
                StepSeries {
                    id: "xs".into(),
                    dx_step_mm: step_mm,
                    dy_step_mm: 0.0,
                    count,
                },
                StepSeries {
                    id: "ys".into(),
                    dx_step_mm: 0.0,
                    dy_step_mm: step_mm,
                    count,
                },
            ]
        } else {
            Vec::new()
        };
        Ok(ExperimentRequest {
            name: self.name.clone(),
            patterns: vec![self.pattern.clone()],
            print_characterised: self.print_characterised,
            moves,
            step_series,
            static_frames: self.static_frames,
            repeats: 1,
            schemes: vec![SchemeSpec::Preset("native".into())],
            dic: self.dic_for(size),
            seed: self.seed,
            ..ExperimentRequest::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> BenchLimits {
        BenchLimits {
            scale_px_per_mm: 13.0,
            target_field_mm: None,
            travel_x_mm: Some((-25.0, 25.0)),
            travel_y_mm: Some((-3.0, 25.0)),
            stage_resolution_mm: None,
            exposure_us: (10.0, 1e6),
            hardware_schemes: Vec::new(),
        }
    }

    #[test]
    fn the_default_plan_moves_both_ways_along_both_axes_within_the_travel() {
        let request = CalibrationPlan::default()
            .experiment(&limits(), (640, 540))
            .unwrap();
        // 640 px at 13 px/mm: a 49.2 mm field, 10 % of it 4.92 mm, cut to the 3 mm the stage
        // can go towards −y; the small move a fifth of that.
        let sizes: Vec<f64> = request
            .moves
            .iter()
            .map(|m| m.dx_mm.abs() + m.dy_mm.abs())
            .collect();
        assert_eq!(sizes, [0.6, 0.6, 0.6, 0.6, 3.0, 3.0, 3.0, 3.0]);
        let ids: Vec<&str> = request.moves.iter().map(|m| m.id.as_str()).collect();
        assert_eq!(
            ids,
            ["xp1", "xm1", "yp1", "ym1", "xp2", "xm2", "yp2", "ym2"]
        );
        // A nominal print: no phase scan (it could separate nothing), the print as nominal.
        assert!(request.step_series.is_empty());
        assert!(!request.print_characterised);
        assert!(request.plan(&limits()).is_ok());
    }

    #[test]
    fn a_characterised_print_takes_the_phase_scan_unless_the_plan_says_otherwise() {
        let characterised = CalibrationPlan {
            print_characterised: true,
            ..CalibrationPlan::default()
        };
        let request = characterised.experiment(&limits(), (640, 540)).unwrap();
        assert!(request.print_characterised);
        let counts: Vec<usize> = request.step_series.iter().map(|s| s.count).collect();
        assert_eq!(counts, [DEFAULT_PHASE_SCAN_COUNT, DEFAULT_PHASE_SCAN_COUNT]);
        assert!((request.step_series[0].dx_step_mm - 0.25 / 13.0).abs() < 1e-15);
        assert!((request.step_series[1].dy_step_mm - 0.25 / 13.0).abs() < 1e-15);
        // Set, the count is the plan's either way.
        for print_characterised in [false, true] {
            let plan = CalibrationPlan {
                print_characterised,
                phase_scan_count: Some(3),
                ..CalibrationPlan::default()
            };
            let request = plan.experiment(&limits(), (640, 540)).unwrap();
            assert_eq!(request.step_series.len(), 2);
            assert!(request.step_series.iter().all(|s| s.count == 3));
        }
        let none = CalibrationPlan {
            print_characterised: true,
            phase_scan_count: Some(0),
            ..CalibrationPlan::default()
        };
        assert!(none
            .experiment(&limits(), (640, 540))
            .unwrap()
            .step_series
            .is_empty());
        // Stated as run: the default resolved, a set count kept.
        let stated = |p: &CalibrationPlan| p.clone().with_phase_scan_stated().phase_scan_count;
        assert_eq!(stated(&characterised), Some(DEFAULT_PHASE_SCAN_COUNT));
        assert_eq!(stated(&CalibrationPlan::default()), Some(0));
        assert_eq!(stated(&none), Some(0));
    }

    #[test]
    fn the_default_moves_stay_within_what_the_dic_tracks() {
        // The paper's bench (26 px/mm, 2560 px): 10 % of the field is 256 px, beyond the DIC's
        // 160 px; the default stays within 75 % of it (4.62 mm), and a plan asking more is told.
        let paper = BenchLimits {
            scale_px_per_mm: 26.0,
            travel_y_mm: Some((-25.0, 25.0)),
            stage_resolution_mm: None,
            ..limits()
        };
        assert_eq!(
            CalibrationPlan::default().sizes_mm(&paper, 2560),
            [0.92, 4.62]
        );
        let plan = CalibrationPlan {
            move_sizes_mm: vec![9.85],
            ..CalibrationPlan::default()
        };
        let e = plan.experiment(&paper, (2560, 2160)).unwrap_err();
        assert_eq!(e.field, "move_sizes_mm");
        assert!(e.reason.contains("max_motion_px"), "{}", e.reason);
    }

    #[test]
    fn a_plan_names_what_is_wrong() {
        let plan: Result<CalibrationPlan, _> = toml::from_str("move_sizes = [1.0]");
        assert!(plan.unwrap_err().to_string().contains("move_sizes"));
        let plan = CalibrationPlan {
            move_sizes_mm: vec![1.0, -2.0],
            ..CalibrationPlan::default()
        };
        assert_eq!(
            plan.experiment(&limits(), (640, 540)).unwrap_err().field,
            "move_sizes_mm"
        );
    }
}
