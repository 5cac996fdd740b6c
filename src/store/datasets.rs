//! Stored datasets: `datasets/{id}/` holds an `ffdic-dataset/1` folder (manifest and frames) and
//! the store's `record.json`. A dataset is assembled in a staging folder and renamed into place
//! only once its manifest is valid and every file it names is there; a failed commit (or a staging
//! folder simply dropped) leaves nothing behind.

use super::error::{io, Result, StoreError};
use super::files::{list_files, read_json, remove_dir, sync_dir, write_json};
use super::ids::{random_suffix, DatasetId};
use super::index;
use super::paths::safe_relative_path;
use super::record::{now_rfc3339, DatasetRecord, DatasetSource};
use super::run_store::{RunStore, DATASETS, DATASET_RECORD, STAGING_PREFIX};
use super::usage::tree_bytes;
use crate::dataset::{DatasetError, Manifest};
use std::path::{Path, PathBuf};

/// A folder under `datasets/.staging-*` that becomes a dataset on
/// [`RunStore::commit_dataset`]; removed with everything in it when dropped uncommitted.
#[derive(Debug)]
pub struct StagingDir {
    path: PathBuf,
    committed: bool,
}

impl StagingDir {
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes `bytes` to `rel` (see [`safe_relative_path`]) inside the staging folder, atomically.
    pub fn write_file(&self, rel: &str, bytes: &[u8]) -> Result<PathBuf> {
        let path = self.path.join(safe_relative_path(rel)?);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io(parent))?;
        }
        crate::atomic_write::write_atomically(&path, bytes).map_err(io(&path))?;
        Ok(path)
    }
}

impl Drop for StagingDir {
    fn drop(&mut self) {
        if !self.committed {
            if let Err(e) = remove_dir(&self.path) {
                tracing::warn!("cannot remove a staging folder: {e}");
            }
        }
    }
}

/// Width, height and bit depth of a frame (TIFF, PNG or BMP), from its header alone.
fn frame_header(path: &Path) -> Result<crate::image::FrameInfo> {
    crate::image::read_image_header(path).map_err(|e| {
        StoreError::Dataset(DatasetError::Invalid {
            path: path.into(),
            message: format!("not a readable frame: {e}"),
        })
    })
}

impl RunStore {
    /// Bytes the stored datasets take (every file under `DATA/datasets` but the staging
    /// folders of uploads in progress, which their uploads count): what the datasets quota is
    /// held against.
    pub fn datasets_bytes(&self) -> Result<u64> {
        let dir = self.data_dir().join(DATASETS);
        let in_progress = |name: &str| name.starts_with(STAGING_PREFIX);
        tree_bytes(&dir, &in_progress).map_err(io(dir))
    }

