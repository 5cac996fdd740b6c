//! Datasets from the independent generator (`tests/independent/generate.py`, Python with numpy,
//! sharing no code with `src/model/`): the truth the diagnosis tests hold ffdic against.
//!
//! The generator runs in a virtual environment under `target/independent-venv`, made on first use
//! from `tests/independent/requirements.txt` (numpy and tifffile from PyPI).

#![allow(dead_code)]

use ffdic::diagnose::{
    diagnose_rounds_prepared, load_measurement, Candidate, CompareOptions, Diagnosis, Measurement,
    Rounds, BASELINE_TOML,
};
use ffdic::dic::DicSettings;
use ffdic::model::ModelConfig;
use ffdic::reduce::Scheme;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Cargo's target folder: `CARGO_TARGET_DIR`, else the repository's `target/`.
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("target"))
}

/// The venv's python, made (once per run of the tests) when missing or out of date by
/// `scripts/pip-venv.sh` (which `scripts/test-all.sh` runs ahead, while the crate compiles).
pub fn python() -> PathBuf {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            let venv = target_dir().join("independent-venv");
            let script = repo().join("scripts/pip-venv.sh");
            let ok = Command::new("bash")
                .arg(&script)
                .arg(&venv)
                .arg(repo().join("tests/independent/requirements.txt"))
                .arg("independent generator")
                .status()
                .expect("bash runs")
                .success();
            assert!(ok, "{} {} failed", script.display(), venv.display());
            venv.join("bin/python")
        })
        .clone()
}

