//! A sweep as a user writes it (TOML): the sensor, the axes, the model and the DIC settings.

use super::task::REFERENCE_BLOCK_PX;
use crate::dic::DicSettings;
use crate::experiment::FieldError;
use crate::model::{Camera, SpecklePattern};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The most tasks one plan may hold (a typo in an axis should not plan a year of work).
pub const MAX_TASKS: usize = 1_000_000;
/// Realisations per cell.
pub const MAX_SEEDS: usize = 1_000;
/// The sensor's side, px (a 16384² frame is 1 GiB of f32).
pub const MIN_SENSOR_SIDE_PX: usize = 16;
pub const MAX_SENSOR_SIDE_PX: usize = 16_384;
/// The commanded move, per axis.
pub const MAX_MOVE_MM: f64 = 100.0;

/// Also the body of `POST /sweeps` (as JSON); its schema is refined in `api::request_schemas`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    pub name: String,
    /// Base seed; each realisation `k` of a cell mixes it with `k`.
    #[serde(default)]
    pub seed: u64,
    /// Speckle realisations (layout and noise) per cell.
    pub seeds: usize,
    /// The full-resolution sensor the fill factors are synthesised from.
    #[schema(value_type = Object)]
    pub camera: Camera,
    /// The imaging model's effects besides the axes' (noise and PSF come from the axes): an
    /// embedded or stored model's name (`ffdic sweep plan` also takes a model file), read when
    /// planning. Default: none (an ideal bench).
    #[serde(default)]
    pub model: Option<String>,
    /// The commanded move, mm, before the sub-pixel axes add to it.
    #[serde(default)]
    pub move_mm: [f64; 2],
    pub axes: Axes,
    #[serde(default)]
    #[schema(value_type = Object)]
    pub dic: DicSettings,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(as = SweepAxes)]
pub struct Axes {
    /// Prints by dot diameter in pixels of the reduced image (the camera being designed),
    /// spacing 1.5 diameters, contrast 0.85 — or the paper's presets with `patterns`.
    #[serde(default)]
    pub dot_diameter_px: Vec<f64>,
    #[serde(default)]
    pub patterns: Vec<String>,
    /// Reduction schemes: presets (`ff100`, `ff50`, `ff25`) or per-axis schemes as JSON-like
    /// tables `{ name, x = { block, first, active }, y = {…} }`.
    #[schema(value_type = Vec<Object>)]
    pub schemes: Vec<crate::experiment::SchemeSpec>,
    /// Sensor noise levels; empty = noiseless.
    #[serde(default)]
    pub noise: Vec<NoiseLevel>,
    /// Gaussian PSF σ at full resolution, px (0 = none).
    #[serde(default = "zero_list")]
    pub psf_sigma_px: Vec<f64>,
    /// The full-resolution sensor's own pixel aperture, linear fill factor `[fx, fy]` in
    /// (0, 1], rendered through the model's `fill_factor` effect (each pixel integrates only
    /// its centred active part) before any scheme reduces it; empty = the model's aperture.
    #[serde(default)]
    #[schema(value_type = Vec<Vec<f64>>)]
    pub pixel_aperture: Vec<[f64; 2]>,
    /// Sub-pixel part of the move in reduced px, added to `move_mm`.
    #[serde(default = "zero_list")]
    pub subpixel_x: Vec<f64>,
    #[serde(default = "zero_list")]
    pub subpixel_y: Vec<f64>,
}

fn zero_list() -> Vec<f64> {
    vec![0.0]
}

/// A sensor's noise: shot noise of a full well and read noise, electrons.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NoiseLevel {
    pub full_well_e: f64,
    pub read_noise_e: f64,
    /// Electrons per DN.
    #[serde(default = "default_gain")]
    pub gain: f64,
}

fn default_gain() -> f64 {
    0.46
}

/// One value of the print axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PrintAxis {
    /// Dot diameter in reduced-image px.
    DotDiameterPx(f64),
    /// A preset of the paper (`a`, `b`, `c`).
    Pattern(String),
}

