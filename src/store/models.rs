//! Analysis models a user added (`data/models/{name}.toml`): the versions a dataset's history
//! refers to. A name holds one model for good — a changed model is a new name — so a history
//! entry always points at the model it was computed with.

use super::error::{Result, StoreError};
use super::run_store::RunStore;
use crate::atomic_write::write_atomically;
use std::path::{Path, PathBuf};

/// Longest model name, bytes.
pub const MAX_MODEL_NAME_LEN: usize = 96;

/// `name` is 1–96 characters of `A-Z a-z 0-9 _ - + .`, not starting with '.' or '-': safe as a
/// file name and readable in a URL.
pub fn is_model_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_MODEL_NAME_LEN
        && !name.starts_with('.')
        && !name.starts_with('-')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '+' | '.'))
}

/// Whether `save_model` stored a new model or found the identical one already there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelSaved {
    Created,
    AlreadyThere,
}

/// The models folder of a data folder (`DATA/models`), usable without opening the run store —
/// a command line reads models there while a daemon holds the store.
/// The sub-folder of deleted models' texts.
const RETIRED: &str = ".retired";

pub struct ModelFolder {
    dir: PathBuf,
}

impl ModelFolder {
    pub fn in_data_dir(data_dir: &Path) -> Self {
        Self {
            dir: data_dir.join("models"),
        }
    }

    /// The folder itself.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where model `name` is (or would be) stored; an error for a name that is not one.
    pub fn path(&self, name: &str) -> Result<PathBuf> {
        if !is_model_name(name) {
            return Err(StoreError::BadPath(format!(
                "'{}' is not a model name (A-Z a-z 0-9 _ - + ., at most {MAX_MODEL_NAME_LEN})",
                name.chars().take(80).collect::<String>()
            )));
        }
        Ok(self.dir.join(format!("{name}.toml")))
    }

    /// Stores the TOML text of model `name`. The same text again is `AlreadyThere`; another text
    /// under a stored name is a `Conflict` (names are versions: choose a new one).
    pub fn save(&self, name: &str, toml_text: &str) -> Result<ModelSaved> {
        let path = self.path(name)?;
        let retired = self.retired_path(name)?;
        if let Ok(earlier) = std::fs::read_to_string(&retired) {
            if earlier != toml_text {
                return Err(StoreError::Conflict(format!(
                    "a different model named '{name}' was stored and deleted; names are \
                     versions, give this one a new name"
                )));
            }
        }
        if let Ok(existing) = std::fs::read_to_string(&path) {
            return if existing == toml_text {
                Ok(ModelSaved::AlreadyThere)
            } else {
                Err(StoreError::Conflict(format!(
                    "a different model named '{name}' is stored; models are never rewritten, \
                     give this one a new name"
                )))
            };
        }
        let io = |source| StoreError::Io {
            path: path.clone(),
            source,
        };
        std::fs::create_dir_all(&self.dir).map_err(io)?;
        write_atomically(&path, toml_text.as_bytes()).map_err(io)?;
        Ok(ModelSaved::Created)
    }

    /// Where deleted model `name` is kept: out of the list, but its name stays taken by its text
    /// (a diagnosis's history names models; a name never means two models).
    fn retired_path(&self, name: &str) -> Result<PathBuf> {
        let path = self.path(name)?;
        Ok(self
            .dir
            .join(RETIRED)
            .join(path.file_name().expect("a model path names a file")))
    }

    /// Takes stored model `name` out of the list (`NotFound` when there is none). Its text is
    /// kept aside: the same text saved again brings it back, another text under its name is a
    /// `Conflict`.
    pub fn retire(&self, name: &str) -> Result<()> {
        let path = self.path(name)?;
        if !path.is_file() {
            return Err(StoreError::NotFound(format!("model '{name}'")));
        }
        let retired = self.retired_path(name)?;
        let folder = self.dir.join(RETIRED);
        std::fs::create_dir_all(&folder).map_err(|source| StoreError::Io {
            path: folder.clone(),
            source,
        })?;
        std::fs::rename(&path, &retired).map_err(|source| StoreError::Io { path, source })?;
        super::files::sync_dir(&self.dir)
    }

    /// The TOML text of stored model `name`.
    pub fn read(&self, name: &str) -> Result<String> {
        let path = self.path(name)?;
        std::fs::read_to_string(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => StoreError::NotFound(format!("model '{name}'")),
            _ => StoreError::Io { path, source: e },
        })
    }

    /// Names of the stored models, sorted.
    pub fn list(&self) -> Result<Vec<String>> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(source) => {
                return Err(StoreError::Io {
                    path: self.dir.clone(),
                    source,
                })
            }
        };
        let mut names: Vec<String> = entries
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let stem = name.strip_suffix(".toml")?.to_string();
                is_model_name(&stem).then_some(stem)
            })
            .collect();
        names.sort();
        Ok(names)
    }
}

impl RunStore {
    fn models(&self) -> ModelFolder {
        ModelFolder::in_data_dir(self.data_dir())
    }

    /// [`ModelFolder::save`] in this store's data folder.
    pub fn save_model(&self, name: &str, toml_text: &str) -> Result<ModelSaved> {
        self.models().save(name, toml_text)
    }

    /// [`ModelFolder::read`] in this store's data folder.
    pub fn read_model(&self, name: &str) -> Result<String> {
        self.models().read(name)
    }

    /// [`ModelFolder::retire`] in this store's data folder, refused (`InUse`) while a queued or
    /// running run names the model.
    pub fn delete_model(&self, name: &str) -> Result<()> {
        self.unless_model_in_use(name, || self.models().retire(name))
    }

    /// [`ModelFolder::list`] in this store's data folder.
    pub fn list_models(&self) -> Result<Vec<String>> {
        self.models().list()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_that_could_leave_the_folder_are_refused() {
        for bad in [
            "",
            "../x",
            "a/b",
            ".hidden",
            "-x",
            "a b",
            "a\\b",
            &"x".repeat(97),
        ] {
            assert!(!is_model_name(bad), "{bad}");
        }
        for ok in ["baseline", "baseline+lens_distortion", "bench-2.1"] {
            assert!(is_model_name(ok), "{ok}");
        }
    }

    #[test]
    fn a_name_holds_one_model_for_good() {
        let dir = tempfile::tempdir().unwrap();
        let (store, _) = RunStore::open(dir.path()).unwrap();
        assert_eq!(store.list_models().unwrap(), Vec::<String>::new());
        assert_eq!(
            store.save_model("m1", "name = \"m1\"\n").unwrap(),
            ModelSaved::Created
        );
        assert_eq!(
            store.save_model("m1", "name = \"m1\"\n").unwrap(),
            ModelSaved::AlreadyThere
        );
        assert!(matches!(
            store.save_model("m1", "name = \"m1\"\n# changed\n"),
            Err(StoreError::Conflict(_))
        ));
        assert_eq!(store.read_model("m1").unwrap(), "name = \"m1\"\n");
        assert!(matches!(
            store.read_model("m2"),
            Err(StoreError::NotFound(_))
        ));
        assert!(matches!(
            store.read_model("../m1"),
            Err(StoreError::BadPath(_))
        ));
        assert_eq!(store.list_models().unwrap(), vec!["m1".to_string()]);
    }
}
