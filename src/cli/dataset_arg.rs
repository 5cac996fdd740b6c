//! A dataset on the command line: its folder, or the `dataset.json` inside it (what a user
//! tab-completes to, or copies from a file manager).

use std::path::PathBuf;

/// The clap value parser of a DATASET argument: a folder as given; a path to a `dataset.json`
/// as its folder; any other file refused, saying what is taken.
pub fn dataset_folder(arg: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(arg);
    if !path.is_file() {
        // A folder, or nothing there: the manifest's reader says what is missing.
        return Ok(path);
    }
    if path.file_name().is_some_and(|n| n == "dataset.json") {
        let folder = path.parent().map(PathBuf::from).unwrap_or_default();
        return Ok(if folder.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            folder
        });
    }
    Err(format!(
        "{arg} is a file; a dataset is its folder or the folder's dataset.json"
    ))
}
