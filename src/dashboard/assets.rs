//! The dashboard's files, compiled into the binary.

pub const HOME_HTML: &str = include_str!("assets/home.html");
pub const EXPERIMENT_HTML: &str = include_str!("assets/experiment.html");
pub const DATASET_HTML: &str = include_str!("assets/dataset.html");
pub const SWEEP_HTML: &str = include_str!("assets/sweep.html");
pub const CALIBRATION_HTML: &str = include_str!("assets/calibration.html");

/// Every asset under `/assets/`: name and bytes.
pub const ALL: [(&str, &[u8]); 9] = [
    ("style.css", include_bytes!("assets/style.css")),
    ("common.js", include_bytes!("assets/common.js")),
    ("charts.js", include_bytes!("assets/charts.js")),
    ("home.js", include_bytes!("assets/home.js")),
    ("experiment.js", include_bytes!("assets/experiment.js")),
    ("dataset.js", include_bytes!("assets/dataset.js")),
    ("sweep.js", include_bytes!("assets/sweep.js")),
    ("calibration.js", include_bytes!("assets/calibration.js")),
    ("favicon.svg", include_bytes!("assets/favicon.svg")),
];

/// The asset called `name` with its media type.
pub fn find(name: &str) -> Option<(&'static [u8], &'static str)> {
    let (_, bytes) = ALL.iter().find(|(n, _)| *n == name)?;
    let mime = match name.rsplit('.').next() {
        Some("css") => "text/css; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        Some("svg") => "image/svg+xml",
        _ => "application/octet-stream",
    };
    Some((bytes, mime))
}
