//! The perpendicularity readout (issue 33's live setup aid): the target's tilt and the stage's
//! angle from one small move back and forth, fitted on the measured displacement fields alone.
//!
//! A flat target square to the optical axis moved by the stage gives a uniform displacement; what
//! else the field holds is the camera's geometry. A tilt's field grows with the move and changes
//! sign with it (Hijazi et al., "A novel approach for the determination of surface tilt angles in
//! 2D-DIC experiments", Exp. Mech. 2020; first-order fields in [`super::basis`]); a rotation or a
//! scale change between the frames does not, and radial distortion is quadratic over the frame. So
//! the moves +d and −d along x from one reference tell the two tilt slopes from rotation, scale and
//! k1, fitted jointly by the weighted least squares of the geometric candidates
//! ([`super::fit_geometric`]) with each run's rigid move as a nuisance — no model rendered, no
//! print calibrated: a fraction of a second beside the DIC, where a calibration round takes tens.
//!
//! What it cannot tell: decentring distortion (p1, p2) leaves nearly a tilt's field under any
//! translation (`move_design`'s canonical correlation ≥ 0.97), so a decentred lens reads as a
//! constant tilt; the reading follows the mount as it is adjusted, and a camera card fits both.
//! The stage's angle is the direction of the move's image (+d against −d) after the fitted
//! fields are taken off. Its standard error counts the DIC's noise over the points and the
//! stage's landing scatter, which the closure of the move back and forth shows: the two landings'
//! sum, +d and −d from the reference, is zero for a stage that lands where told (a rough figure:
//! two degrees of freedom).

use super::basis::GeometricParam;
use super::bic::inflation;
use super::discrepancy::CommonPoint;
use super::fit_geometric::{fit_geometric, FieldSample, GeometricFit};
use super::write_geometric::ASSUMED_WORKING_DISTANCE_MM;
use crate::dic::DicResult;
use crate::reduce::Scheme;
use crate::stats::median;
use serde::{Deserialize, Serialize};

/// The readout's terms, in the order they are admitted: k1 only when the runs tell it from the
/// others.
const TERMS: [GeometricParam; 5] = [
    GeometricParam::Rotation,
    GeometricParam::Scale,
    GeometricParam::TiltSlopeY,
    GeometricParam::TiltSlopeX,
    GeometricParam::DistortionK1,
];

/// The significance threshold of a tilt angle, in standard errors: two angles tested at a
/// family-wise 1 % (Bonferroni, Φ⁻¹(1 − 0.01/4)).
pub const TILT_Z_SIGNIFICANT: f64 = 2.807;

/// One move of the check: where the stage was told to go from the reference, and the DIC of the
/// reference against the frame there.
pub struct ReadoutRun<'a> {
    pub commanded_mm: (f64, f64),
    pub dic: &'a DicResult,
}

/// What the bench states of its optics and stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadoutSetting {
    pub width_px: usize,
    pub height_px: usize,
    /// The nominal scale, px/mm (the tilt's slope is tan θ over the distance times this).
    pub scale_px_per_mm: f64,
    /// Pupil to target, mm, when stated: the angles are then absolute.
    pub working_distance_mm: Option<f64>,
}

