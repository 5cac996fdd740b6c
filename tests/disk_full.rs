//! Issue 12, item 5: a run whose terminal write fails (a full disk) must not stay `running` for
//! ever, and cancel must end it or say why it cannot. The data folder sits on a small tmpfs the
//! test mounts (root, as in CI); the job fills the disk itself, so its end cannot be written.
//! Issue 36: an upload that meets a full disk is 507, as every other store write, not 500.

use crate::common::daemon;

use ffdic::service::{JobOutput, JobResult, Jobs, Lane};
use ffdic::store::{RunKind, RunStatus, RunStore};
use serde_json::json;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A tmpfs of `size` mounted for the test's lifetime.
struct Tmpfs {
    dir: tempfile::TempDir,
}

impl Tmpfs {
    fn mount(size: &str) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let status = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir.path())
            .status()
            .expect("mount runs");
        assert!(
            status.success(),
            "mounting a tmpfs needs root (CI has it): {status}"
        );
        Self { dir }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.dir.path()).status();
    }
}

/// Writes `path` until the file system refuses: the disk is full.
fn fill(path: &Path) {
    let mut f = std::fs::File::create(path).unwrap();
    let block = vec![0u8; 64 * 1024];
    loop {
        if f.write_all(&block).and_then(|_| f.sync_all()).is_err() {
            break;
        }
    }
    // Whatever smaller writes still fit.
    while f.write_all(&[0u8; 512]).and_then(|_| f.sync_all()).is_ok() {}
}

fn wait_for(what: &str, limit: Duration, mut done: impl FnMut() -> bool) {
    let t = Instant::now();
    while !done() {
        assert!(t.elapsed() < limit, "{what} after {limit:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_run_whose_end_cannot_be_written_ends_once_space_returns_and_cancel_says_why_not_before() {
    let disk = Tmpfs::mount("16m");
    let data = disk.path().join("data");
    let filler: PathBuf = disk.path().join("filler");
    let (store, _) = RunStore::open(&data).unwrap();
    let store = Arc::new(store);
    let jobs = Jobs::start(store.clone());
    let filler_in_job = filler.clone();
    let (record, _) = jobs
        .submit(
            RunKind::Analysis,
            Lane::Compute,
            json!({}),
            None,
            None,
            Box::new(move |_| {
                fill(&filler_in_job);
                Ok(JobOutput {
                    message: "done".into(),
                    result: JobResult::Files,
                })
            }),
        )
        .unwrap();
    let id = record.id.clone();
    wait_for(
        "the job never filled the disk",
        Duration::from_secs(30),
        || std::fs::metadata(&filler).is_ok_and(|m| m.len() > 1 << 20),
    );
    // The work has returned; its end cannot be written.
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(store.get(&id).unwrap().status, RunStatus::Running);

    // Cancel cannot write either: it says so instead of answering as if it had worked.
    let refused = jobs.cancel(&id).unwrap_err();
    assert!(refused.is_storage_full(), "{refused}");
    assert_eq!(store.get(&id).unwrap().status, RunStatus::Running);

    // Space returns: the run ends on its own, failed (its files may be incomplete).
    std::fs::remove_file(&filler).unwrap();
    wait_for("the run never ended", Duration::from_secs(10), || {
        store.get(&id).unwrap().status.is_terminal()
    });
    let ended = store.get(&id).unwrap();
    assert_eq!(ended.status, RunStatus::Failed, "{ended:?}");
    assert!(
        ended.message.contains("could not record the end"),
        "{ended:?}"
    );
    let events = store.events(&id, None).unwrap();
    assert_eq!(events.last().unwrap().kind.as_str(), "failed");
}

#[test]
fn cancel_ends_a_running_run_that_no_worker_holds() {
    // A run left `running` by another process's lifetime (its worker is gone): cancel ends it.
    let dir = tempfile::tempdir().unwrap();
    let (store, _) = RunStore::open(dir.path()).unwrap();
    let store = Arc::new(store);
    let (run, _) = store
        .create_run(RunKind::Analysis, json!({}), None, None)
        .unwrap();
    store
        .set_status(&run.id, RunStatus::Running, "running")
        .unwrap();
    let jobs = Jobs::start(store.clone());
    let r = jobs.cancel(&run.id).unwrap();
    assert_eq!(r.status, RunStatus::Cancelled);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_upload_that_meets_a_full_disk_is_507_and_leaves_nothing() {
    let disk = Tmpfs::mount("8m");
    let data = disk.path().join("data");
    let server = daemon::TestServer::start(daemon::small_config(&data)).await;
    // Two 4 MB frames: the second cannot be staged.
    let frame = ffdic::image::tiff_u16_bytes(2048, 1024, &vec![7u16; 2048 * 1024]).unwrap();
    let manifest = json!({"format": "ffdic-dataset/1", "name": "full", "scale_px_per_mm": 13.0,
        "runs": [{"id": "r1", "reference": "ref.tif", "deformed": "def.tif",
                  "stage": {"dx_mm": 0.0, "dy_mm": 0.0}}]});
    let part = |name: &str, bytes: Vec<u8>| {
        reqwest::multipart::Part::bytes(bytes).file_name(name.to_string())
    };
    let form = reqwest::multipart::Form::new()
        .part(
            "dataset.json",
            part("dataset.json", manifest.to_string().into_bytes()),
        )
        .part("ref.tif", part("ref.tif", frame.clone()))
        .part("def.tif", part("def.tif", frame));
    let r = daemon::client()
        .post(server.url("/datasets"))
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 507);
    let p: serde_json::Value = r.json().await.unwrap();
    assert!(
        !p["detail"]
            .as_str()
            .unwrap()
            .contains(&data.display().to_string()),
        "no server path: {p}"
    );
    let left: Vec<_> = std::fs::read_dir(data.join("datasets"))
        .unwrap()
        .flatten()
        .collect();
    assert!(left.is_empty(), "{left:?}");
    server.stop().await;
}
