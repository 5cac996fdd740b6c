//! Hardware binning and decimation described as fill-factor schemes, so an experiment can capture
//! them beside the synthesised ones (`src/reduce` of the root crate). Every camera driver
//! describes what its sensor can do with [`ReductionCaps`]; [`schemes_for`] names the schemes.
//!
//! Geometry per axis, as in `src/reduce`: a block of `factor` sensor pixels becomes one output
//! pixel. Averaging binning integrates the whole block, like the synthesised `ff100` (100 % linear
//! fill); decimation keeps one pixel of each block, like `ff25` for 2x2 (50 % linear fill per
//! axis); vertical binning with horizontal decimation is `ff50`. Summing binning has the same
//! geometry as averaging, only the grey scale differs (and saturates sooner).
//!
//! Names are `hw:` and the reduction: `hw:bin2x2-average`, `hw:dec2x2`, `hw:dec2-bin2-average`
//! (decimate x, bin y). The `hw:` prefix keeps them apart from the synthesised schemes' names.

use crate::CameraSettings;
use serde::{Deserialize, Serialize};

/// How the camera combines the pixels of a binning block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BinningMode {
    Average,
    Sum,
    /// The camera has no `Binning*Mode` feature: whatever its vendor does (usually summing).
    VendorDefault,
}

/// Where the sensor combines the pixels of a binning block: before the read-out (charge binning,
/// one read noise per binned pixel) or after it (digital binning, one read noise per pixel).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BinningDomain {
    Charge,
    Digital,
    /// The camera does not say (GenICam has no standard feature for it).
    Unknown,
}

/// What the hardware does along one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum AxisReduction {
    Bin { factor: u32, mode: BinningMode },
    Decimate { factor: u32 },
}

impl AxisReduction {
    pub fn factor(self) -> u32 {
        match self {
            AxisReduction::Bin { factor, .. } | AxisReduction::Decimate { factor } => factor,
        }
    }

    /// Sensor pixels of each block that reach the output pixel.
    pub fn active_px(self) -> u32 {
        match self {
            AxisReduction::Bin { factor, .. } => factor,
            AxisReduction::Decimate { .. } => 1,
        }
    }

    /// Linear fill factor of the output pixel along this axis.
    pub fn linear_fill(self) -> f64 {
        self.active_px() as f64 / self.factor() as f64
    }
}

/// One hardware reduction the camera offers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HardwareScheme {
    /// e.g. `hw:bin2x2-average`, `hw:dec2x2`, `hw:dec2-bin2-average`.
    pub name: String,
    pub x: AxisReduction,
    pub y: AxisReduction,
    /// Where binning combines the pixels; `None` when the scheme bins nothing.
    pub binning_domain: Option<BinningDomain>,
    /// The synthesised preset with the same geometry, when there is one.
    pub equivalent_preset: Option<String>,
    /// Area fill factor of an output pixel (x × y linear fill).
    pub fill_factor: f64,
}

/// The prefix of every hardware scheme's name.
pub const HARDWARE_SCHEME_PREFIX: &str = "hw:";

impl HardwareScheme {
    fn new(x: AxisReduction, y: AxisReduction, domain: BinningDomain) -> Self {
        let name = match (x, y) {
            (AxisReduction::Bin { factor: fx, mode }, AxisReduction::Bin { factor: fy, .. }) => {
                format!("hw:bin{fx}x{fy}-{}", mode_name(mode))
            }
            (AxisReduction::Decimate { factor: fx }, AxisReduction::Decimate { factor: fy }) => {
                format!("hw:dec{fx}x{fy}")
            }
            (AxisReduction::Decimate { factor: fx }, AxisReduction::Bin { factor: fy, mode }) => {
                format!("hw:dec{fx}-bin{fy}-{}", mode_name(mode))
            }
            (AxisReduction::Bin { factor: fx, mode }, AxisReduction::Decimate { factor: fy }) => {
                format!("hw:bin{fx}-{}-dec{fy}", mode_name(mode))
            }
        };
        let equivalent_preset = match (x, y) {
            (AxisReduction::Bin { factor: 2, .. }, AxisReduction::Bin { factor: 2, .. }) => {
                Some("ff100".to_string())
            }
            (AxisReduction::Decimate { factor: 2 }, AxisReduction::Bin { factor: 2, .. }) => {
                Some("ff50".to_string())
            }
            (AxisReduction::Decimate { factor: 2 }, AxisReduction::Decimate { factor: 2 }) => {
                Some("ff25".to_string())
            }
            _ => None,
        };
        let bins = matches!(x, AxisReduction::Bin { .. }) || matches!(y, AxisReduction::Bin { .. });
        Self {
            name,
            x,
            y,
            binning_domain: bins.then_some(domain),
            equivalent_preset,
            fill_factor: x.linear_fill() * y.linear_fill(),
        }
    }

    /// The `CameraSettings` (binning, decimation) pairs that select this scheme.
    pub fn settings(&self) -> ((u32, u32), (u32, u32)) {
        let split = |a: AxisReduction| match a {
            AxisReduction::Bin { factor, .. } => (factor, 1),
            AxisReduction::Decimate { factor } => (1, factor),
        };
        let (bx, dx) = split(self.x);
        let (by, dy) = split(self.y);
        ((bx, by), (dx, dy))
    }

    /// `base` with this scheme's binning and decimation (everything else kept).
    pub fn applied_to(&self, base: &CameraSettings) -> CameraSettings {
        let (binning, decimation) = self.settings();
        CameraSettings {
            binning,
            decimation,
            ..base.clone()
        }
    }

    /// Whether `settings` select this scheme (what a camera read back after `apply`).
    pub fn is_selected_by(&self, settings: &CameraSettings) -> bool {
        (settings.binning, settings.decimation) == self.settings()
    }