/// One reading: both tilt angles and the stage's angle, each with its standard error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PerpendicularityReading {
    /// The target's rotation about the image's vertical axis (its +x side farther), rad.
    pub tilt_about_y_rad: f64,
    pub tilt_about_y_se_rad: f64,
    /// About the image's horizontal axis (its +y side farther), rad.
    pub tilt_about_x_rad: f64,
    pub tilt_about_x_se_rad: f64,
    /// tan θ over the working distance, per m: what one translation identifies.
    pub tan_about_y_per_m: f64,
    pub tan_about_x_per_m: f64,
    /// The distance the angles are at, mm, and whether the bench states it (otherwise
    /// [`ASSUMED_WORKING_DISTANCE_MM`]).
    pub working_distance_mm: f64,
    pub working_distance_stated: bool,
    /// The stage's x axis against the sensor's rows, rad (positive: a +x move goes towards +y).
    pub stage_angle_rad: f64,
    pub stage_angle_se_rad: f64,
    /// Image px per mm of the stage's x travel, measured.
    pub scale_x_px_per_mm: f64,
    /// The stage's landing scatter (one σ per axis), px, from the closure of the move back and
    /// forth: the landings' sum (+d, then −d from one reference) over √6 per component.
    pub landing_scatter_px: f64,
    /// Between the reference and the moved frames: a rotation (rad) and a scale change.
    pub rotation_rad: f64,
    pub rotation_se_rad: f64,
    pub scale_ds: f64,
    pub scale_ds_se: f64,
    /// Radial distortion k1 (normalised by the half diagonal), when the fit admitted it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k1: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k1_se: Option<f64>,
    /// A tilt angle lies more than [`TILT_Z_SIGNIFICANT`] standard errors from zero.
    pub significant: bool,
    /// Points fitted over all runs, and the RMS of the field about the fit, px.
    pub points: usize,
    pub residual_px: f64,
    pub notes: Vec<String>,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ReadoutError {
    #[error("a perpendicularity reading needs a move along +x and one along −x from one reference, got {0} runs")]
    Moves(usize),
    #[error("run {run}: {valid} valid DIC points, too few to fit a field (at least {needed})")]
    TooFewPoints {
        run: usize,
        valid: usize,
        needed: usize,
    },
    #[error("the runs' fields do not separate a tilt from a rotation and a scale change")]
    NotSeparated,
}

/// The fewest valid points a run's field must have.
const MIN_POINTS: usize = 50;

/// Reads the tilt and the stage's angle from `runs` (at least a move along +x and one along −x).
pub fn read_perpendicularity(
    runs: &[ReadoutRun],
    setting: &ReadoutSetting,
) -> Result<PerpendicularityReading, ReadoutError> {
    let plus = runs.iter().position(|r| r.commanded_mm.0 > 0.0);
    let minus = runs.iter().position(|r| r.commanded_mm.0 < 0.0);
    let (Some(plus), Some(minus)) = (plus, minus) else {
        return Err(ReadoutError::Moves(runs.len()));
    };
    let points: Vec<Vec<CommonPoint>> = runs.iter().map(|r| valid_points(r.dic)).collect();
    if let Some((run, p)) = points
        .iter()
        .enumerate()
        .find(|(_, p)| p.len() < MIN_POINTS)
    {
        return Err(ReadoutError::TooFewPoints {
            run,
            valid: p.len(),
            needed: MIN_POINTS,
        });
    }
    let frame = Frame::of(setting);
    let fields = Fields::fit(runs, points, &frame)?;
    let (lp, lm) = (fields.landing(plus, &frame), fields.landing(minus, &frame));
    let (du, dv) = (lp.0 - lm.0, lp.1 - lm.1);
    let length_px = du.hypot(dv);
    let scale_x_px_per_mm = length_px / (runs[plus].commanded_mm.0 - runs[minus].commanded_mm.0);
    // The closure e₊ + e₋ − 2e₀ of three landings each of variance σ² has variance 6σ² per
    // component; the angle reads e₊ − e₋ across the move (2σ²), beside each landing's DIC noise.
    let closure = (lp.0 + lm.0, lp.1 + lm.1);
    let scatter_var = (closure.0.powi(2) + closure.1.powi(2)) / 12.0;
    let across_var = fields.landing_var(plus) + fields.landing_var(minus) + 2.0 * scatter_var;
    let (z, stated) = match setting.working_distance_mm {
        Some(z) => (z, true),
        None => (ASSUMED_WORKING_DISTANCE_MM, false),
    };
    // a = tan θ / (Z·scale): the measured scale is the one the slopes' px are in.
    let k = z * scale_x_px_per_mm;
    let angle = |p: GeometricParam| {
        let (a, se) = fields.value(p).expect("a tilt term is always fitted");
        let t = a * k;
        (t.atan(), se * k / (1.0 + t * t), t / z * 1000.0)
    };
    let (ty, ty_se, tan_y) = angle(GeometricParam::TiltSlopeY);
    let (tx, tx_se, tan_x) = angle(GeometricParam::TiltSlopeX);
    let (rotation_rad, rotation_se_rad) = fields.value(GeometricParam::Rotation).expect("fitted");
    let (scale_ds, scale_ds_se) = fields.value(GeometricParam::Scale).expect("fitted");
    let k1 = fields.value(GeometricParam::DistortionK1);
    Ok(PerpendicularityReading {
        tilt_about_y_rad: ty,
        tilt_about_y_se_rad: ty_se,
        tilt_about_x_rad: tx,
        tilt_about_x_se_rad: tx_se,
        tan_about_y_per_m: tan_y,
        tan_about_x_per_m: tan_x,
        working_distance_mm: z,
        working_distance_stated: stated,
        stage_angle_rad: dv.atan2(du),
        stage_angle_se_rad: across_var.sqrt() / length_px,
        scale_x_px_per_mm,
        landing_scatter_px: scatter_var.sqrt(),
        rotation_rad,
        rotation_se_rad,
        scale_ds,
        scale_ds_se,
        k1: k1.map(|(v, _)| v),
        k1_se: k1.map(|(_, se)| se),
        significant: (ty / ty_se).abs() > TILT_Z_SIGNIFICANT
            || (tx / tx_se).abs() > TILT_Z_SIGNIFICANT,
        points: fields.points.iter().map(Vec::len).sum(),
        residual_px: fields.residual_px(),
        notes: notes(stated, z, k1.is_some()),
    })
}

