//! A sweep spec expanded into tasks named by the content hash of their inputs, grouped into
//! shards that share one rendering.

use super::spec::{NoiseLevel, PrintAxis, SweepError, SweepSpec};
use crate::model::{Effects, ModelConfig};
use crate::reduce::Scheme;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::Path;

/// One task: one print, noise, blur, move, seed and scheme.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskInput {
    /// Content hash of everything that makes the result (16 hex digits).
    pub id: String,
    pub print: PrintAxis,
    pub scheme: Scheme,
    /// `None`: the model's own sensor noise.
    pub noise: Option<NoiseLevel>,
    pub psf_sigma_px: f64,
    /// The sensor's own pixel aperture `[fx, fy]`; `None`: the model's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture: Option<[f64; 2]>,
    /// Sub-pixel part of the move, reduced px.
    pub subpixel_px: [f64; 2],
    /// Realisation number within its cell, and the seed it renders with.
    pub realisation: usize,
    pub seed: u64,
}

impl TaskInput {
    /// The cell this task is a realisation of: every axis but the seed, as text.
    pub fn cell_key(&self) -> String {
        format!(
            "{}|{}|{:?}|{}|{:?}|{}|{}",
            self.print.label(),
            self.scheme.name,
            self.noise.map(|n| (n.full_well_e, n.read_noise_e, n.gain)),
            self.psf_sigma_px,
            self.aperture,
            self.subpixel_px[0],
            self.subpixel_px[1]
        )
    }
}

/// Tasks rendered together: the same print, noise, blur, move and seed; one scheme each.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub tasks: Vec<TaskInput>,
}

/// What `ffdic sweep plan` writes to `DIR/plan.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub spec: SweepSpec,
    /// The model's effects the axes start from (read once, when planning).
    pub base_effects: Effects,
    pub ffdic_version: String,
    pub shards: Vec<Shard>,
}

impl Plan {
    pub fn task_count(&self) -> usize {
        self.shards.iter().map(|s| s.tasks.len()).sum()
    }

    pub fn read(dir: &Path) -> Result<Self, SweepError> {
        let path = dir.join("plan.json");
        let text = std::fs::read_to_string(&path).map_err(|source| SweepError::Read {
            path: path.clone(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|e| SweepError::Invalid {
            path,
            message: e.to_string(),
        })
    }
}

/// Everything a task's result depends on, hashed into its id.
#[derive(Serialize)]
struct TaskKey<'a> {
    ffdic_version: &'a str,
    camera: &'a crate::model::Camera,
    effects: &'a Effects,
    pattern: &'a crate::model::SpecklePattern,
    move_mm: [f64; 2],
    subpixel_px: [f64; 2],
    seed: u64,
    scheme: &'a Scheme,
    dic: &'a crate::dic::DicSettings,
}

/// Expands `spec` (whose model, if named, is `model`) into shards. Deterministic: the same spec
/// and model give the same plan, and a task's id depends only on its own inputs.
pub fn plan(spec: &SweepSpec, model: Option<&ModelConfig>) -> Result<Plan, SweepError> {
    let base_effects = model.map(|m| m.effects.clone()).unwrap_or_default();
    let schemes = crate::experiment::check_schemes(&spec.axes.schemes)
        .map_err(|e| SweepError::Task(e.to_string()))?;
    let apertures = spec.apertures();
    let mut shards = Vec::new();
    for print in spec.prints() {
        let pattern = print.pattern(spec.camera.scale_px_per_mm, super::task::REFERENCE_BLOCK_PX);
        for noise in spec.noise_levels() {
            for (&psf, aperture) in spec
                .axes
                .psf_sigma_px
                .iter()
                .flat_map(|p| apertures.iter().map(move |&a| (p, a)))
            {
                let effects = task_effects(&base_effects, noise, psf, aperture);
                for &sx in &spec.axes.subpixel_x {
                    for &sy in &spec.axes.subpixel_y {
                        for realisation in 0..spec.seeds {
                            let seed =
                                crate::model::derive_seed(spec.seed, realisation as u64, 0x5EE9);
                            let tasks = schemes
                                .iter()
                                .map(|scheme| {
                                    let key = TaskKey {
                                        ffdic_version: crate::VERSION,
                                        camera: &spec.camera,
                                        effects: &effects,
                                        pattern: &pattern,
                                        move_mm: spec.move_mm,
                                        subpixel_px: [sx, sy],
                                        seed,
                                        scheme,
                                        dic: &spec.dic,
                                    };
                                    TaskInput {
                                        id: content_hash(&key),
                                        print: print.clone(),
                                        scheme: scheme.clone(),
                                        noise,
                                        psf_sigma_px: psf,
                                        aperture,
                                        subpixel_px: [sx, sy],
                                        realisation,
                                        seed,
                                    }
                                })
                                .collect();
                            shards.push(Shard {
                                index: shards.len(),
                                tasks,
                            });
                        }
                    }
                }
            }
        }
    }
    Ok(Plan {
        spec: spec.clone(),
        base_effects,
        ffdic_version: crate::VERSION.to_string(),
        shards,
    })
}

/// The model's effects with the task's noise, PSF blur and pixel aperture in place of its own.
pub(super) fn task_effects(
    base: &Effects,
    noise: Option<NoiseLevel>,
    psf_sigma_px: f64,
    aperture: Option<[f64; 2]>,
) -> Effects {
    let mut effects = base.clone();
    if let Some([fx, fy]) = aperture {
        effects.fill_factor = Some(crate::model::effects::FillFactor { fx, fy });
    }
    if let Some(n) = noise {
        effects.sensor_noise = Some(crate::model::effects::SensorNoise {
            full_well_e: n.full_well_e,
            read_noise_e: n.read_noise_e,
            gain: n.gain,
        });
    }
    if psf_sigma_px > 0.0 {
        effects.psf_blur = Some(crate::model::effects::PsfBlur {
            sigma_px: psf_sigma_px,
        });
    }
    effects
}

fn content_hash(key: &impl Serialize) -> String {
    let bytes = serde_json::to_vec(key).expect("task keys serialise");
    let digest = Sha256::digest(&bytes);
    digest[..8].iter().map(|b| format!("{b:02x}")).collect()
}