impl PrintAxis {
    /// The print on the target, for a camera of `scale_px_per_mm` reduced by `block_px`.
    pub fn pattern(&self, scale_px_per_mm: f64, block_px: f64) -> SpecklePattern {
        match self {
            PrintAxis::DotDiameterPx(d) => {
                let diameter_mm = d * block_px / scale_px_per_mm;
                SpecklePattern {
                    label: format!("d{d}px"),
                    dot_diameter_mm: diameter_mm,
                    dot_spacing_mm: 1.5 * diameter_mm,
                    contrast: 0.85,
                    edge_softness_mm: 0.0,
                    placement: Default::default(),
                    profile: Default::default(),
                    min_gap_mm: 0.0,
                }
            }
            PrintAxis::Pattern(label) => {
                SpecklePattern::preset(label).expect("checked when the spec was read")
            }
        }
    }

    pub fn label(&self) -> String {
        match self {
            PrintAxis::DotDiameterPx(d) => format!("{d}"),
            PrintAxis::Pattern(p) => p.clone(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("sweep {path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("sweep task: {0}")]
    Task(String),
    #[error("cancelled")]
    Cancelled,
}

impl SweepSpec {
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, SweepError> {
        let invalid = |message: String| SweepError::Invalid {
            path: origin.to_owned(),
            message,
        };
        let spec: SweepSpec = toml::from_str(text).map_err(|e| invalid(e.message().to_string()))?;
        spec.validate().map_err(|e| invalid(e.to_string()))?;
        Ok(spec)
    }

    pub fn load(path: &Path) -> Result<Self, SweepError> {
        let text = std::fs::read_to_string(path).map_err(|source| SweepError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// The print axis: dot diameters, or presets.
    pub fn prints(&self) -> Vec<PrintAxis> {
        let dots = self
            .axes
            .dot_diameter_px
            .iter()
            .map(|&d| PrintAxis::DotDiameterPx(d));
        let presets = self.axes.patterns.iter().cloned().map(PrintAxis::Pattern);
        dots.chain(presets).collect()
    }

    /// The noise axis; one noiseless level when empty.
    pub fn noise_levels(&self) -> Vec<Option<NoiseLevel>> {
        if self.axes.noise.is_empty() {
            vec![None]
        } else {
            self.axes.noise.iter().copied().map(Some).collect()
        }
    }

    /// The pixel-aperture axis; the model's own aperture when empty.
    pub fn apertures(&self) -> Vec<Option<[f64; 2]>> {
        if self.axes.pixel_aperture.is_empty() {
            vec![None]
        } else {
            self.axes.pixel_aperture.iter().copied().map(Some).collect()
        }
    }

    pub fn task_count(&self) -> usize {
        [
            self.prints().len(),
            self.axes.schemes.len(),
            self.noise_levels().len(),
            self.axes.psf_sigma_px.len(),
            self.apertures().len(),
            self.axes.subpixel_x.len(),
            self.axes.subpixel_y.len(),
            self.seeds,
        ]
        .iter()
        .try_fold(1usize, |n, &k| n.checked_mul(k))
        .unwrap_or(usize::MAX)
    }

    /// Checks every field (also what the schema cannot say, e.g. the task count); the field to
    /// blame on failure.
    pub fn validate(&self) -> Result<(), FieldError> {
        crate::experiment::check_run_name(&self.name)?;
        if !(1..=MAX_SEEDS).contains(&self.seeds) {
            return bad("seeds", format!("1 to {MAX_SEEDS}"));
        }
        self.validate_axes()?;
        if !self
            .move_mm
            .iter()
            .all(|v| v.is_finite() && v.abs() <= MAX_MOVE_MM)
        {
            return bad("move_mm", format!("each within ±{MAX_MOVE_MM} mm"));
        }
        validate_camera(&self.camera)?;
        self.dic.validate().map_err(|e| FieldError {
            field: "dic".into(),
            reason: e.to_string(),
        })?;
        let n = self.task_count();
        if n > MAX_TASKS {
            return bad("axes", format!("{n} tasks; at most {MAX_TASKS}"));
        }
        Ok(())
    }

    fn validate_axes(&self) -> Result<(), FieldError> {
        let axes = &self.axes;
        if self.prints().is_empty() {
            return bad("axes", "give dot_diameter_px or patterns".into());
        }
        let (d_lo, d_hi) = DOT_DIAMETER_PX;
        if let Some(d) = axes
            .dot_diameter_px
            .iter()
            .find(|d| !(d.is_finite() && (d_lo..=d_hi).contains(*d)))
        {
            return bad(
                "axes.dot_diameter_px",
                format!("{d} is not in [{d_lo}, {d_hi}] px"),
            );
        }
        if let Some(p) = axes
            .patterns
            .iter()
            .find(|p| SpecklePattern::preset(p).is_none())
        {
            return bad("axes.patterns", format!("unknown preset '{p}' (a, b or c)"));
        }
        // A preset is in mm: at a small scale its dots fall below a pixel.
        for label in &axes.patterns {
            let print = PrintAxis::Pattern(label.clone())
                .pattern(self.camera.scale_px_per_mm, REFERENCE_BLOCK_PX);
            let d = print.dot_diameter_mm * self.camera.scale_px_per_mm / REFERENCE_BLOCK_PX;
            if d.is_finite() && d < d_lo {
                return bad(
                    "axes.patterns",
                    format!(
                        "preset '{label}' has dots of {d:.2} px at {} px/mm (2x2-reduced px); at least {d_lo} px: a larger camera.scale_px_per_mm",
                        self.camera.scale_px_per_mm
                    ),
                );
            }
        }
        crate::experiment::check_schemes(&axes.schemes).map_err(|e| FieldError {
            field: format!("axes.{}", e.field),
            reason: e.reason,
        })?;
        let sane = |n: &NoiseLevel| {
            n.full_well_e > 0.0
                && n.read_noise_e >= 0.0
                && n.gain > 0.0
                && [n.full_well_e, n.read_noise_e, n.gain]
                    .iter()
                    .all(|v| v.is_finite())
        };
        if !axes.noise.iter().all(sane) {
            return bad(
                "axes.noise",
                "full_well_e and gain positive, read_noise_e ≥ 0".into(),
            );
        }
        within("psf_sigma_px", &axes.psf_sigma_px, 0.0, 20.0)?;
        if let Some(a) = axes
            .pixel_aperture
            .iter()
            .find(|a| !a.iter().all(|f| f.is_finite() && *f > 0.0 && *f <= 1.0))
        {
            return bad(
                "axes.pixel_aperture",
                format!("[{}, {}]: each linear fill factor in (0, 1]", a[0], a[1]),
            );
        }
        within("subpixel_x", &axes.subpixel_x, -1.0, 1.0)?;
        within("subpixel_y", &axes.subpixel_y, -1.0, 1.0)
    }
}

/// The dot diameters a sweep takes, px of the 2x2-reduced image: below one pixel the renderer
/// makes no speckle the DIC can follow (0.5 px dots gave 0 valid points of 36, 1 px gave 30:
/// every task of such a sweep failed), above 100 px a subset holds no pattern.
pub const DOT_DIAMETER_PX: (f64, f64) = (1.0, 100.0);

fn bad(field: &str, reason: String) -> Result<(), FieldError> {
    Err(FieldError {
        field: field.to_string(),
        reason,
    })
}

/// Every value of axis `name` finite and in [lo, hi], and at least one.
fn within(name: &str, xs: &[f64], lo: f64, hi: f64) -> Result<(), FieldError> {
    if xs.is_empty() {
        return bad(&format!("axes.{name}"), "at least one value".into());
    }
    match xs
        .iter()
        .find(|v| !(v.is_finite() && (lo..=hi).contains(*v)))
    {
        Some(v) => bad(
            &format!("axes.{name}"),
            format!("{v} is not in [{lo}, {hi}]"),
        ),
        None => Ok(()),
    }
}

fn validate_camera(c: &Camera) -> Result<(), FieldError> {
    let sides = MIN_SENSOR_SIDE_PX..=MAX_SENSOR_SIDE_PX;
    if !sides.contains(&c.width) || !sides.contains(&c.height) {
        return bad(
            "camera",
            format!("width and height {MIN_SENSOR_SIDE_PX} to {MAX_SENSOR_SIDE_PX} px"),
        );
    }
    if !(c.scale_px_per_mm.is_finite() && (0.01..=10_000.0).contains(&c.scale_px_per_mm)) {
        return bad("camera.scale_px_per_mm", "0.01 to 10,000 px/mm".into());
    }
    if !(c.exposure_level.is_finite() && c.exposure_level > 0.0 && c.exposure_level <= 1.0) {
        return bad("camera.exposure_level", "in (0, 1]".into());
    }
    let half = c.width.max(c.height) as f64;
    if ![c.principal_dx_px, c.principal_dy_px]
        .iter()
        .all(|v| v.is_finite() && v.abs() <= half)
    {
        return bad("camera", "principal point offsets within the sensor".into());
    }
    Ok(())
}