/// What a reading cannot say, in words.
fn notes(stated: bool, z: f64, k1_fitted: bool) -> Vec<String> {
    let mut notes = vec![
        "decentring distortion (p1, p2) leaves nearly a tilt's field under translations: a decentred lens reads as a constant tilt".to_string(),
        "the stage's landing scatter, in the stage angle's error, is read from the closure of one move back and forth (two degrees of freedom: a rough figure)".to_string(),
    ];
    if !stated {
        notes.push(format!(
            "the bench states no working_distance_mm: the angles are those at an assumed {z:.0} mm (tan_about_*_per_m is what the moves identify)"
        ));
    }
    if !k1_fitted {
        notes.push("k1: not separated from the tilt by these moves; not fitted".into());
    }
    notes
}

/// The frame's centre (the optical axis) and distortion radius (its half diagonal), px.
struct Frame {
    centre: (f64, f64),
    r0: f64,
}

impl Frame {
    fn of(setting: &ReadoutSetting) -> Self {
        let (w, h) = (setting.width_px as f64, setting.height_px as f64);
        Self {
            centre: ((w - 1.0) / 2.0, (h - 1.0) / 2.0),
            r0: 0.5 * w.hypot(h),
        }
    }

    fn rel(&self, p: &CommonPoint) -> (f64, f64) {
        (p.x - self.centre.0, p.y - self.centre.1)
    }
}

/// The runs' fields and the weighted joint fit of [`TERMS`] on them.
struct Fields {
    points: Vec<Vec<CommonPoint>>,
    /// Each run's move's image (the median displacement), px.
    moves: Vec<(f64, f64)>,
    /// Each run's scatter about the fit (u, v), px², and its covariance inflation.
    var: Vec<(f64, f64)>,
    inflation: Vec<f64>,
    fit: GeometricFit,
}

