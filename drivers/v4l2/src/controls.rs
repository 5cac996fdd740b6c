//! Exposure and gain: V4L2 control ids, ranges, and the conversion from ffdic's units.
//!
//! - Exposure: V4L2_CID_EXPOSURE_ABSOLUTE is in units of 100 µs (V4L2 UAPI "Camera Control
//!   Reference"); it only takes effect with V4L2_CID_EXPOSURE_AUTO at V4L2_EXPOSURE_MANUAL (1).
//! - Gain: V4L2_CID_ANALOGUE_GAIN ("Image Source Control Reference": applied before the ADC) is
//!   preferred over V4L2_CID_GAIN ("User Controls": on most devices a digital gain). Both are in
//!   device units the spec leaves undefined — neither dB nor a factor. A `GainCalibration` from the
//!   config maps dB onto them, assuming the device is linear in dB (true of the common Sony and
//!   onsemi sensor registers, false of sensors whose gain register is a linear factor: calibrate
//!   those over the range you use). Without a calibration only 0 dB is accepted, meaning the
//!   control's minimum, the lowest gain the device has.

use ffdic_hw::{HwError, HwResult};
use serde::{Deserialize, Serialize};

pub const CID_EXPOSURE_AUTO: u32 = 0x009a_0901;
pub const CID_EXPOSURE_ABSOLUTE: u32 = 0x009a_0902;
pub const CID_GAIN: u32 = 0x0098_0913;
pub const CID_ANALOGUE_GAIN: u32 = 0x009e_0903;
/// `V4L2_EXPOSURE_MANUAL` of the `v4l2_exposure_auto_type` menu.
pub const EXPOSURE_MANUAL: i64 = 1;
/// One V4L2_CID_EXPOSURE_ABSOLUTE unit.
pub const EXPOSURE_UNIT_US: f64 = 100.0;

/// What VIDIOC_QUERY_EXT_CTRL says an integer control accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ControlRange {
    pub min: i64,
    pub max: i64,
    /// Values are `min + k · step`; 0 from a driver is read as 1.
    pub step: u64,
    pub default: i64,
}

impl ControlRange {
    /// The accepted value nearest to `value` (device units), or `None` outside [min, max].
    pub fn nearest(&self, value: f64) -> Option<i64> {
        if !value.is_finite() || value < self.min as f64 || value > self.max as f64 {
            return None;
        }
        let step = self.step.max(1) as f64;
        let k = ((value - self.min as f64) / step).round();
        let mut v = self.min as f64 + k * step;
        if v > self.max as f64 {
            v -= step;
        }
        Some((v as i64).clamp(self.min, self.max))
    }
}

/// The device value for `exposure_us`, rounded to the control's grid.
pub fn exposure_to_device(exposure_us: f64, range: &ControlRange) -> HwResult<i64> {
    range
        .nearest(exposure_us / EXPOSURE_UNIT_US)
        .filter(|_| exposure_us > 0.0)
        .ok_or_else(|| HwError::OutOfRange {
            what: "exposure_us".into(),
            value: exposure_us,
            min: range.min.max(1) as f64 * EXPOSURE_UNIT_US,
            max: range.max as f64 * EXPOSURE_UNIT_US,
        })
}

pub fn exposure_from_device(value: i64) -> f64 {
    value as f64 * EXPOSURE_UNIT_US
}

/// Device gain units against dB, linear in dB: `units = unit_at_0_db + gain_db / db_per_unit`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainCalibration {
    /// dB per device unit (e.g. 0.1 for a register in 0.1 dB steps, 0.3 for 0.3 dB steps).
    pub db_per_unit: f64,
    /// The device value of unity gain (0 dB).
    pub unit_at_0_db: i64,
}

impl GainCalibration {
    pub fn validate(&self) -> HwResult<()> {
        if self.db_per_unit.is_finite() && self.db_per_unit > 0.0 {
            Ok(())
        } else {
            Err(HwError::OutOfRange {
                what: "gain.db_per_unit".into(),
                value: self.db_per_unit,
                min: f64::MIN_POSITIVE,
                max: f64::MAX,
            })
        }
    }

    pub fn to_device(&self, gain_db: f64, range: &ControlRange) -> HwResult<i64> {
        range
            .nearest(self.unit_at_0_db as f64 + gain_db / self.db_per_unit)
            .ok_or_else(|| HwError::OutOfRange {
                what: "gain_db".into(),
                value: gain_db,
                min: self.from_device(range.min),
                max: self.from_device(range.max),
            })
    }

    pub fn from_device(&self, value: i64) -> f64 {
        (value - self.unit_at_0_db) as f64 * self.db_per_unit
    }
}

