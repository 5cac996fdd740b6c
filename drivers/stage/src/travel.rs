//! Travel limits and the mm ↔ device-unit conversions all three drivers share.

use ffdic_hw::{HwError, HwResult, StageInfo, StagePosition};

/// Which axis a command concerns; also the index into a driver's axis list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Axis {
    X,
    Y,
}

impl Axis {
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
        }
    }

    pub fn of(self, p: StagePosition) -> f64 {
        match self {
            Axis::X => p.x_mm,
            Axis::Y => p.y_mm,
        }
    }
}

/// Builds the stage description; a one-axis stage has the y travel `(0, 0)`.
pub(crate) fn stage_info(
    model: String,
    x_travel_mm: (f64, f64),
    y_travel_mm: Option<(f64, f64)>,
    resolution_mm: f64,
) -> StageInfo {
    StageInfo {
        model,
        axes: if y_travel_mm.is_some() { 2 } else { 1 },
        travel_x_mm: x_travel_mm,
        travel_y_mm: y_travel_mm.unwrap_or((0.0, 0.0)),
        resolution_mm,
    }
}

/// Refuses a target outside the travel of the stage (NaN included); a one-axis stage accepts only
/// y = 0.
pub(crate) fn check_target(info: &StageInfo, target: StagePosition) -> HwResult<()> {
    for (what, v, (lo, hi)) in [
        ("x_mm", target.x_mm, info.travel_x_mm),
        ("y_mm", target.y_mm, info.travel_y_mm),
    ] {
        if !(v >= lo && v <= hi) {
            return Err(HwError::OutOfRange {
                what: what.into(),
                value: v,
                min: lo,
                max: hi,
            });
        }
    }
    Ok(())
}

/// The intersection of the configured travel and the controller's own limits.
pub(crate) fn narrow(config_mm: (f64, f64), controller_mm: (f64, f64)) -> (f64, f64) {
    (
        config_mm.0.max(controller_mm.0),
        config_mm.1.min(controller_mm.1),
    )
}

/// mm → integer device units (microsteps, encoder counts), rounded to the nearest.
pub(crate) fn to_units(mm: f64, units_per_mm: f64) -> HwResult<i64> {
    let u = (mm * units_per_mm).round();
    if !u.is_finite() || u.abs() > i32::MAX as f64 {
        return Err(HwError::OutOfRange {
            what: "position in device units".into(),
            value: u,
            min: i32::MIN as f64,
            max: i32::MAX as f64,
        });
    }
    Ok(u as i64)
}

pub(crate) fn to_mm(units: i64, units_per_mm: f64) -> f64 {
    units as f64 / units_per_mm
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_axis_stage_accepts_only_y_zero() {
        let info = stage_info("t".into(), (0.0, 25.0), None, 1e-6);
        let ok = StagePosition {
            x_mm: 25.0,
            y_mm: 0.0,
        };
        assert!(check_target(&info, ok).is_ok());
        for bad in [(25.001, 0.0), (1.0, 0.1), (f64::NAN, 0.0)] {
            let p = StagePosition {
                x_mm: bad.0,
                y_mm: bad.1,
            };
            assert!(matches!(
                check_target(&info, p),
                Err(HwError::OutOfRange { .. })
            ));
        }
    }

    #[test]
    fn units_round_trip_within_half_a_unit() {
        let u = to_units(5.25, 34_304.0).unwrap();
        assert_eq!(u, 180_096);
        assert!((to_mm(u, 34_304.0) - 5.25).abs() < 0.5 / 34_304.0);
        assert!(to_units(1e9, 34_304.0).is_err());
    }
}