impl Fields {
    /// Unit weights first; then each run weighted by its own scatter about that fit.
    fn fit(
        runs: &[ReadoutRun],
        points: Vec<Vec<CommonPoint>>,
        frame: &Frame,
    ) -> Result<Self, ReadoutError> {
        let native = Scheme::parse("native").expect("the native scheme parses");
        let moves: Vec<(f64, f64)> = points.iter().map(|p| median_move(p)).collect();
        let inflation: Vec<f64> = runs.iter().map(|r| inflation(&r.dic.settings)).collect();
        let fit_with = |var: &[(f64, f64)]| {
            let samples: Vec<FieldSample> = (0..runs.len())
                .map(|run| FieldSample {
                    scheme: &native,
                    move_px: moves[run],
                    centre: frame.centre,
                    r0: frame.r0,
                    points: &points[run],
                    var: var[run],
                    inflation: inflation[run],
                    // Every run shares the one reference frame.
                    pattern: 0,
                    run,
                })
                .collect();
            fit_geometric(&samples, &TERMS).or_else(|| fit_geometric(&samples, &TERMS[..4]))
        };
        let first = fit_with(&vec![(1.0, 1.0); runs.len()]).ok_or(ReadoutError::NotSeparated)?;
        let var: Vec<(f64, f64)> = points
            .iter()
            .enumerate()
            .map(|(run, pts)| {
                residual_var(pts, |p| first.field_at(frame.rel(p), moves[run], frame.r0))
            })
            .collect();
        let fit = fit_with(&var).ok_or(ReadoutError::NotSeparated)?;
        Ok(Self {
            points,
            moves,
            var,
            inflation,
            fit,
        })
    }

    fn value(&self, p: GeometricParam) -> Option<(f64, f64)> {
        self.fit.value(p)
    }

    /// The run's rigid move: its displacement less the fitted fields, averaged.
    fn landing(&self, run: usize, frame: &Frame) -> (f64, f64) {
        rigid_move(&self.points[run], |p| {
            self.fit.field_at(frame.rel(p), self.moves[run], frame.r0)
        })
    }

    /// The variance of the run's landing in v (across an x move), px².
    fn landing_var(&self, run: usize) -> f64 {
        self.var[run].1 * self.inflation[run] / self.points[run].len() as f64
    }

    /// The RMS of every run's field about the fit, px.
    fn residual_px(&self) -> f64 {
        let n: usize = self.points.iter().map(Vec::len).sum();
        let ss: f64 = self
            .var
            .iter()
            .zip(&self.points)
            .map(|(v, p)| (v.0 + v.1) * p.len() as f64)
            .sum();
        (ss / n as f64).sqrt()
    }
}

/// The valid points of a DIC result, their displacement as the field to fit.
fn valid_points(dic: &DicResult) -> Vec<CommonPoint> {
    dic.points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.status.is_valid() && p.u.is_finite() && p.v.is_finite())
        .map(|(index, p)| CommonPoint {
            index,
            x: p.x,
            y: p.y,
            du: p.u,
            dv: p.v,
            fit_du: 0.0,
            fit_dv: 0.0,
        })
        .collect()
}

/// The median displacement: the move's image, robust to a few wrong points.
fn median_move(points: &[CommonPoint]) -> (f64, f64) {
    let of = |component: fn(&CommonPoint) -> f64| {
        median(&mut points.iter().map(component).collect::<Vec<f64>>())
    };
    (of(|p| p.du), of(|p| p.dv))
}

/// The mean of the displacement less `field`: the run's rigid move.
fn rigid_move(points: &[CommonPoint], field: impl Fn(&CommonPoint) -> (f64, f64)) -> (f64, f64) {
    let n = points.len() as f64;
    points.iter().fold((0.0, 0.0), |(u, v), p| {
        let f = field(p);
        (u + (p.du - f.0) / n, v + (p.dv - f.1) / n)
    })
}

