//! A run's files written into a folder and its events kept: the sink the service gives the
//! experiment runner writes into the store; tests run the same runner without HTTP.

use ffdic::experiment::RunSink;
use ffdic::run_event::EventKind;

pub struct FolderSink {
    pub dir: std::path::PathBuf,
    pub events: std::sync::Mutex<Vec<String>>,
}

impl FolderSink {
    pub fn new(dir: &std::path::Path) -> Self {
        Self {
            dir: dir.to_owned(),
            events: Default::default(),
        }
    }
}

impl RunSink for FolderSink {
    fn event(&self, kind: EventKind, _progress: f64, message: &str, _data: serde_json::Value) {
        self.events
            .lock()
            .unwrap()
            .push(format!("{kind:?}: {message}"));
    }

    fn write(&self, rel: &str, bytes: &[u8]) -> Result<std::path::PathBuf, String> {
        let path = self.dir.join(rel);
        std::fs::create_dir_all(path.parent().unwrap()).map_err(|e| e.to_string())?;
        std::fs::write(&path, bytes).map_err(|e| e.to_string())?;
        Ok(path)
    }

    fn cancelled(&self) -> bool {
        false
    }
}