/// The device gain value for `gain_db`, and the dB it really means.
pub fn gain_to_device(
    gain_db: f64,
    range: &ControlRange,
    calibration: Option<&GainCalibration>,
) -> HwResult<(i64, f64)> {
    match calibration {
        Some(c) => {
            let v = c.to_device(gain_db, range)?;
            Ok((v, c.from_device(v)))
        }
        None if gain_db == 0.0 => Ok((range.min, 0.0)),
        None => Err(HwError::Unsupported(format!(
            "gain_db = {gain_db}: V4L2 gain is in device units ({}..={}); \
             set [camera.v4l2.gain] db_per_unit and unit_at_0_db to use dB",
            range.min, range.max
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXPOSURE: ControlRange = ControlRange {
        min: 1,
        max: 5000,
        step: 1,
        default: 156,
    };

    #[test]
    fn control_ids_are_the_videodev2_values() {
        // V4L2_CID_CAMERA_CLASS_BASE + 1 and + 2, V4L2_CID_BASE + 19,
        // V4L2_CID_IMAGE_SOURCE_CLASS_BASE + 3.
        assert_eq!(CID_EXPOSURE_AUTO, 0x009a0900 + 1);
        assert_eq!(CID_EXPOSURE_ABSOLUTE, 0x009a0900 + 2);
        assert_eq!(CID_GAIN, 0x00980900 + 19);
        assert_eq!(CID_ANALOGUE_GAIN, 0x009e0900 + 3);
    }

    #[test]
    fn exposure_is_in_units_of_100_us_and_rounds() {
        assert_eq!(exposure_to_device(10_000.0, &EXPOSURE).unwrap(), 100);
        assert_eq!(exposure_to_device(149.0, &EXPOSURE).unwrap(), 1);
        assert_eq!(exposure_to_device(150.0, &EXPOSURE).unwrap(), 2);
        assert_eq!(exposure_to_device(33_333.0, &EXPOSURE).unwrap(), 333);
        assert_eq!(exposure_from_device(333), 33_300.0);
        assert_eq!(exposure_from_device(1), 100.0);
    }

    #[test]
    fn exposure_outside_the_range_names_it_in_us() {
        let e = exposure_to_device(50.0, &EXPOSURE).unwrap_err();
        assert_eq!(
            e,
            HwError::OutOfRange {
                what: "exposure_us".into(),
                value: 50.0,
                min: 100.0,
                max: 500_000.0
            }
        );
        assert!(exposure_to_device(600_000.0, &EXPOSURE).is_err());
        assert!(exposure_to_device(f64::NAN, &EXPOSURE).is_err());
        let from_zero = ControlRange { min: 0, ..EXPOSURE };
        assert!(exposure_to_device(0.0, &from_zero).is_err());
        assert!(exposure_to_device(-100.0, &from_zero).is_err());
    }

    #[test]
    fn nearest_follows_the_step_grid() {
        let r = ControlRange {
            min: 3,
            max: 20,
            step: 4,
            default: 3,
        };
        assert_eq!(r.nearest(3.0), Some(3));
        assert_eq!(r.nearest(4.9), Some(3));
        assert_eq!(r.nearest(5.0), Some(7));
        assert_eq!(r.nearest(20.0), Some(19));
        assert_eq!(r.nearest(2.9), None);
        assert_eq!(r.nearest(20.1), None);
        // 10 rounds to 12, past a max that is off the grid: the last grid value inside wins.
        let off_grid = ControlRange {
            min: 0,
            max: 10,
            step: 4,
            default: 0,
        };
        assert_eq!(off_grid.nearest(10.0), Some(8));
        let zero_step = ControlRange { step: 0, ..r };
        assert_eq!(zero_step.nearest(5.4), Some(5));
    }

    #[test]
    fn gain_with_a_calibration_is_linear_in_db() {
        let range = ControlRange {
            min: 0,
            max: 480,
            step: 1,
            default: 0,
        };
        let cal = GainCalibration {
            db_per_unit: 0.1,
            unit_at_0_db: 0,
        };
        let (v, db) = gain_to_device(6.0, &range, Some(&cal)).unwrap();
        assert_eq!(v, 60);
        assert!((db - 6.0).abs() < 1e-12);
        let (v, db) = gain_to_device(6.04, &range, Some(&cal)).unwrap();
        assert_eq!(v, 60);
        assert!((db - 6.0).abs() < 1e-12);
        let e = gain_to_device(49.0, &range, Some(&cal)).unwrap_err();
        assert!(
            matches!(e, HwError::OutOfRange { ref what, max, .. } if what == "gain_db" && (max - 48.0).abs() < 1e-9),
            "{e:?}"
        );
        let offset = GainCalibration {
            db_per_unit: 0.3,
            unit_at_0_db: 16,
        };
        assert_eq!(
            gain_to_device(3.0, &range, Some(&offset)).unwrap().0,
            16 + 10
        );
        assert!(gain_to_device(-6.0, &range, Some(&offset)).is_err());
    }

    #[test]
    fn gain_without_a_calibration_accepts_only_0_db() {
        let range = ControlRange {
            min: 16,
            max: 255,
            step: 1,
            default: 32,
        };
        assert_eq!(gain_to_device(0.0, &range, None).unwrap(), (16, 0.0));
        let e = gain_to_device(6.0, &range, None).unwrap_err();
        assert!(
            matches!(e, HwError::Unsupported(ref m) if m.contains("device units")),
            "{e:?}"
        );
    }

    #[test]
    fn calibrations_must_have_a_positive_slope() {
        for bad in [0.0, -0.1, f64::NAN, f64::INFINITY] {
            let c = GainCalibration {
                db_per_unit: bad,
                unit_at_0_db: 0,
            };
            assert!(c.validate().is_err(), "{bad}");
        }
    }
}