/// Generates the dataset of `spec` into `dir` (which must not exist or be empty) and returns its
/// truth (`truth.json`).
pub fn generate(spec: &Value, dir: &Path) -> Value {
    let spec_path = dir.with_extension("spec.json");
    std::fs::write(&spec_path, serde_json::to_vec_pretty(spec).unwrap()).unwrap();
    let out = Command::new(python())
        .arg(repo().join("tests/independent/generate.py"))
        .arg(&spec_path)
        .arg(dir)
        .arg("--quiet")
        .output()
        .expect("generate.py runs");
    assert!(
        out.status.success(),
        "generate.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&std::fs::read(dir.join("truth.json")).unwrap()).unwrap()
}

/// The DIC Challenge Sample 3 images (../shared/data) as a dataset at `scale` px/mm.
pub fn sample3(dir: &Path, scale: f64) {
    let out = Command::new(python())
        .arg(repo().join("tests/independent/sample3_dataset.py"))
        .arg(dir)
        .args(["--scale", &scale.to_string()])
        .output()
        .expect("sample3_dataset.py runs");
    assert!(
        out.status.success(),
        "sample3_dataset.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A reproducible draw for the hidden values of one test: `FFDIC_INDEPENDENT_SEED` (default 2026)
/// mixed with the test's own number, so another seed redraws every dataset.
pub struct Draw(u64);

impl Draw {
    pub fn new(test: u64) -> Self {
        let base: u64 = std::env::var("FFDIC_INDEPENDENT_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(2026);
        Self(base.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ test.wrapping_mul(0xD1B5_4A32_D192_ED03))
    }

    /// Uniform in [0, 1) (splitmix64).
    pub fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// −1 or +1, evenly.
    pub fn sign(&mut self) -> f64 {
        if self.unit() < 0.5 {
            -1.0
        } else {
            1.0
        }
    }

    pub fn seed(&mut self) -> u64 {
        (self.unit() * 1e9) as u64 + 1
    }
}

/// A speckle print drawn for a test: Gaussian dots or hard disks, 0.25–0.35 mm at 1.6–1.8 times
/// that spacing, contrast 0.5–0.8.
pub fn print(draw: &mut Draw, label: &str, sharp: bool) -> Value {
    let d = draw.range(0.25, 0.35);
    let spacing = d * draw.range(1.6, 1.8);
    let contrast = draw.range(0.5, 0.8);
    if sharp {
        json!({"label": label, "profile": "disk", "dot_diameter_mm": d, "dot_spacing_mm": spacing,
               "contrast": contrast, "placement": "dart"})
    } else {
        json!({"label": label, "profile": "gaussian", "dot_diameter_mm": d,
               "dot_spacing_mm": spacing, "contrast": contrast})
    }
}

/// The bench of the tests: 640x540 at 13 px/mm (a quarter of the paper's 2560x2160 at 26 px/mm
/// per axis, the same field in mm at half the magnification), 16-bit, a signal-independent read
/// noise of 20 DN (the sensor the baseline assumes), translations of 5, 2.5 and 5 mm (x, x, y),
/// sub-pixel step series of 0.1 px in x and in y, one static repeat, and a stage that lands within
/// a stated 20 µm repeatability with a drawn constant offset up to 0.5 px per axis plus 5 µm of
/// random scatter.
pub fn bench(name: &str, draw: &mut Draw, sharp: bool) -> Value {
    json!({
        "name": name,
        "seed": draw.seed(),
        "width": 640, "height": 540, "scale_px_per_mm": 13.0, "bit_depth": 16,
        "white_level_dn": draw.range(25000.0, 35000.0),
        "gain_e_per_dn": null, "read_noise_dn": 20.0,
        "patterns": [print(draw, "a", sharp)],
        "state_print": "nominal",
        "moves": [{"id": "x5mm", "dx_mm": 5.0, "dy_mm": 0.0},
                  {"id": "x2mm", "dx_mm": 2.5, "dy_mm": 0.0},
                  {"id": "y5mm", "dx_mm": 0.0, "dy_mm": 5.0}],
        "step_series": [{"id": "xs", "dx_step_mm": 0.0077, "dy_step_mm": 0.0, "count": 3},
                        {"id": "ys", "dx_step_mm": 0.0, "dy_step_mm": 0.0077, "count": 3}],
        "repeats": 1,
        "stage": {"constant_offset_px": [draw.range(-0.5, 0.5), draw.range(-0.5, 0.5)],
                  "repeatability_um": 5.0},
        "stated_repeatability_um": 20.0,
        "effects": {}
    })
}

/// The baseline model, the analysis and the diagnosis the independent tests run.
pub fn baseline() -> ModelConfig {
    ModelConfig::from_toml(BASELINE_TOML, Path::new("config/models/baseline.toml")).unwrap()
}

pub fn options() -> CompareOptions {
    CompareOptions {
        dic: DicSettings::default(),
        schemes: vec![Scheme::preset("native").unwrap()],
        seed: 0x5EED,
    }
}

/// Generates `spec`, diagnoses the baseline against it for up to `rounds` rounds; returns the
/// rounds and the truth.
pub fn diagnose(spec: &Value, rounds: usize) -> (Rounds, Value) {
    diagnose_model(spec, &baseline(), rounds)
}

/// [`diagnose`] of `model` instead of the baseline.
pub fn diagnose_model(spec: &Value, model: &ModelConfig, rounds: usize) -> (Rounds, Value) {
    let measured = measure(spec);
    let r = measured.diagnose(model, rounds);
    (r, measured.truth)
}

/// A generated dataset measured once, so that several models can be diagnosed against it.
pub struct Measured {
    pub measurement: Measurement,
    pub truth: Value,
    name: String,
    /// The dataset's folder, kept while the measurement is.
    _root: tempfile::TempDir,
}

/// Generates `spec` and measures it with the tests' [`options`].
pub fn measure(spec: &Value) -> Measured {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("dataset");
    let truth = generate(spec, &dir);
    Measured {
        measurement: load_measurement(&dir, &options(), &|_, _| true).unwrap(),
        truth,
        name: spec["name"].as_str().unwrap_or("?").to_string(),
        _root: root,
    }
}

impl Measured {
    /// `model` diagnosed against the measurement for up to `rounds` rounds, reported.
    pub fn diagnose(&self, model: &ModelConfig, rounds: usize) -> Rounds {
        let r = diagnose_rounds_prepared(&self.measurement, model, rounds, &|_, _| true).unwrap();
        report(&self.name, &r);
        r
    }
}

pub fn report(name: &str, r: &Rounds) {
    println!("== {name}: verdicts {:?}", r.verdicts);
    for round in &r.rounds {
        println!(
            "   {} ± {} px -> {} {:?} ± {:?} -> {:?}",
            round.discrepancy_px,
            round.discrepancy_se_px,
            ffdic::model::effects::verdict_name(&round.verdict),
            round.params,
            round.stderr,
            round.after_px
        );
    }
    for (k, d) in r.diagnoses.iter().enumerate() {
        let u = &d.unexplained;
        println!(
            "   round {k}: unexplained {} F {:?} (threshold {:?}) light F {:?} (threshold {:?}) ratio {:.2}; after: {:?} F {:?}; explained {:?} partial {} withheld {:?}",
            u.significant,
            u.field_f,
            u.field_f_threshold,
            u.light_f,
            u.light_f_threshold,
            u.ratio,
            d.unexplained_after.as_ref().map(|a| a.significant),
            d.unexplained_after.as_ref().and_then(|a| a.field_f),
            d.explained_fraction,
            d.partial,
            d.withheld.as_ref().map(|w| (w.effect.clone(), w.explained_fraction)),
        );
        println!("     {}", u.summary);
        if let Some(a) = &d.unexplained_after {
            println!("     after: {}", a.summary);
        }
        if std::env::var_os("FFDIC_SHOW_SHAPES").is_some() {
            for r in &d.before.as_ref().expect("kept").runs {
                println!(
                    "     {} {}: rigid {:.5} field {:.5} std {:.5} random meas {:?} model {:?}",
                    r.id,
                    r.scheme,
                    r.rigid_px,
                    r.field_px,
                    r.std_px,
                    r.measured.random_px,
                    r.model.random_px
                );
            }
            for s in u
                .shape
                .runs
                .iter()
                .chain(d.unexplained_after.iter().flat_map(|a| a.shape.runs.iter()))
            {
                println!(
                    "     {} move {:?}: exx {:.2e} eyy {:.2e} shear {:.2e} rot {:.2e} se {:.1e} quad {:.5}",
                    s.run, s.move_px, s.exx, s.eyy, s.shear, s.rotation, s.se[0], s.quadratic_px
                );
            }
        }
    }
    let d = &r.diagnoses[0];
    for c in d.candidates.iter().filter(|c| c.delta_bic < -10.0) {
        println!(
            "   {:<20} dBIC {:>12.1} drop {:+.5} ± {:.5} img {:.1} ± {:.1} sig {} {:?}",
            c.effect,
            c.delta_bic,
            c.criteria.drop_px,
            c.criteria.drop_se_px,
            c.criteria.image_chi2_drop,
            c.criteria.image_chi2_se,
            c.significant,
            c.params
        );
        for note in &c.notes {
            println!("      note: {note}");
        }
        if !c.derived.is_empty() {
            println!("      derived: {:?}", c.derived);
        }
    }
}

/// The diagnosis' candidate for `effect` (the test fails when it was not fitted).
pub fn candidate<'a>(d: &'a Diagnosis, effect: &str) -> &'a Candidate {
    d.candidates
        .iter()
        .find(|c| c.effect.to_string() == effect)
        .unwrap_or_else(|| panic!("{effect} was not fitted"))
}

/// The winner of the first round lowered the discrepancy at least 3x.
pub fn winner_falls_3x(d: &Diagnosis, effect: &str) {
    let after = d.after.as_ref().expect("the winner's comparison");
    assert!(
        after.discrepancy_px * 3.0 <= d.discrepancy_px,
        "{effect}: discrepancy {} -> {} px, less than a 3x fall",
        d.discrepancy_px,
        after.discrepancy_px
    );
}
