//! The summary of one DIC analysis as JSON: what `ffdic analyze --json` prints and the Python
//! bindings return.

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
