//! The capture mode of a run's frames: full resolution, or a hardware scheme (the sensor's own
//! binning or decimation) recorded in the manifest as the camera described it, so whoever reads
//! the dataset — the study, `compare`, `diagnose` — treats the frames as the sensor made them.

use crate::model::{BinnedValue, BinningDomain as ModelDomain, SensorReadout};
use ffdic_hw::{BinningDomain, BinningMode, HardwareScheme};

/// How the model reads its sensor out to render frames taken in `scheme`: the scheme's binning
/// and decimation; a summing camera sums; only a camera that says it bins charge is rendered
/// with one read noise per binned pixel (an unknown domain reads out like the synthesised
/// schemes: digitally).
pub fn sensor_readout(scheme: &HardwareScheme) -> SensorReadout {
    let ((bx, by), (dx, dy)) = scheme.settings();
    SensorReadout {
        binning: (bx as usize, by as usize),
        decimation: (dx as usize, dy as usize),
        value: match scheme.binning_mode() {
            Some(BinningMode::Sum) => BinnedValue::Sum,
            Some(BinningMode::Average | BinningMode::VendorDefault) | None => BinnedValue::Average,
        },
        domain: match scheme.binning_domain {
            Some(BinningDomain::Charge) => ModelDomain::Charge,
            Some(BinningDomain::Digital | BinningDomain::Unknown) | None => ModelDomain::Digital,
        },
    }
}