/// The variance (u, v) of the displacement less `field` about its mean.
fn residual_var(points: &[CommonPoint], field: impl Fn(&CommonPoint) -> (f64, f64)) -> (f64, f64) {
    let rest: Vec<(f64, f64)> = points
        .iter()
        .map(|p| {
            let f = field(p);
            (p.du - f.0, p.dv - f.1)
        })
        .collect();
    let n = rest.len() as f64;
    let (mu, mv) = rest
        .iter()
        .fold((0.0, 0.0), |(a, b), r| (a + r.0 / n, b + r.1 / n));
    let (vu, vv) = rest.iter().fold((0.0, 0.0), |(a, b), r| {
        (a + (r.0 - mu).powi(2), b + (r.1 - mv).powi(2))
    });
    let dof = (n - 1.0).max(1.0);
    (vu / dof, vv / dof)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::synthetic_result;
    use crate::dic::DicSettings;

    const SIZE: (usize, usize) = (2560, 2160);
    const SCALE: f64 = 26.0;
    const Z_MM: f64 = 300.0;

    /// The image (px from the centre) of the in-plane target point q (mm) through a pinhole at
    /// `Z_MM` from a target turned by θx about x, then θy about y — written here from the
    /// rotation matrices, not from the model.
    fn pinhole(q: (f64, f64), theta_x: f64, theta_y: f64) -> (f64, f64) {
        let (sx, cx) = theta_x.sin_cos();
        let (sy, cy) = theta_y.sin_cos();
        let w = [q.0, q.1 * cx, q.1 * sx];
        let (wx, wy, wz) = (cy * w[0] - sy * w[2], w[1], sy * w[0] + cy * w[2] + Z_MM);
        (SCALE * Z_MM * wx / wz, SCALE * Z_MM * wy / wz)
    }

    /// The DIC of a reference against the target moved by `t_mm` along the stage's x axis turned
    /// `stage_rad` from the rows, through the tilted pinhole, with noise of σ 0.01 px.
    fn run(t_mm: f64, tilt: (f64, f64), stage_rad: f64, seed: u64) -> DicResult {
        landed(t_mm, tilt, stage_rad, (0.0, 0.0), seed)
    }

    /// [`run`], the stage landing `off_px` from where it was told.
    fn landed(
        t_mm: f64,
        tilt: (f64, f64),
        stage_rad: f64,
        off_px: (f64, f64),
        seed: u64,
    ) -> DicResult {
        let settings = DicSettings {
            step_px: 40,
            ..DicSettings::default()
        };
        let (c0, c1) = ((SIZE.0 as f64 - 1.0) / 2.0, (SIZE.1 as f64 - 1.0) / 2.0);
        let t = (t_mm * stage_rad.cos(), t_mm * stage_rad.sin());
        synthetic_result(
            SIZE,
            &settings,
            |x, y| {
                let p = (x - c0, y - c1);
                // The target point seen at p: the projection inverted by fixed point.
                let mut q = (p.0 / SCALE, p.1 / SCALE);
                for _ in 0..60 {
                    let r = pinhole(q, tilt.0, tilt.1);
                    q = (q.0 + (p.0 - r.0) / SCALE, q.1 + (p.1 - r.1) / SCALE);
                }
                let moved = pinhole((q.0 + t.0, q.1 + t.1), tilt.0, tilt.1);
                (moved.0 - p.0 + off_px.0, moved.1 - p.1 + off_px.1)
            },
            0.01,
            seed,
        )
    }

    fn setting(working_distance_mm: Option<f64>) -> ReadoutSetting {
        ReadoutSetting {
            width_px: SIZE.0,
            height_px: SIZE.1,
            scale_px_per_mm: SCALE,
            working_distance_mm,
        }
    }

    /// The reading of `plus` (+3 mm) and `minus` (−3 mm).
    fn read_pair(
        plus: &DicResult,
        minus: &DicResult,
        working_distance_mm: Option<f64>,
    ) -> PerpendicularityReading {
        let runs = [
            ReadoutRun {
                commanded_mm: (3.0, 0.0),
                dic: plus,
            },
            ReadoutRun {
                commanded_mm: (-3.0, 0.0),
                dic: minus,
            },
        ];
        read_perpendicularity(&runs, &setting(working_distance_mm)).unwrap()
    }

    #[test]
    fn the_readout_finds_a_pinholes_tilt_and_the_stages_angle_from_a_move_back_and_forth() {
        // 0.05° is the setup aid's stated accuracy (issue 33) for tilts of 0.2–2°.
        let tolerance = 0.05_f64.to_radians();
        for (k, tilt) in [
            (0.0, 2.0_f64.to_radians()),
            (0.2_f64.to_radians(), 0.0),
            (-1.0_f64.to_radians(), 0.7_f64.to_radians()),
        ]
        .into_iter()
        .enumerate()
        {
            let stage = 0.004;
            let (plus, minus) = (
                run(3.0, tilt, stage, 10 + k as u64),
                run(-3.0, tilt, stage, 20 + k as u64),
            );
            let r = read_pair(&plus, &minus, Some(Z_MM));
            assert!(
                (r.tilt_about_x_rad - tilt.0).abs() < tolerance
                    && (r.tilt_about_y_rad - tilt.1).abs() < tolerance,
                "tilt {tilt:?}: read ({}, {}) ± ({}, {})",
                r.tilt_about_x_rad,
                r.tilt_about_y_rad,
                r.tilt_about_x_se_rad,
                r.tilt_about_y_se_rad
            );
            assert!(r.significant && r.working_distance_stated);
            assert!(
                (r.stage_angle_rad - stage).abs() < 3.0 * r.stage_angle_se_rad + 1e-5,
                "stage {} ± {}",
                r.stage_angle_rad,
                r.stage_angle_se_rad
            );
        }
    }

    #[test]
    fn a_square_target_reads_no_significant_tilt() {
        let (plus, minus) = (run(3.0, (0.0, 0.0), 0.0, 1), run(-3.0, (0.0, 0.0), 0.0, 2));
        let r = read_pair(&plus, &minus, None);
        assert!(!r.significant, "{r:?}");
        assert!(!r.working_distance_stated && r.notes.iter().any(|n| n.contains("assumed")));
        assert!(
            (r.scale_x_px_per_mm - SCALE).abs() < 1e-3 * SCALE,
            "{}",
            r.scale_x_px_per_mm
        );
    }

    #[test]
    fn a_landing_off_where_told_shows_in_the_closure_and_widens_the_stage_angles_error() {
        let tilt = (0.0, 0.5_f64.to_radians());
        let read = |off: (f64, f64)| {
            let plus = landed(3.0, tilt, 0.004, off, 5);
            let minus = run(-3.0, tilt, 0.004, 6);
            read_pair(&plus, &minus, Some(Z_MM))
        };
        let (exact, off) = (read((0.0, 0.0)), read((0.03, -0.04)));
        // A closure of 0.05 px is a scatter of 0.05/√12 per component.
        assert!(
            exact.landing_scatter_px < 1e-3,
            "{}",
            exact.landing_scatter_px
        );
        assert!(
            (off.landing_scatter_px - 0.05 / 12f64.sqrt()).abs() < 1e-3,
            "{}",
            off.landing_scatter_px
        );
        assert!(off.stage_angle_se_rad > 10.0 * exact.stage_angle_se_rad);
        // The landing moves the angle, not the tilt: the runs' constants are nuisances.
        assert!(
            (off.tilt_about_y_rad - exact.tilt_about_y_rad).abs() < 3.0 * exact.tilt_about_y_se_rad
        );
        assert!((off.stage_angle_rad - 0.004).abs() < 3.0 * off.stage_angle_se_rad);
    }

    #[test]
    fn one_direction_alone_is_refused() {
        let plus = run(3.0, (0.0, 0.0), 0.0, 1);
        let runs = [ReadoutRun {
            commanded_mm: (3.0, 0.0),
            dic: &plus,
        }];
        assert_eq!(
            read_perpendicularity(&runs, &setting(None)).unwrap_err(),
            ReadoutError::Moves(1)
        );
    }
}