    /// The scheme's name as part of a file name: `hw:bin2x2-average` → `hw-bin2x2-average`.
    pub fn file_stem(&self) -> String {
        self.name.replace(':', "-")
    }

    /// The binning mode, when the scheme bins.
    pub fn binning_mode(&self) -> Option<BinningMode> {
        [self.x, self.y].into_iter().find_map(|a| match a {
            AxisReduction::Bin { mode, .. } => Some(mode),
            AxisReduction::Decimate { .. } => None,
        })
    }
}

fn mode_name(mode: BinningMode) -> &'static str {
    match mode {
        BinningMode::Average => "average",
        BinningMode::Sum => "sum",
        BinningMode::VendorDefault => "vendor",
    }
}

/// What the camera can reduce in hardware: largest factor per axis (1 = not available).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReductionCaps {
    pub binning_max: (u32, u32),
    /// `None` when the camera has no binning at all.
    pub binning_mode: Option<BinningMode>,
    pub binning_domain: BinningDomain,
    pub decimation_max: (u32, u32),
}

impl Default for ReductionCaps {
    /// No hardware reduction at all.
    fn default() -> Self {
        Self {
            binning_max: (1, 1),
            binning_mode: None,
            binning_domain: BinningDomain::Unknown,
            decimation_max: (1, 1),
        }
    }
}

/// The schemes worth offering: square binning and decimation of 2, 3 and 4, and the paper's
/// mixed `ff50` geometry (decimate x, bin y) when both exist.
pub fn schemes_for(caps: &ReductionCaps) -> Vec<HardwareScheme> {
    let mut out = Vec::new();
    let domain = caps.binning_domain;
    if let Some(mode) = caps.binning_mode {
        for f in 2..=4 {
            if f <= caps.binning_max.0 && f <= caps.binning_max.1 {
                out.push(HardwareScheme::new(
                    AxisReduction::Bin { factor: f, mode },
                    AxisReduction::Bin { factor: f, mode },
                    domain,
                ));
            }
        }
        if caps.decimation_max.0 >= 2 && caps.binning_max.1 >= 2 {
            out.push(HardwareScheme::new(
                AxisReduction::Decimate { factor: 2 },
                AxisReduction::Bin { factor: 2, mode },
                domain,
            ));
        }
    }
    for f in 2..=4 {
        if f <= caps.decimation_max.0 && f <= caps.decimation_max.1 {
            out.push(HardwareScheme::new(
                AxisReduction::Decimate { factor: f },
                AxisReduction::Decimate { factor: f },
                domain,
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_hardware_reduction_offers_nothing() {
        assert!(schemes_for(&ReductionCaps::default()).is_empty());
    }

    #[test]
    fn averaging_binning_and_decimation_map_to_the_paper_presets() {
        let caps = ReductionCaps {
            binning_max: (2, 2),
            binning_mode: Some(BinningMode::Average),
            binning_domain: BinningDomain::Digital,
            decimation_max: (2, 2),
        };
        let s = schemes_for(&caps);
        let names: Vec<_> = s.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            ["hw:bin2x2-average", "hw:dec2-bin2-average", "hw:dec2x2"]
        );
        let presets: Vec<_> = s.iter().map(|s| s.equivalent_preset.as_deref()).collect();
        assert_eq!(presets, [Some("ff100"), Some("ff50"), Some("ff25")]);
        let domains: Vec<_> = s.iter().map(|s| s.binning_domain).collect();
        let digital = Some(BinningDomain::Digital);
        assert_eq!(domains, [digital, digital, None]);
        assert_eq!(s[0].file_stem(), "hw-bin2x2-average");
        let fills: Vec<_> = s.iter().map(|s| s.fill_factor).collect();
        assert_eq!(fills, [1.0, 0.5, 0.25]);
        assert_eq!(s[0].settings(), ((2, 2), (1, 1)));
        assert_eq!(s[1].settings(), ((1, 2), (2, 1)));
        assert_eq!(s[2].settings(), ((1, 1), (2, 2)));
    }

    #[test]
    fn larger_factors_follow_the_smaller_axis_limit() {
        let caps = ReductionCaps {
            binning_max: (4, 3),
            binning_mode: Some(BinningMode::VendorDefault),
            binning_domain: BinningDomain::Unknown,
            decimation_max: (1, 1),
        };
        let names: Vec<_> = schemes_for(&caps).into_iter().map(|s| s.name).collect();
        assert_eq!(names, ["hw:bin2x2-vendor", "hw:bin3x3-vendor"]);
    }
}

#[cfg(test)]
mod settings_tests {
    use super::*;

    #[test]
    fn a_scheme_selects_and_recognises_its_settings() {
        let caps = ReductionCaps {
            binning_max: (2, 2),
            binning_mode: Some(BinningMode::Sum),
            binning_domain: BinningDomain::Charge,
            decimation_max: (2, 2),
        };
        let base = CameraSettings {
            exposure_us: 123.0,
            ..CameraSettings::default()
        };
        for scheme in schemes_for(&caps) {
            let s = scheme.applied_to(&base);
            assert_eq!(s.exposure_us, 123.0);
            assert!(scheme.is_selected_by(&s), "{}", scheme.name);
            assert!(!scheme.is_selected_by(&base), "{}", scheme.name);
        }
        let text = serde_json::to_string(&schemes_for(&caps)[1]).unwrap();
        let back: HardwareScheme = serde_json::from_str(&text).unwrap();
        assert_eq!(back, schemes_for(&caps)[1]);
        assert_eq!(back.binning_mode(), Some(BinningMode::Sum));
    }
}
