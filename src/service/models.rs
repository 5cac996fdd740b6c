//! The analysis models a comparison can use: those compiled in (`config/models/*.toml`) and those
//! users added (`data/models/`, see `store::models`). Embedded names are reserved.

use super::config::PAPER_BENCH_TOML;
use super::Service;
use crate::diagnose::{model_version, BASELINE_TOML};
use crate::model::ModelConfig;
use crate::store::{ModelSaved, StoreError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The paper's bench with a mild lens distortion: the embedded default mock bench's truth.
pub const PAPER_BENCH_DISTORTION_TOML: &str =
    include_str!("../../config/models/paper-bench-distortion.toml");

/// Models compiled into the binary: (name, file it was compiled from, TOML text).
pub const EMBEDDED_MODELS: [(&str, &str, &str); 3] = [
    ("baseline", "config/models/baseline.toml", BASELINE_TOML),
    (
        "paper-bench",
        "config/models/paper-bench.toml",
        PAPER_BENCH_TOML,
    ),
    (
        "paper-bench-distortion",
        "config/models/paper-bench-distortion.toml",
        PAPER_BENCH_DISTORTION_TOML,
    ),
];

/// The embedded model `name`, parsed.
pub fn embedded_model(name: &str) -> Option<ModelConfig> {
    EMBEDDED_MODELS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|(_, file, text)| {
            ModelConfig::from_toml(text, Path::new(file)).expect("embedded models parse")
        })
}

/// A model that `find_analysis_model` could not find or read.
#[derive(Debug, thiserror::Error)]
pub enum ModelLookupError {
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(
        "{given}: no such file, and no model of that name (embedded: {embedded}; stored in {}: {stored})",
        dir.display()
    )]
    NotFound {
        given: String,
        embedded: String,
        dir: std::path::PathBuf,
        stored: String,
    },
}

/// The analysis model `given` names, as `ffdic compare --model` and the Python bindings take
/// it: a file if one exists at that path, else an embedded model, else one the daemon stored
/// in `data_dir/models`; the baseline when not given.
pub fn find_analysis_model(
    given: Option<&str>,
    data_dir: &Path,
) -> Result<ModelConfig, ModelLookupError> {
    let Some(given) = given else {
        return Ok(embedded_model("baseline").expect("baseline is embedded"));
    };
    let as_path = Path::new(given);
    if as_path.is_file() {
        return Ok(ModelConfig::load(as_path)?);
    }
    if let Some(model) = embedded_model(given) {
        return Ok(model);
    }
    let stored = crate::store::ModelFolder::in_data_dir(data_dir);
    if let Ok(path) = stored.path(given) {
        if path.is_file() {
            return Ok(ModelConfig::load(&path)?);
        }
    }
    let embedded: Vec<&str> = EMBEDDED_MODELS.iter().map(|m| m.0).collect();
    let names = stored.list()?;
    Err(ModelLookupError::NotFound {
        given: given.to_string(),
        embedded: embedded.join(", "),
        dir: stored.dir().to_owned(),
        stored: if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        },
    })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ModelSource {
    Embedded,
    Stored,
}

/// A model as `GET /models` lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ModelSummary {
    pub name: String,
    /// A hash of the model's effects and parameters (what history entries refer to).
    pub version: String,
    pub description: String,
    /// Enabled effect ids, in vocabulary order (DESIGN.md).
    pub effects: Vec<String>,
    pub source: ModelSource,
}

/// `GET /models/{name}`: the summary and the model file itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ModelDetail {
    #[serde(flatten)]
    pub summary: ModelSummary,
    pub toml: String,
}

/// `POST /models`: a model file's text (TOML, `name` inside it names the model).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewModel {
    pub toml: String,
}

#[derive(Debug, thiserror::Error)]
pub enum ModelStoreError {
    /// The text is not a valid model (the message names the key or parameter).
    #[error("{0}")]
    Invalid(String),
    #[error("'{0}' is an embedded model; give yours another name")]
    Reserved(String),
    #[error("no model '{0}'")]
    NotFound(String),
    #[error(transparent)]
    Store(StoreError),
}

impl From<StoreError> for ModelStoreError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound(what) => {
                ModelStoreError::NotFound(what.trim_start_matches("model ").replace('\'', ""))
            }
            StoreError::BadPath(m) => ModelStoreError::Invalid(m),
            other => ModelStoreError::Store(other),
        }
    }
}

fn summary(model: &ModelConfig, source: ModelSource) -> ModelSummary {
    ModelSummary {
        name: model.name.clone(),
        version: model_version(model),
        description: model.description.clone(),
        effects: model.effects.names(),
        source,
    }
}

impl Service {
    /// Every model a comparison can name: the embedded ones first, then the stored ones.
    pub fn models(&self) -> Result<Vec<ModelSummary>, ModelStoreError> {
        let mut out: Vec<ModelSummary> = EMBEDDED_MODELS
            .iter()
            .map(|(n, _, _)| summary(&embedded_model(n).expect("embedded"), ModelSource::Embedded))
            .collect();
        for name in self.store.list_models()? {
            match self.model(&name) {
                Ok(d) => out.push(d.summary),
                // A file damaged by hand is skipped from the list, not fatal to it.
                Err(e) => tracing::warn!(model = %name, "stored model unreadable: {e}"),
            }
        }
        Ok(out)
    }

    /// Model `name` with its file.
    pub fn model(&self, name: &str) -> Result<ModelDetail, ModelStoreError> {
        if let Some((_, _, text)) = EMBEDDED_MODELS.iter().find(|(n, _, _)| *n == name) {
            let m = embedded_model(name).expect("embedded");
            return Ok(ModelDetail {
                summary: summary(&m, ModelSource::Embedded),
                toml: text.to_string(),
            });
        }
        let text = self.store.read_model(name)?;
        let m = parse(&text)?;
        Ok(ModelDetail {
            summary: summary(&m, ModelSource::Stored),
            toml: text,
        })
    }

    /// Model `name`, parsed, for a comparison or a diagnosis.
    pub fn model_config(&self, name: &str) -> Result<ModelConfig, ModelStoreError> {
        match embedded_model(name) {
            Some(m) => Ok(m),
            None => parse(&self.store.read_model(name)?),
        }
    }

    /// Validates and stores a model; `true` when it is new, `false` when the identical model
    /// was already stored (adding it twice is harmless).
    pub fn add_model(&self, new: &NewModel) -> Result<(ModelDetail, bool), ModelStoreError> {
        let m = parse(&new.toml)?;
        if EMBEDDED_MODELS.iter().any(|(n, _, _)| *n == m.name) {
            return Err(ModelStoreError::Reserved(m.name));
        }
        let saved = self.store.save_model(&m.name, &new.toml)?;
        Ok((
            ModelDetail {
                summary: summary(&m, ModelSource::Stored),
                toml: new.toml.clone(),
            },
            saved == ModelSaved::Created,
        ))
    }

    /// Deletes stored model `name` (`Reserved` for an embedded one; the store's `InUse` while a
    /// queued or running run names it). Its name stays its text's: see `ModelFolder::retire`.
    pub fn delete_model(&self, name: &str) -> Result<(), ModelStoreError> {
        if embedded_model(name).is_some() {
            return Err(ModelStoreError::Reserved(name.to_string()));
        }
        Ok(self.store.delete_model(name)?)
    }
}

fn parse(text: &str) -> Result<ModelConfig, ModelStoreError> {
    ModelConfig::from_toml(text, Path::new("model"))
        .map_err(|e| ModelStoreError::Invalid(e.to_string()))
}
