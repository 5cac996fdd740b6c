use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::path::{Component, Path, PathBuf};

use super::manifest_schema::schema_problems;
pub use crate::model::DotProfile;
use crate::model::Placement;

pub const FORMAT: &str = "ffdic-dataset/1";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub name: String,
    pub scale_px_per_mm: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraInfo>,
    /// The stage's stated repeatability, 1σ per axis, µm: landings within 3σ of the commanded
    /// position are the stage behaving as specified (see `model::effects::StageError`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage_repeatability_um: Option<f64>,
    /// Distance from the lens's entrance pupil to the target along the optical axis, mm: with
    /// it a target's tilt is reported as angles, without it as angles at an assumed distance
    /// (one translation identifies tan θ over the distance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub working_distance_mm: Option<f64>,
    pub runs: Vec<Run>,
    /// Fields this version does not know, kept so a rewrite loses nothing.
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub width: usize,
    pub height: usize,
    pub bit_depth: u8,
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// What a dataset states of a pattern's print. The size and spacing are what the lab asked the
/// printer for (nominal); a `profile` with its `contrast` and size (`dot_diameter_mm` or a
/// measured `mtf`) characterises the print (see `diagnose::print`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PatternInfo {
    pub label: String,
    /// Dot diameter (FWHM for Gaussian dots), mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dot_diameter_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dot_spacing_mm: Option<f64>,
    /// The dots' measured profile.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<DotProfile>,
    /// A dot's depth: 1 − its reflectance over the background's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contrast: Option<f64>,
    /// σ of the print's own blur, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_softness_mm: Option<f64>,
    /// The print's measured transfer function: `[cycles_per_mm, modulation]` pairs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mtf: Option<Vec<[f64; 2]>>,
    /// How the dots are placed; absent: chosen from the measured spectrum.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub placement: Option<Placement>,
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// The largest dot or spacing a print may state, in image px: a few dots per frame at most.
/// Larger figures (`dot_diameter_mm` 1e6) are typing errors that the model would render at
/// great cost.
pub const MAX_PRINT_FEATURE_PX: f64 = 1024.0;
/// The softest dot edge a print may state, in image px: beyond it the pattern is blurred away,
/// and `edge_softness_mm` 65 (1,690 px at the paper's scale) made `compare` 20x slower.
pub const MAX_EDGE_SOFTNESS_PX: f64 = 64.0;

impl PatternInfo {
    /// The first number of this entry outside its range, named; sizes are held in px of the
    /// frames (`scale_px_per_mm`).
    fn check(&self, scale_px_per_mm: f64) -> Result<(), String> {
        let positive = [
            ("dot_diameter_mm", self.dot_diameter_mm),
            ("dot_spacing_mm", self.dot_spacing_mm),
        ];
        for (name, value) in positive {
            if let Some(v) = value.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(format!(
                    "pattern {}: {name} must be positive, got {v}",
                    self.label
                ));
            }
            if let Some(v) = value.filter(|v| v * scale_px_per_mm > MAX_PRINT_FEATURE_PX) {
                return Err(format!(
                    "pattern {}: {name} {v} is {:.0} px at {scale_px_per_mm} px/mm; at most {MAX_PRINT_FEATURE_PX} px",
                    self.label,
                    v * scale_px_per_mm
                ));
            }
        }
        if let Some(c) = self.contrast.filter(|c| !(*c > 0.0 && *c <= 1.0)) {
            return Err(format!(
                "pattern {}: contrast must lie in (0, 1], got {c}",
                self.label
            ));
        }
        if let Some(s) = self
            .edge_softness_mm
            .filter(|s| !(s.is_finite() && *s >= 0.0))
        {
            return Err(format!(
                "pattern {}: edge_softness_mm must be at least 0, got {s}",
                self.label
            ));
        }
        if let Some(s) = self
            .edge_softness_mm
            .filter(|s| s * scale_px_per_mm > MAX_EDGE_SOFTNESS_PX)
        {
            return Err(format!(
                "pattern {}: edge_softness_mm {s} is {:.0} px at {scale_px_per_mm} px/mm; at most {MAX_EDGE_SOFTNESS_PX} px",
                self.label,
                s * scale_px_per_mm
            ));
        }
        if let Some(bad) = self
            .mtf
            .iter()
            .flatten()
            .find(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(format!(
                "pattern {}: mtf pair {bad:?} is not finite",
                self.label
            ));
        }
        Ok(())
    }
}

