//! The GenICam (SFNC) features this driver uses, resolved once per camera with their fallbacks.
//!
//! Names are looked up here and nowhere else: cameras differ (older GigE models have
//! `ExposureTimeAbs` and `GainRaw` instead of SFNC's `ExposureTime` and `Gain`, many lack binning
//! modes or decimation), so `Features::discover` decides once which names exist and every setter
//! uses the decision.

use crate::error::ctl;
use crate::roi::{fit_roi, IntRange, RoiLimits};
use crate::unpack::{from_genicam_name, genicam_name};
use aravis::prelude::*;
use aravis::Camera;
use ffdic_hw::{BinningDomain, BinningMode, ReductionCaps};
use ffdic_hw::{HwError, HwResult, PixelFormat, SensorRoi, TriggerMode};

/// Where exposure time lives (both in µs).
const EXPOSURE_NAMES: [&str; 2] = ["ExposureTime", "ExposureTimeAbs"];
/// Gains in dB, SFNC first.
const GAIN_DB_NAMES: [&str; 2] = ["Gain", "GainAbs"];
const GAIN_RAW: &str = "GainRaw";

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum GainFeature {
    /// A float feature in dB.
    Db(&'static str),
    /// Vendor units only: no way to convert dB, so only the minimum (unity gain) is offered.
    Raw,
}

/// One horizontal/vertical pair of integer features (binning, decimation) and its limits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct AxisPair {
    pub horizontal: &'static str,
    pub vertical: &'static str,
    pub max: (u32, u32),
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Features {
    pub exposure: &'static str,
    pub gain: Option<GainFeature>,
    pub pixel_formats: Vec<PixelFormat>,
    pub binning: Option<AxisPair>,
    pub binning_mode: Option<BinningMode>,
    pub decimation: Option<AxisPair>,
    pub software_trigger: bool,
}

fn available(cam: &Camera, name: &str) -> bool {
    // Unknown nodes come back as an error or as `false`; both mean "not here".
    cam.is_feature_available(name).unwrap_or(false)
}

fn axis_pair(cam: &Camera, horizontal: &'static str, vertical: &'static str) -> Option<AxisPair> {
    if !available(cam, horizontal) || !available(cam, vertical) {
        return None;
    }
    let max = |name| {
        cam.integer_bounds(name)
            .map(|(_, max)| max.clamp(1, u32::MAX as i64) as u32)
            .unwrap_or(1)
    };
    Some(AxisPair {
        horizontal,
        vertical,
        max: (max(horizontal), max(vertical)),
    })
    .filter(|p| p.max.0 > 1 || p.max.1 > 1)
}

fn enum_entries(cam: &Camera, feature: &str) -> Vec<String> {
    cam.dup_available_enumerations_as_strings(feature)
        .map(|v| v.into_iter().map(|s| s.to_string()).collect())
        .unwrap_or_default()
}

impl Features {
    pub fn discover(cam: &Camera) -> HwResult<Self> {
        let exposure = EXPOSURE_NAMES
            .into_iter()
            .find(|n| available(cam, n))
            .ok_or_else(|| HwError::Unsupported("no ExposureTime or ExposureTimeAbs".into()))?;
        let gain = GAIN_DB_NAMES
            .into_iter()
            .find(|n| available(cam, n))
            .map(GainFeature::Db)
            .or_else(|| available(cam, GAIN_RAW).then_some(GainFeature::Raw));
        let pixel_formats = ctl("list PixelFormat", || {
            cam.dup_available_pixel_formats_as_strings()
        })?
        .iter()
        .filter_map(|s| from_genicam_name(s.as_str()))
        .collect::<Vec<_>>();
        if pixel_formats.is_empty() {
            return Err(HwError::Unsupported(
                "no Mono8/Mono10/Mono12/Mono16 pixel format".into(),
            ));
        }
        let binning = axis_pair(cam, "BinningHorizontal", "BinningVertical");
        let binning_mode = binning.map(|_| {
            let entries = enum_entries(cam, "BinningHorizontalMode");
            if entries.iter().any(|e| e == "Average") {
                BinningMode::Average
            } else if entries.iter().any(|e| e == "Sum") {
                BinningMode::Sum
            } else {
                BinningMode::VendorDefault
            }
        });
        let decimation = axis_pair(cam, "DecimationHorizontal", "DecimationVertical");
        Ok(Self {
            exposure,
            gain,
            pixel_formats,
            binning,
            binning_mode,
            decimation,
            software_trigger: available(cam, "TriggerSoftware"),
        })
    }

    pub fn reduction_caps(&self) -> ReductionCaps {
        ReductionCaps {
            binning_max: self.binning.map_or((1, 1), |p| p.max),
            binning_mode: self.binning_mode,
            // GenICam's SFNC has no feature saying where the sensor bins.
            binning_domain: BinningDomain::Unknown,
            decimation_max: self.decimation.map_or((1, 1), |p| p.max),
        }
    }

    pub fn set_exposure_us(&self, cam: &Camera, exposure_us: f64) -> HwResult<f64> {
        let name = self.exposure;
        let (min, max) = ctl("read exposure bounds", || cam.float_bounds(name))?;
        if !(exposure_us >= min && exposure_us <= max) {
            return Err(HwError::OutOfRange {
                what: "exposure_us".into(),
                value: exposure_us,
                min,
                max,
            });
        }
        ctl("set exposure", || cam.set_float(name, exposure_us))?;
        ctl("read exposure", || cam.float(name))
    }

    pub fn exposure_us(&self, cam: &Camera) -> HwResult<f64> {
        ctl("read exposure", || cam.float(self.exposure))
    }

    pub fn set_gain_db(&self, cam: &Camera, gain_db: f64) -> HwResult<f64> {
        match self.gain {
            Some(GainFeature::Db(name)) => {
                let (min, max) = ctl("read gain bounds", || cam.float_bounds(name))?;
                if !(gain_db >= min && gain_db <= max) {
                    return Err(HwError::OutOfRange {
                        what: "gain_db".into(),
                        value: gain_db,
                        min,
                        max,
                    });
                }
                ctl("set gain", || cam.set_float(name, gain_db))?;
                ctl("read gain", || cam.float(name))
            }
            Some(GainFeature::Raw) if gain_db == 0.0 => {
                // The raw minimum is the camera's unity gain; other raw values have no dB scale.
                let (min, _) = ctl("read GainRaw bounds", || cam.integer_bounds(GAIN_RAW))?;
                ctl("set GainRaw", || cam.set_integer(GAIN_RAW, min))?;
                Ok(0.0)
            }
            Some(GainFeature::Raw) => Err(HwError::Unsupported(format!(
                "gain of {gain_db} dB: this camera has GainRaw only (vendor units), use 0 dB"
            ))),
            None if gain_db == 0.0 => Ok(0.0),
            None => Err(HwError::Unsupported("gain: the camera has none".into())),
        }
    }

    pub fn gain_db(&self, cam: &Camera) -> HwResult<f64> {
        match self.gain {
            Some(GainFeature::Db(name)) => ctl("read gain", || cam.float(name)),
            _ => Ok(0.0),
        }
    }

    pub fn set_pixel_format(&self, cam: &Camera, format: PixelFormat) -> HwResult<PixelFormat> {
        if !self.pixel_formats.contains(&format) {
            return Err(HwError::Unsupported(format!(
                "pixel format {}",
                genicam_name(format)
            )));
        }
        ctl("set PixelFormat", || {
            cam.set_pixel_format_from_string(genicam_name(format))
        })?;
        self.pixel_format(cam)
    }

    pub fn pixel_format(&self, cam: &Camera) -> HwResult<PixelFormat> {
        let name = ctl("read PixelFormat", || cam.pixel_format_as_string())?;
        from_genicam_name(name.as_str())
            .ok_or_else(|| HwError::Protocol(format!("camera reports pixel format {name}")))
    }

    /// Sets one binning/decimation pair; (1, 1) on a camera without it is fine.
    fn set_pair(
        cam: &Camera,
        pair: Option<AxisPair>,
        what: &str,
        factor: (u32, u32),
    ) -> HwResult<(u32, u32)> {
        let Some(p) = pair else {
            return match factor {
                (1, 1) => Ok((1, 1)),
                _ => Err(HwError::Unsupported(format!("hardware {what}"))),
            };
        };
        for (name, f, max) in [
            (p.horizontal, factor.0, p.max.0),
            (p.vertical, factor.1, p.max.1),
        ] {
            if f < 1 || f > max {
                return Err(HwError::OutOfRange {
                    what: name.into(),
                    value: f as f64,
                    min: 1.0,
                    max: max as f64,
                });
            }
            ctl(name, || cam.set_integer(name, f as i64))?;
        }
        let h = ctl(p.horizontal, || cam.integer(p.horizontal))?;
        let v = ctl(p.vertical, || cam.integer(p.vertical))?;
        Ok((h as u32, v as u32))
    }

    /// Binning (averaging where the camera can) and decimation; returns what the camera set.
    pub fn set_reduction(
        &self,
        cam: &Camera,
        binning: (u32, u32),
        decimation: (u32, u32),
    ) -> HwResult<((u32, u32), (u32, u32))> {
        if binning != (1, 1) && self.binning_mode == Some(BinningMode::Average) {
            // Averaging keeps the grey scale of the full-resolution image (the ff100 analogue).
            for name in ["BinningHorizontalMode", "BinningVerticalMode"] {
                if available(cam, name) {
                    ctl(name, || cam.set_string(name, "Average"))?;
                }
            }
        }
        let b = Self::set_pair(cam, self.binning, "binning", binning)?;
        let d = Self::set_pair(cam, self.decimation, "decimation", decimation)?;
        Ok((b, d))
    }

    pub fn reduction(&self, cam: &Camera) -> HwResult<((u32, u32), (u32, u32))> {
        let read = |p: Option<AxisPair>| -> HwResult<(u32, u32)> {
            match p {
                None => Ok((1, 1)),
                Some(p) => Ok((
                    ctl(p.horizontal, || cam.integer(p.horizontal))? as u32,
                    ctl(p.vertical, || cam.integer(p.vertical))? as u32,
                )),
            }
        };
        Ok((read(self.binning)?, read(self.decimation)?))
    }

    fn int_range(cam: &Camera, name: &str) -> HwResult<IntRange> {
        let (min, max) = ctl(name, || cam.integer_bounds(name))?;
        let inc = cam.integer_increment(name).unwrap_or(1).max(1);
        Ok(IntRange { min, max, inc })
    }

    /// Sets the region (sensor px; `None` = whole sensor) once binning/decimation are set.
    pub fn set_roi(
        &self,
        cam: &Camera,
        roi: Option<SensorRoi>,
        factor: (u32, u32),
    ) -> HwResult<SensorRoi> {
        // Offsets first to zero, so Width/Height may span the whole sensor, then sizes, then
        // the real offsets: the order that never leaves the camera in an invalid state.
        ctl("OffsetX", || cam.set_integer("OffsetX", 0))?;
        ctl("OffsetY", || cam.set_integer("OffsetY", 0))?;
        let limits = RoiLimits {
            width: Self::int_range(cam, "Width")?,
            height: Self::int_range(cam, "Height")?,
            offset_x_inc: cam.integer_increment("OffsetX").unwrap_or(1),
            offset_y_inc: cam.integer_increment("OffsetY").unwrap_or(1),
            factor,
        };
        let out = fit_roi(roi, &limits)?;
        ctl("Width", || cam.set_integer("Width", out.width))?;
        ctl("Height", || cam.set_integer("Height", out.height))?;
        ctl("OffsetX", || cam.set_integer("OffsetX", out.x))?;
        ctl("OffsetY", || cam.set_integer("OffsetY", out.y))?;
        self.roi(cam, factor)
    }

    pub fn roi(&self, cam: &Camera, factor: (u32, u32)) -> HwResult<SensorRoi> {
        let (x, y, w, h) = ctl("read region", || cam.region())?;
        Ok(crate::roi::OutputRoi {
            x: x as i64,
            y: y as i64,
            width: w as i64,
            height: h as i64,
        }
        .to_sensor(factor))
    }

    pub fn set_trigger(&self, cam: &Camera, trigger: TriggerMode) -> HwResult<()> {
        match trigger {
            TriggerMode::FreeRun => ctl("clear triggers", || cam.clear_triggers()),
            TriggerMode::Software if self.software_trigger => {
                ctl("set software trigger", || cam.set_trigger("Software"))
            }
            TriggerMode::Software => Err(HwError::Unsupported("software trigger".into())),
        }
    }
}