    /// A fresh, empty staging folder for a dataset being uploaded or imported.
    pub fn stage_dataset(&self) -> Result<StagingDir> {
        let datasets = self.data_dir().join(DATASETS);
        loop {
            let path = datasets.join(format!("{STAGING_PREFIX}{}", random_suffix(12)));
            match std::fs::create_dir(&path) {
                Ok(()) => {
                    return Ok(StagingDir {
                        path,
                        committed: false,
                    })
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(StoreError::Io { path, source: e }),
            }
        }
    }

    /// Checks the staged dataset — `dataset.json` reads and validates, every file it names is a
    /// regular file, every name is safe, `record.json` is not taken — then writes its record and
    /// renames the folder into `datasets/{id}`. `name` empty means the manifest's name. On any
    /// error the staging folder is removed.
    pub fn commit_dataset(
        &self,
        mut staging: StagingDir,
        name: &str,
        source: DatasetSource,
    ) -> Result<DatasetRecord> {
        let dir = staging.path.clone();
        let manifest = Manifest::read(&dir)?;
        let manifest_path = dir.join("dataset.json");
        for run in &manifest.runs {
            let named = std::iter::once(&run.reference)
                .chain([&run.deformed])
                .chain(&run.repeat);
            for file in named {
                let is_file = std::fs::symlink_metadata(dir.join(file))
                    .map(|m| m.is_file())
                    .unwrap_or(false);
                if !is_file {
                    return Err(DatasetError::Invalid {
                        path: manifest_path,
                        message: format!("run {}: file '{file}' is missing", run.id),
                    }
                    .into());
                }
            }
        }
        let files = list_files(&dir, false)?;
        if files.iter().any(|f| f == DATASET_RECORD) {
            return Err(StoreError::BadPath(format!(
                "'{DATASET_RECORD}' is the store's own file in a dataset"
            )));
        }
        // The full-resolution frames' header (a hardware scheme's frames are smaller): the size
        // when the manifest states no camera, and the bit depth.
        let first = manifest.runs.iter().find(|r| r.capture.is_none());
        let header = frame_header(&dir.join(&first.unwrap_or(&manifest.runs[0]).reference));
        let (width, height, bit_depth) = match (&manifest.camera, header) {
            (Some(c), header) => (c.width, c.height, header.ok().map(|h| h.bit_depth)),
            (None, header) => {
                let h = header?;
                (h.width, h.height, Some(h.bit_depth))
            }
        };
        let name = if name.trim().is_empty() {
            manifest.name.clone()
        } else {
            name.to_string()
        };

        let datasets = self.data_dir().join(DATASETS);
        // Held from choosing the id to the commit, so no two datasets take one id.
        let mut db = self.db();
        let id = loop {
            let id = DatasetId::generate();
            if !datasets.join(id.as_str()).exists() {
                break id;
            }
        };
        let record = DatasetRecord {
            id: id.clone(),
            name,
            created_at: now_rfc3339(),
            source,
            runs: manifest.runs.len(),
            width,
            height,
            bit_depth,
            files,
        };
        write_json(&dir.join(DATASET_RECORD), &record)?;
        sync_dir(&dir)?;
        let tx = db.transaction()?;
        index::upsert_dataset(&tx, &record)?;
        let target = self.dataset_dir(&id);
        std::fs::rename(&dir, &target).map_err(io(&target))?;
        // Until the index commits, dropping `staging` removes the dataset again.
        staging.path = target;
        tx.commit()?;
        staging.committed = true;
        if let Err(e) = sync_dir(&datasets) {
            tracing::warn!(dataset = %id, "{e}");
        }
        Ok(record)
    }

    /// Brings the dataset folder `src` (e.g. an experiment's `frames/`) into the store through a
    /// staging folder (hard links on the same filesystem, copies elsewhere) and commits it. Hidden files are left out; symbolic links are refused.
    pub fn import_dataset_dir(
        &self,
        src: &Path,
        name: &str,
        source: DatasetSource,
    ) -> Result<DatasetRecord> {
        if !src.is_dir() {
            return Err(StoreError::NotFound(format!("folder {}", src.display())));
        }
        let staging = self.stage_dataset()?;
        for rel in list_files(src, true)? {
            let from = src.join(&rel);
            let to = staging.path().join(&rel);
            if let Some(parent) = to.parent() {
                std::fs::create_dir_all(parent).map_err(io(parent))?;
            }
            // A frame the store already holds (an experiment's export in its run folder) is
            // linked, not written again. Across filesystems: a copy.
            crate::atomic_write::link_or_copy(&from, &to).map_err(|(path, e)| io(&path)(e))?;
        }
        self.commit_dataset(staging, name, source)
    }

    /// Dataset `id` as its `record.json` says.
    pub fn get_dataset(&self, id: &DatasetId) -> Result<DatasetRecord> {
        read_json(&self.dataset_dir(id).join(DATASET_RECORD))?
            .ok_or_else(|| StoreError::NotFound(format!("dataset {id}")))
    }

    /// Every stored dataset, newest first.
    pub fn list_datasets(&self) -> Result<Vec<DatasetRecord>> {
        index::list_datasets(&self.db(), usize::MAX, None)
    }

    /// A page of [`RunStore::list_datasets`]: at most `limit` after `after`.
    pub fn list_datasets_page(
        &self,
        limit: usize,
        after: Option<&index::PageAfter>,
    ) -> Result<Vec<DatasetRecord>> {
        index::list_datasets(&self.db(), limit, after)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_size_comes_from_the_frame_header() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.tif");
        std::fs::write(&p, crate::image::tiff_u16_bytes(7, 2, &[1u16; 14]).unwrap()).unwrap();
        let info = frame_header(&p).unwrap();
        assert_eq!((info.width, info.height, info.bit_depth), (7, 2, 16));
        std::fs::write(&p, b"II*\0garbage").unwrap();
        assert!(matches!(frame_header(&p), Err(StoreError::Dataset(_))));
        // A PNG (by its first bytes, whatever its name): 16-bit grey, 5x3.
        let mut png_bytes = Vec::new();
        {
            let mut e = png::Encoder::new(&mut png_bytes, 5, 3);
            e.set_color(png::ColorType::Grayscale);
            e.set_depth(png::BitDepth::Sixteen);
            let mut w = e.write_header().unwrap();
            w.write_image_data(&[0u8; 30]).unwrap();
        }
        std::fs::write(&p, &png_bytes).unwrap();
        let info = frame_header(&p).unwrap();
        assert_eq!((info.width, info.height, info.bit_depth), (5, 3, 16));
    }

    #[test]
    fn a_staging_folder_is_removed_unless_committed() {
        let dir = tempfile::tempdir().unwrap();
        let (store, _) = RunStore::open(dir.path()).unwrap();
        let s = store.stage_dataset().unwrap();
        let p = s.write_file("sub/a.tif", b"x").unwrap();
        assert!(p.starts_with(s.path()) && p.is_file());
        assert!(s
            .path()
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with(STAGING_PREFIX));
        let path = s.path().to_path_buf();
        drop(s);
        assert!(!path.exists());
    }
}