/// The commanded stage move, not what happened.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageMove {
    pub dx_mm: f64,
    pub dy_mm: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Run {
    pub id: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pattern: Option<PatternInfo>,
    pub reference: String,
    pub deformed: String,
    pub stage: StageMove,
    /// Further static frames of the reference position.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repeat: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_us: Option<f64>,
    /// One independent capture of the run named here (an experiment with `repeats` > 1): the
    /// study pools the runs that share it into one row with an interval over captures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeat_of: Option<String>,
    /// The hardware scheme the camera read both frames out in (its own binning or decimation);
    /// absent: full resolution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capture: Option<ffdic_hw::HardwareScheme>,
    /// With `capture`: the full-resolution run of the same pattern and move, whose synthesised
    /// schemes the study sets beside this run's hardware scheme.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twin_of: Option<String>,
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// The largest hardware binning or decimation factor a manifest may state (what any camera
/// offers is 2 to 8).
pub const MAX_CAPTURE_FACTOR: u32 = 64;

impl Run {
    /// Image px per mm in this run's frames: the dataset's scale (full resolution), divided by
    /// the block of the hardware scheme the camera read the frames out in (the geometric mean of
    /// its two axes).
    pub fn frame_px_per_mm(&self, scale_px_per_mm: f64) -> f64 {
        match &self.capture {
            Some(c) => scale_px_per_mm / ((c.x.factor() * c.y.factor()) as f64).sqrt(),
            None => scale_px_per_mm,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
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
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

impl DatasetError {
    /// The error with its file named by its name alone (for a client, who never sees the
    /// server's folders).
    pub fn without_folder(&self) -> String {
        let name = |p: &std::path::Path| {
            p.file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
        };
        match self {
            DatasetError::Read { path, source } => format!("cannot read {}: {source}", name(path)),
            DatasetError::Write { path, source } => {
                format!("cannot write {}: {source}", name(path))
            }
            DatasetError::Invalid { path, message } => format!("{}: {message}", name(path)),
        }
    }
}

impl Manifest {
    pub fn new(name: &str, scale_px_per_mm: f64) -> Self {
        Self {
            format: FORMAT.into(),
            name: name.into(),
            scale_px_per_mm,
            camera: None,
            stage_repeatability_um: None,
            working_distance_mm: None,
            runs: Vec::new(),
            extra: Map::new(),
        }
    }

    /// Reads and checks `DIR/dataset.json`.
    pub fn read(dir: &Path) -> Result<Self, DatasetError> {
        let path = dir.join("dataset.json");
        let text = std::fs::read_to_string(&path).map_err(|source| DatasetError::Read {
            path: path.clone(),
            source,
        })?;
        let invalid = |message: String| DatasetError::Invalid {
            path: path.clone(),
            message,
        };
        let value: Value = serde_json::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        // Every mistake at once: first what the schema (docs/dataset-format.schema.json) finds,
        // then, on a manifest that holds it, what depends on the numbers together (a print's
        // size at the dataset's scale, a capture's twin).
        let problems = schema_problems(&value);
        if !problems.is_empty() {
            return Err(invalid(listed(problems)));
        }
        let m: Manifest = serde_json::from_value(value).map_err(|e| invalid(e.to_string()))?;
        m.validate().map_err(invalid)?;
        Ok(m)
    }

    /// Checks the format, the numbers and every file name; every problem, listed.
    pub fn validate(&self) -> Result<(), String> {
        let mut problems = Vec::new();
        if self.format != FORMAT {
            problems.push(format!("format is '{}', expected '{FORMAT}'", self.format));
        }
        if !(self.scale_px_per_mm > 0.0) {
            problems.push("scale_px_per_mm must be positive".into());
        }
        if let Some(r) = self.stage_repeatability_um {
            if !(r.is_finite() && r > 0.0) {
                problems.push(format!(
                    "stage_repeatability_um must be a positive number of µm, got {r}"
                ));
            }
        }
        if let Some(z) = self.working_distance_mm {
            if !(z.is_finite() && z >= 1.0) {
                problems.push(format!(
                    "working_distance_mm must be a distance of at least 1 mm, got {z}"
                ));
            }
        }
        if self.runs.is_empty() {
            problems.push("runs is empty".into());
        }
        for run in &self.runs {
            problems.extend(self.run_problems(run));
        }
        match problems.is_empty() {
            true => Ok(()),
            false => Err(listed(problems)),
        }
    }

    /// What is wrong with `run`: its file names, its move, its capture and its print.
    fn run_problems(&self, run: &Run) -> Vec<String> {
        let mut problems = Vec::new();
        for file in std::iter::once(&run.reference)
            .chain([&run.deformed])
            .chain(&run.repeat)
        {
            if !is_plain_file_name(file) {
                problems.push(format!(
                    "run {}: '{file}' is not a file name inside the dataset",
                    run.id
                ));
            }
        }
        if !(run.stage.dx_mm.is_finite() && run.stage.dy_mm.is_finite()) {
            problems.push(format!("run {}: stage move is not finite", run.id));
        }
        if let Err(e) = self.check_capture(run) {
            problems.push(e);
        }
        if let Some(p) = &run.pattern {
            if let Err(e) = p.check(self.scale_px_per_mm) {
                problems.push(format!("run {}: {e}", run.id));
            }
        }
        problems
    }

    /// A hardware run's capture mode (factors 1 to [`MAX_CAPTURE_FACTOR`]) and its twin: an
    /// earlier run of this manifest at full resolution (the study compares with its first
    /// scheme as it goes).
    fn check_capture(&self, run: &Run) -> Result<(), String> {
        let Some(capture) = &run.capture else {
            return match run.twin_of {
                Some(_) => Err(format!("run {}: twin_of without capture", run.id)),
                None => Ok(()),
            };
        };
        let factors = [capture.x.factor(), capture.y.factor()];
        if factors
            .iter()
            .any(|f| !(1..=MAX_CAPTURE_FACTOR).contains(f))
        {
            return Err(format!(
                "run {}: capture factors must be 1 to {MAX_CAPTURE_FACTOR}, got {factors:?}",
                run.id
            ));
        }
        if let Some(twin) = &run.twin_of {
            let earlier = self.runs.iter().take_while(|r| r.id != run.id);
            if !earlier
                .into_iter()
                .any(|r| r.id == *twin && r.capture.is_none())
            {
                return Err(format!(
                    "run {}: twin_of '{twin}' must name an earlier full-resolution run",
                    run.id
                ));
            }
        }
        Ok(())
    }

    /// The manifest without the runs a camera read out in its own binning or decimation
    /// (`capture`), and those runs.
    pub fn full_resolution(mut self) -> (Manifest, Vec<Run>) {
        let (full, hardware) = self.runs.into_iter().partition(|r| r.capture.is_none());
        self.runs = full;
        (self, hardware)
    }

    /// Every frame file the runs name (reference, deformed, static frames), each once, in
    /// the order the runs name them.
    pub fn frame_files(&self) -> Vec<String> {
        let mut files: Vec<String> = Vec::new();
        for run in &self.runs {
            for file in std::iter::once(&run.reference)
                .chain([&run.deformed])
                .chain(&run.repeat)
            {
                if !files.contains(file) {
                    files.push(file.clone());
                }
            }
        }
        files
    }

    /// Writes `DIR/dataset.json` atomically.
    pub fn write(&self, dir: &Path) -> Result<(), DatasetError> {
        let path = dir.join("dataset.json");
        let text = serde_json::to_string_pretty(self).expect("a manifest always serialises");
        crate::atomic_write::write_atomically(&path, text.as_bytes())
            .map_err(|source| DatasetError::Write { path, source })
    }
}

/// One problem as it is; several counted and listed, so a person fixes them in one go.
fn listed(problems: Vec<String>) -> String {
    match problems.len() {
        1 => problems.into_iter().next().expect("one"),
        n => format!("{n} problems: {}", problems.join("; ")),
    }
}

/// A name that stays inside the dataset folder: one normal path component, no separators.
pub fn is_plain_file_name(name: &str) -> bool {
    // `Path::components` drops a trailing `/` or `/.`, so `x/` and `x/.` would pass as `x`:
    // refuse separators outright, and control characters with them.
    let mut comps = Path::new(name).components();
    matches!(comps.next(), Some(Component::Normal(_)))
        && comps.next().is_none()
        && !name.contains(['/', '\\'])
        && !name.chars().any(char::is_control)
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"{ "format": "ffdic-dataset/1", "name": "bench-2026-11-22",
      "scale_px_per_mm": 26.0, "operator": "kept",
      "camera": { "width": 2560, "height": 2160, "bit_depth": 16 },
      "runs": [ { "id": "b-x5mm", "pattern": { "label": "b", "dot_diameter_mm": 0.24, "dot_spacing_mm": 0.36 },
                  "reference": "b_ref.tif", "deformed": "b_x5mm.tif",
                  "stage": { "dx_mm": 5.0, "dy_mm": 0.0 } } ] }"#;

    #[test]
    fn design_example_parses_and_keeps_unknown_fields() {
        let m: Manifest = serde_json::from_str(EXAMPLE).unwrap();
        m.validate().unwrap();
        assert_eq!(m.runs[0].stage.dx_mm, 5.0);
        assert_eq!(m.extra["operator"], "kept");
        let back = serde_json::to_string(&m).unwrap();
        assert!(back.contains("\"operator\":\"kept\""));
    }

    /// A hard-disk print whose dots never touch: its profile and placement pass the schema
    /// (`docs/dataset-format.schema.json`) and the types.
    #[test]
    fn a_disk_print_placed_as_a_hard_core_is_accepted() {
        let print = r#""dot_spacing_mm": 0.36, "profile": "disk", "contrast": 0.8,
            "placement": "hard_core""#;
        let text = EXAMPLE.replace(r#""dot_spacing_mm": 0.36"#, print);
        let m: Manifest = serde_json::from_str(&text).unwrap();
        m.validate().unwrap();
        let p = m.runs[0].pattern.as_ref().unwrap();
        assert_eq!(p.profile, Some(DotProfile::Disk));
        assert_eq!(p.placement, Some(Placement::HardCore));
    }

    #[test]
    fn a_characterised_print_is_typed_and_checked() {
        let print = r#""dot_spacing_mm": 0.36, "profile": "gaussian", "contrast": 0.7,
            "edge_softness_mm": 0.01, "mtf": [[0.0, 1.0], [2.0, 0.6]], "placement": "poisson""#;
        let text = EXAMPLE.replace(r#""dot_spacing_mm": 0.36"#, print);
        let m: Manifest = serde_json::from_str(&text).unwrap();
        m.validate().unwrap();
        let p = m.runs[0].pattern.as_ref().unwrap();
        assert_eq!(p.profile, Some(DotProfile::Gaussian));
        assert_eq!(p.mtf.as_deref(), Some(&[[0.0, 1.0], [2.0, 0.6]][..]));
        assert_eq!(p.placement, Some(Placement::Poisson));
        assert!(p.extra.is_empty(), "{:?}", p.extra);
        let mut bad = m.clone();
        bad.runs[0].pattern.as_mut().unwrap().contrast = Some(1.5);
        let err = bad.validate().unwrap_err();
        assert!(err.contains("contrast") && err.contains("b-x5mm"), "{err}");
        // Issue 36: sizes no print has, which the model renders at great cost.
        let mut soft = m.clone();
        soft.runs[0].pattern.as_mut().unwrap().edge_softness_mm = Some(65.0);
        let err = soft.validate().unwrap_err();
        assert!(
            err.contains("edge_softness_mm") && err.contains("1690 px"),
            "{err}"
        );
        let mut huge = m.clone();
        huge.runs[0].pattern.as_mut().unwrap().dot_diameter_mm = Some(1e6);
        let err = huge.validate().unwrap_err();
        assert!(err.contains("dot_diameter_mm"), "{err}");
        let unknown = text.replace(r#""poisson""#, r#""dart""#);
        let err = serde_json::from_str::<Manifest>(&unknown)
            .unwrap_err()
            .to_string();
        assert!(err.contains("dart"), "{err}");
    }

    #[test]
    fn missing_field_is_named() {
        let text = EXAMPLE.replace("\"scale_px_per_mm\": 26.0,", "");
        let err = serde_json::from_str::<Manifest>(&text)
            .unwrap_err()
            .to_string();
        assert!(err.contains("scale_px_per_mm"), "{err}");
    }

    /// Issue 34: errors named one missing field at a time (`id`, then `stage`, then `name`, then
    /// `scale_px_per_mm`: six tries, twenty minutes). Five mistakes, one error listing all five.
    #[test]
    fn a_manifest_with_five_mistakes_gets_one_error_listing_all_five() {
        let dir = tempfile::tempdir().unwrap();
        let text = r#"{ "format": "ffdic-dataset/1", "scale_px_per_mm": -26,
          "runs": [ { "reference": "ref.tif", "deformed": "x1.tif",
                      "stage": { "dx_mm": 1.0, "dy_mm": 0.0 } },
                    { "id": "x2", "reference": "../ref.tif", "deformed": "x2.tif",
                      "stage": { "dx_mm": 2.0 } } ] }"#;
        std::fs::write(dir.path().join("dataset.json"), text).unwrap();
        let err = Manifest::read(dir.path()).unwrap_err().to_string();
        println!("{err}");
        assert!(err.contains("5 problems"), "{err}");
        for part in [
            "missing field `name`",
            "scale_px_per_mm: -26",
            "runs[0]: missing field `id`",
            "runs[1].reference: \"../ref.tif\" is not a plain file name",
            "runs[1].stage: missing field `dy_mm`",
        ] {
            assert!(err.contains(part), "{part}: {err}");
        }
    }

    #[test]
    fn file_names_cannot_leave_the_folder() {
        assert!(is_plain_file_name("a.tif"));
        for bad in [
            "../a.tif",
            "/etc/passwd",
            "x/a.tif",
            "",
            "..",
            "a\\b.tif",
            "x/",
            "x/.",
            "a\u{7}.tif",
        ] {
            assert!(!is_plain_file_name(bad), "{bad}");
        }
    }

    /// A hardware run states a plausible capture mode and an earlier full-resolution twin.
    #[test]
    fn a_hardware_run_needs_sane_factors_and_an_earlier_twin() {
        let caps = ffdic_hw::ReductionCaps {
            binning_max: (2, 2),
            binning_mode: Some(ffdic_hw::BinningMode::Average),
            binning_domain: ffdic_hw::BinningDomain::Charge,
            decimation_max: (2, 2),
        };
        let scheme = ffdic_hw::schemes_for(&caps).remove(0);
        let mut m: Manifest = serde_json::from_str(EXAMPLE).unwrap();
        let full = m.runs[0].clone();
        let hw = Run {
            id: "b-x5mm_hw".into(),
            capture: Some(scheme.clone()),
            twin_of: Some(full.id.clone()),
            ..full.clone()
        };
        m.runs.push(hw.clone());
        m.validate().unwrap();
        assert_eq!(m.runs[1].frame_px_per_mm(26.0), 13.0);
        assert_eq!(m.clone().full_resolution().1.len(), 1);

        let mut later = m.clone();
        later.runs.reverse();
        assert!(later.validate().unwrap_err().contains("earlier"));
        let mut no_capture = m.clone();
        no_capture.runs[1].capture = None;
        assert!(no_capture
            .validate()
            .unwrap_err()
            .contains("twin_of without capture"));
        let mut zero = m.clone();
        let mut bad = scheme;
        bad.x = ffdic_hw::AxisReduction::Decimate { factor: 0 };
        zero.runs[1].capture = Some(bad);
        assert!(zero.validate().unwrap_err().contains("capture factors"));
    }
}
