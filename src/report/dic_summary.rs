//! One DIC analysis as JSON: its summary and its settings, as `ffdic analyze` prints and writes
//! them and the Python bindings return them.

use crate::dic::DicResult;
use serde_json::json;
use std::collections::BTreeMap;

/// Points, valid points, points per status, the statistics of u, v and the strains (mean, std
/// with its 95 % interval, min, max) and the global rigid offset.
pub fn dic_summary_json(result: &DicResult) -> serde_json::Value {
    let s = result.summary;
    json!({
        "points": s.points,
        "valid": s.valid,
        "statuses": result
            .status_counts()
            .into_iter()
            .map(|(status, n)| (status.as_str(), n))
            .collect::<BTreeMap<_, _>>(),
        "u": s.u, "v": s.v,
        "exx": s.exx, "eyy": s.eyy, "exy": s.exy,
        "global_offset_px": result.global_offset_px,
    })
}

/// Every setting that made the result: the DIC settings, the ROI and grid used, the strain
/// gauge, criterion, shape function, algorithm and ffdic version (`settings.json` of
/// `ffdic analyze --out`, without the file names).
pub fn dic_settings_json(result: &DicResult) -> serde_json::Value {
    json!({
        "dic": result.settings,
        "roi": result.grid.roi,
        "grid": { "nx": result.grid.nx(), "ny": result.grid.ny() },
        "strain_gauge_px": result.strain_gauge_px,
        "criterion": "znssd",
        "shape_function": result.settings.shape.as_str(),
        "algorithm": "icgn",
        "ffdic_version": crate::VERSION,
    })
}
