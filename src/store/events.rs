//! `events.jsonl`: one JSON event per line, appended and synced one at a time. A crash can leave
//! at most a torn last line; readers skip it and the next append starts on a fresh line.

use super::error::{io, Result, StoreError};
use super::record::Event;
use crate::atomic_write::Sync;
use std::fs::OpenOptions;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;

pub const FILE: &str = "events.jsonl";

/// Appends `event` as one line and syncs the file.
pub fn append(path: &Path, event: &Event) -> Result<()> {
    append_with(path, event, Sync::Now)
}

/// Appends `event` as one line, synced as `sync` says.
pub fn append_with(path: &Path, event: &Event, sync: Sync) -> Result<()> {
    let mut line = serde_json::to_vec(event).expect("an event always serialises");
    line.push(b'\n');
    let mut file = OpenOptions::new()
        .read(true)
        .append(true)
        .create(true)
        .open(path)
        .map_err(io(path))?;
    let len = file.metadata().map_err(io(path))?.len();
    if len > 0 {
        // Seal a line torn by an earlier crash so it cannot swallow this one.
        let mut last = [0u8; 1];
        file.seek(SeekFrom::Start(len - 1)).map_err(io(path))?;
        file.read_exact(&mut last).map_err(io(path))?;
        if last[0] != b'\n' {
            line.insert(0, b'\n');
        }
    }
    file.write_all(&line).map_err(io(path))?;
    match sync {
        Sync::Now => file.sync_data().map_err(io(path)),
        Sync::Batched => Ok(()),
    }
}

/// Every event with an id above `after` (all when `None`), in file order. A missing file is an
/// empty log; lines that do not parse (a torn last line) are skipped.
pub fn read(path: &Path, after: Option<u64>) -> Result<Vec<Event>> {
    let text = match std::fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => {
            return Err(StoreError::Io {
                path: path.into(),
                source: e,
            })
        }
    };
    let after = after.unwrap_or(0);
    Ok(text
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty())
        .filter_map(|l| match serde_json::from_slice::<Event>(l) {
            Ok(e) => Some(e),
            Err(err) => {
                tracing::warn!(file = %path.display(), "skipping an unreadable event line: {err}");
                None
            }
        })
        .filter(|e| e.id > after)
        .collect())
}

/// The last readable event, if any.
pub fn last(path: &Path) -> Result<Option<Event>> {
    Ok(read(path, None)?.pop())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn ev(id: u64) -> Event {
        Event {
            id,
            run_id: "exp-1".parse().unwrap(),
            kind: crate::run_event::EventKind::Progress,
            progress: 0.5,
            message: format!("step {id}"),
            at: crate::store::record::now_rfc3339(),
            data: json!({ "n": id }),
        }
    }

    #[test]
    fn appends_read_back_and_resume_after_an_id() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(FILE);
        assert!(read(&p, None).unwrap().is_empty());
        for id in 1..=4 {
            append(&p, &ev(id)).unwrap();
        }
        let all = read(&p, None).unwrap();
        assert_eq!(all.iter().map(|e| e.id).collect::<Vec<_>>(), [1, 2, 3, 4]);
        assert_eq!(all[2].message, "step 3");
        assert_eq!(all[2].data, json!({ "n": 3 }));
        let ids: Vec<u64> = read(&p, Some(2)).unwrap().iter().map(|e| e.id).collect();
        assert_eq!(ids, [3, 4]);
        assert!(read(&p, Some(4)).unwrap().is_empty());
        assert_eq!(last(&p).unwrap().unwrap().id, 4);
    }

    #[test]
    fn a_torn_last_line_is_skipped_and_sealed() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(FILE);
        append(&p, &ev(1)).unwrap();
        std::fs::OpenOptions::new()
            .append(true)
            .open(&p)
            .unwrap()
            .write_all(b"{\"id\":2,\"run_")
            .unwrap();
        assert_eq!(last(&p).unwrap().unwrap().id, 1);
        append(&p, &ev(2)).unwrap();
        let ids: Vec<u64> = read(&p, None).unwrap().iter().map(|e| e.id).collect();
        assert_eq!(ids, [1, 2]);
    }
}
