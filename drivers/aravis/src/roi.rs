//! Fitting a requested sensor region to what GenICam's OffsetX/OffsetY/Width/Height accept.
//!
//! `SensorRoi` is in sensor pixels; the GenICam features count output pixels, i.e. after binning or
//! decimation by `factor`. Values are rounded down to the feature increments (a camera refuses
//! anything else), and the region the camera really uses is reported back in sensor pixels.

use ffdic_hw::{HwError, SensorRoi};

/// Range and increment of one integer feature, in output pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntRange {
    pub min: i64,
    pub max: i64,
    pub inc: i64,
}

/// What the camera allows for a region once binning/decimation are set and the offsets are zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RoiLimits {
    /// Width and height with zero offsets: `max` is the whole (binned) sensor.
    pub width: IntRange,
    pub height: IntRange,
    pub offset_x_inc: i64,
    pub offset_y_inc: i64,
    /// Binning × decimation per axis (sensor px per output px).
    pub factor: (u32, u32),
}

/// A region in output pixels, ready for OffsetX/OffsetY/Width/Height.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputRoi {
    pub x: i64,
    pub y: i64,
    pub width: i64,
    pub height: i64,
}

impl OutputRoi {
    /// The same region in sensor pixels.
    pub fn to_sensor(self, factor: (u32, u32)) -> SensorRoi {
        SensorRoi {
            x: (self.x * factor.0 as i64) as u32,
            y: (self.y * factor.1 as i64) as u32,
            width: (self.width * factor.0 as i64) as u32,
            height: (self.height * factor.1 as i64) as u32,
        }
    }
}

fn snap_down(v: i64, inc: i64) -> i64 {
    let inc = inc.max(1);
    v - v.rem_euclid(inc)
}

/// One axis: start and length in sensor px → output px, rounded down to the increments.
fn fit_axis(
    what: &str,
    start_px: u32,
    len_px: u32,
    factor: u32,
    len: IntRange,
    offset_inc: i64,
) -> Result<(i64, i64), HwError> {
    let factor = factor.max(1) as i64;
    let start = snap_down(start_px as i64 / factor, offset_inc);
    let length = snap_down(len_px as i64 / factor, len.inc);
    if length < len.min {
        return Err(HwError::OutOfRange {
            what: format!("ROI {what} (sensor px)"),
            value: len_px as f64,
            min: (len.min * factor) as f64,
            max: (len.max * factor) as f64,
        });
    }
    if start + length > len.max {
        return Err(HwError::OutOfRange {
            what: format!("ROI end along {what} (sensor px)"),
            value: (start_px as i64 + len_px as i64) as f64,
            min: (len.min * factor) as f64,
            max: (len.max * factor) as f64,
        });
    }
    Ok((start, length))
}

/// The output-pixel region for `roi` (`None`: the whole sensor).
pub fn fit_roi(roi: Option<SensorRoi>, limits: &RoiLimits) -> Result<OutputRoi, HwError> {
    let (fx, fy) = limits.factor;
    let full = SensorRoi {
        x: 0,
        y: 0,
        width: (limits.width.max * fx.max(1) as i64) as u32,
        height: (limits.height.max * fy.max(1) as i64) as u32,
    };
    let r = roi.unwrap_or(full);
    let (x, width) = fit_axis("width", r.x, r.width, fx, limits.width, limits.offset_x_inc)?;
    let (y, height) = fit_axis(
        "height",
        r.y,
        r.height,
        fy,
        limits.height,
        limits.offset_y_inc,
    )?;
    Ok(OutputRoi {
        x,
        y,
        width,
        height,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(factor: (u32, u32)) -> RoiLimits {
        RoiLimits {
            width: IntRange {
                min: 16,
                max: 2048 / factor.0 as i64,
                inc: 8,
            },
            height: IntRange {
                min: 8,
                max: 1536 / factor.1 as i64,
                inc: 2,
            },
            offset_x_inc: 4,
            offset_y_inc: 2,
            factor,
        }
    }

    #[test]
    fn no_roi_is_the_whole_sensor() {
        let r = fit_roi(None, &limits((1, 1))).unwrap();
        assert_eq!(
            r,
            OutputRoi {
                x: 0,
                y: 0,
                width: 2048,
                height: 1536
            }
        );
        let b = fit_roi(None, &limits((2, 2))).unwrap();
        assert_eq!((b.width, b.height), (1024, 768));
        assert_eq!(b.to_sensor((2, 2)).width, 2048);
    }

    #[test]
    fn values_round_down_to_increments() {
        let roi = SensorRoi {
            x: 103,
            y: 51,
            width: 645,
            height: 481,
        };
        let r = fit_roi(Some(roi), &limits((1, 1))).unwrap();
        assert_eq!(
            r,
            OutputRoi {
                x: 100,
                y: 50,
                width: 640,
                height: 480
            }
        );
    }

    #[test]
    fn binning_divides_sensor_pixels() {
        let roi = SensorRoi {
            x: 200,
            y: 100,
            width: 640,
            height: 480,
        };
        let r = fit_roi(Some(roi), &limits((2, 2))).unwrap();
        assert_eq!(
            r,
            OutputRoi {
                x: 100,
                y: 50,
                width: 320,
                height: 240
            }
        );
        assert_eq!(r.to_sensor((2, 2)), roi);
    }

    #[test]
    fn regions_outside_the_sensor_or_too_small_are_out_of_range() {
        let past_edge = SensorRoi {
            x: 2000,
            y: 0,
            width: 64,
            height: 64,
        };
        assert!(matches!(
            fit_roi(Some(past_edge), &limits((1, 1))),
            Err(HwError::OutOfRange { .. })
        ));
        let tiny = SensorRoi {
            x: 0,
            y: 0,
            width: 8,
            height: 64,
        };
        assert!(matches!(
            fit_roi(Some(tiny), &limits((1, 1))),
            Err(HwError::OutOfRange { .. })
        ));
    }
}
