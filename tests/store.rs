//! The run store through its public API: folders are the truth, the index a cache.

use ffdic::run_event::EventKind;
use ffdic::store::{
    rebuild_index, DatasetRecord, DatasetSource, RunId, RunKind, RunRecord, RunStatus, RunStore,
    StoreError,
};
use serde_json::json;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn open(dir: &Path) -> RunStore {
    RunStore::open(dir).expect("store opens").0
}

fn new_run(store: &RunStore, kind: RunKind) -> RunRecord {
    store
        .create_run(kind, json!({ "n": 1 }), None, None)
        .unwrap()
        .0
}

/// Every file under `dir` with its bytes, to show what an operation changed.
fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, &mut out);
    out
}

fn tree_without_index(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut t = tree(dir);
    t.retain(|p, _| !p.to_string_lossy().contains("index.sqlite"));
    t
}

#[test]
fn store_is_shareable_between_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<RunStore>();
    assert_send_sync::<ffdic::store::StagingDir>();
}

#[test]
fn a_run_moves_forward_only_and_its_end_is_final() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    assert_eq!(r.status, RunStatus::Queued);
    assert!(r.id.as_str().starts_with("exp-"));
    assert!(matches!(
        store.set_status(&r.id, RunStatus::Succeeded, "too early"),
        Err(StoreError::Transition {
            from: RunStatus::Queued,
            to: RunStatus::Succeeded
        })
    ));
    let running = store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    assert!(running.started_at.is_some() && running.finished_at.is_none());
    for back in [RunStatus::Queued, RunStatus::Running] {
        assert!(matches!(
            store.set_status(&r.id, back, "back"),
            Err(StoreError::Transition { .. })
        ));
    }
    store.set_progress(&r.id, 0.4, "working").unwrap();
    let done = store
        .set_status(&r.id, RunStatus::Succeeded, "done")
        .unwrap();
    assert_eq!(done.progress, 1.0);
    assert!(done.finished_at.is_some());
    assert_eq!(store.get(&r.id).unwrap(), done);
    for next in RunStatus::ALL {
        assert!(matches!(
            store.set_status(&r.id, next, "again"),
            Err(StoreError::Finished(_))
        ));
    }
    let kinds: Vec<&str> = store
        .events(&r.id, None)
        .unwrap()
        .into_iter()
        .map(|e| e.kind.as_str())
        .collect();
    assert_eq!(kinds, ["queued", "started", "succeeded"]);
    assert_eq!(store.get(&r.id).unwrap().status, RunStatus::Succeeded);
}

#[test]
fn progress_never_goes_down() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Analysis);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    assert_eq!(
        store.set_progress(&r.id, 0.5, "half").unwrap().progress,
        0.5
    );
    let after = store.set_progress(&r.id, 0.2, "later").unwrap();
    assert_eq!((after.progress, after.message.as_str()), (0.5, "later"));
    assert_eq!(
        store.set_progress(&r.id, f64::NAN, "nan").unwrap().progress,
        0.5
    );
    assert_eq!(
        store.set_progress(&r.id, 7.0, "over").unwrap().progress,
        1.0
    );
}

#[test]
fn an_ended_run_takes_no_more_writes() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    store.write_file(&r.id, "results/a.csv", b"x\n1\n").unwrap();
    store.set_status(&r.id, RunStatus::Failed, "broke").unwrap();
    let before = tree_without_index(dir.path());
    assert!(matches!(
        store.write_file(&r.id, "results/b.csv", b"late"),
        Err(StoreError::Finished(_))
    ));
    assert!(matches!(
        store.write_file(&r.id, "results/a.csv", b"overwrite"),
        Err(StoreError::Finished(_))
    ));
    assert!(matches!(
        store.append_event(&r.id, EventKind::Progress, 0.9, "late", json!({})),
        Err(StoreError::Finished(_))
    ));
    assert!(matches!(
        store.set_progress(&r.id, 0.9, "late"),
        Err(StoreError::Finished(_))
    ));
    assert_eq!(tree_without_index(dir.path()), before);
    assert_eq!(store.read_file(&r.id, "results/a.csv").unwrap(), b"x\n1\n");
    assert_eq!(store.get(&r.id).unwrap().result_files, ["results/a.csv"]);
    assert_eq!(
        store.events(&r.id, None).unwrap().last().unwrap().kind,
        EventKind::Failed
    );
}

#[test]
fn only_set_status_writes_status_events() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    for kind in RunStatus::ALL.map(RunStatus::event_kind) {
        assert!(
            matches!(
                store.append_event(&r.id, kind, 0.0, "", json!(null)),
                Err(StoreError::BadEvent(_))
            ),
            "{kind:?}"
        );
    }
    assert_eq!(store.events(&r.id, None).unwrap().len(), 1);
}

#[test]
fn an_idempotency_key_returns_the_same_run() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let req = json!({ "name": "paper", "moves": [5.0] });
    let (a, created_a) = store
        .create_run(RunKind::Experiment, req.clone(), Some("k-1"), None)
        .unwrap();
    let (b, created_b) = store
        .create_run(RunKind::Experiment, req.clone(), Some("k-1"), None)
        .unwrap();
    assert!(created_a && !created_b);
    assert_eq!(a.id, b.id);
    assert_eq!(a.idempotency_key.as_deref(), Some("k-1"));
    // Still the same run once it has moved on, and after a restart.
    store.set_status(&a.id, RunStatus::Running, "go").unwrap();
    drop(store);
    let store = open(dir.path());
    let (c, created_c) = store
        .create_run(RunKind::Experiment, req.clone(), Some("k-1"), None)
        .unwrap();
    assert!(!created_c);
    assert_eq!((c.id, c.status), (a.id.clone(), RunStatus::Failed));
    // Keys are per kind; an empty key is no key; a key reused for another request conflicts.
    let (d, created_d) = store
        .create_run(RunKind::Analysis, req.clone(), Some("k-1"), None)
        .unwrap();
    assert!(created_d && d.id != a.id);
    let e = store
        .create_run(RunKind::Experiment, req.clone(), Some(""), None)
        .unwrap();
    let f = store
        .create_run(RunKind::Experiment, req.clone(), Some(""), None)
        .unwrap();
    assert!(e.1 && f.1 && e.0.id != f.0.id);
    assert_eq!(e.0.idempotency_key, None);
    assert!(matches!(
        store.create_run(
            RunKind::Experiment,
            json!({ "name": "other" }),
            Some("k-1"),
            None
        ),
        Err(StoreError::Conflict(_))
    ));
    assert_eq!(
        store
            .list(None, Some(RunKind::Experiment), 100)
            .unwrap()
            .len(),
        3
    );
}

#[test]
fn one_key_sent_by_many_threads_at_once_makes_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let store = Arc::new(open(dir.path()));
    let handles: Vec<_> = (0..8)
        .map(|_| {
            let store = store.clone();
            std::thread::spawn(move || {
                store
                    .create_run(RunKind::Experiment, json!({}), Some("same"), None)
                    .unwrap()
            })
        })
        .collect();
    let results: Vec<(RunRecord, bool)> = handles.into_iter().map(|h| h.join().unwrap()).collect();
    assert_eq!(results.iter().filter(|(_, created)| *created).count(), 1);
    assert!(results.iter().all(|(r, _)| r.id == results[0].0.id));
    assert_eq!(
        std::fs::read_dir(dir.path().join("runs")).unwrap().count(),
        1
    );
}

#[test]
fn recovery_fails_unfinished_runs_and_leaves_ended_ones_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let running = new_run(&store, RunKind::Experiment);
    store
        .set_status(&running.id, RunStatus::Running, "go")
        .unwrap();
    store
        .append_event(
            &running.id,
            EventKind::FrameCaptured,
            0.3,
            "a_ref.tif",
            json!({}),
        )
        .unwrap();
    let queued = new_run(&store, RunKind::Analysis);
    let done = new_run(&store, RunKind::Comparison);
    store
        .set_status(&done.id, RunStatus::Running, "go")
        .unwrap();
    store.write_file(&done.id, "results/r.json", b"{}").unwrap();
    store
        .set_status(&done.id, RunStatus::Succeeded, "ok")
        .unwrap();
    let done_dir = store.run_dir(&done.id);
    let done_before = tree(&done_dir);
    let done_mtime = std::fs::metadata(done_dir.join("run.json"))
        .unwrap()
        .modified()
        .unwrap();
    drop(store); // the process "dies" here

    let (store, report) = RunStore::open(dir.path()).unwrap();
    let mut failed = report.failed.clone();
    failed.sort();
    let mut expected = vec![running.id.clone(), queued.id.clone()];
    expected.sort();
    assert_eq!(failed, expected);
    assert!(report.completed.is_empty() && report.unreadable.is_empty());

    let r = store.get(&running.id).unwrap();
    assert_eq!(r.status, RunStatus::Failed);
    assert_eq!(r.message, "the server stopped while this run was running");
    assert!(r.finished_at.is_some());
    let ev = store.events(&running.id, None).unwrap();
    assert_eq!(ev.iter().map(|e| e.id).collect::<Vec<_>>(), [1, 2, 3, 4]);
    assert_eq!(ev[3].kind, EventKind::Failed);
    assert_eq!(ev[3].message, r.message);

    let q = store.get(&queued.id).unwrap();
    assert_eq!(q.status, RunStatus::Failed);
    assert_eq!(q.message, "the server stopped while this run was queued");
    assert_eq!(
        store.events(&queued.id, None).unwrap().last().unwrap().kind,
        EventKind::Failed
    );

    assert_eq!(tree(&done_dir), done_before);
    assert_eq!(
        std::fs::metadata(done_dir.join("run.json"))
            .unwrap()
            .modified()
            .unwrap(),
        done_mtime
    );
    // The index agrees with the folders.
    assert_eq!(
        store.list(Some(RunStatus::Failed), None, 10).unwrap().len(),
        2
    );
    assert_eq!(
        store
            .list(Some(RunStatus::Running), None, 10)
            .unwrap()
            .len(),
        0
    );

    // A second open finds nothing more to do and changes nothing.
    drop(store);
    let before = tree_without_index(dir.path());
    let (_, again) = RunStore::open(dir.path()).unwrap();
    assert!(again.failed.is_empty());
    assert_eq!(tree_without_index(dir.path()), before);
}

#[test]
fn a_crash_between_the_terminal_event_and_run_json_is_completed_not_failed() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    let run_json = std::fs::read(store.run_dir(&r.id).join("run.json")).unwrap();
    store
        .set_status(&r.id, RunStatus::Succeeded, "all done")
        .unwrap();
    drop(store);
    // Put back the run.json from before the end: as if the process died right after the event.
    std::fs::write(
        dir.path().join("runs").join(r.id.as_str()).join("run.json"),
        run_json,
    )
    .unwrap();
    let (store, report) = RunStore::open(dir.path()).unwrap();
    assert_eq!(report.completed, std::slice::from_ref(&r.id));
    assert!(report.failed.is_empty());
    let after = store.get(&r.id).unwrap();
    assert_eq!((after.status, after.progress), (RunStatus::Succeeded, 1.0));
    assert_eq!(after.message, "all done");
    assert_eq!(store.events(&r.id, None).unwrap().len(), 3);
}

#[test]
fn rebuilding_the_index_from_the_folders_gives_the_same_lists() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let mut ids = Vec::new();
    for (i, kind) in RunKind::ALL.into_iter().cycle().take(7).enumerate() {
        let (r, _) = store
            .create_run(kind, json!({ "i": i }), Some(&format!("key-{i}")), None)
            .unwrap();
        store.set_status(&r.id, RunStatus::Running, "go").unwrap();
        let end = [
            RunStatus::Succeeded,
            RunStatus::Failed,
            RunStatus::Cancelled,
        ][i % 3];
        store.set_status(&r.id, end, "end").unwrap();
        ids.push(r.id);
    }
    let cancelled = store
        .create_run(RunKind::Analysis, json!({}), None, None)
        .unwrap()
        .0;
    store
        .set_status(&cancelled.id, RunStatus::Cancelled, "never ran")
        .unwrap();
    stage_and_commit(&store, &good_manifest(), &["a_ref.tif", "a_x5.tif"]).unwrap();
    let runs_before = store.list(None, None, 100).unwrap();
    let datasets_before = store.list_datasets().unwrap();
    assert_eq!(runs_before.len(), 8);
    assert_eq!(datasets_before.len(), 1);
    let created: Vec<&str> = runs_before.iter().map(|r| r.created_at.as_str()).collect();
    assert!(
        created.windows(2).all(|w| w[0] >= w[1]),
        "newest first: {created:?}"
    );
    assert_eq!(runs_before[0].id, cancelled.id);
    drop(store);

    std::fs::remove_file(dir.path().join("index.sqlite")).unwrap();
    let report = rebuild_index(dir.path()).unwrap();
    assert_eq!((report.runs, report.datasets), (8, 1));
    let store = open(dir.path());
    assert_eq!(store.list(None, None, 100).unwrap(), runs_before);
    assert_eq!(store.list_datasets().unwrap(), datasets_before);
    // Filters and the limit work on the rebuilt index, and so do idempotency keys.
    // As many as the original list holds (however many kinds there are to cycle through).
    let cancelled_analyses = runs_before
        .iter()
        .filter(|r| r.status == RunStatus::Cancelled && r.kind == RunKind::Analysis)
        .count();
    assert!(cancelled_analyses >= 1);
    assert_eq!(
        store
            .list(Some(RunStatus::Cancelled), Some(RunKind::Analysis), 100)
            .unwrap()
            .len(),
        cancelled_analyses
    );
    assert_eq!(store.list(None, None, 3).unwrap()[..], runs_before[..3]);
    let (again, created) = store
        .create_run(RunKind::Experiment, json!({ "i": 0 }), Some("key-0"), None)
        .unwrap();
    assert!(!created);
    assert_eq!(again.id, ids[0]);
}

#[test]
fn a_damaged_index_is_rebuilt_from_the_folders() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Diagnosis);
    store
        .set_status(&r.id, RunStatus::Cancelled, "stop")
        .unwrap();
    drop(store);
    for f in ["index.sqlite-wal", "index.sqlite-shm"] {
        let _ = std::fs::remove_file(dir.path().join(f));
    }
    std::fs::write(
        dir.path().join("index.sqlite"),
        b"this is not a database at all",
    )
    .unwrap();
    let store = open(dir.path());
    assert_eq!(store.list(None, None, 10).unwrap()[0].id, r.id);
}

#[test]
fn events_resume_after_an_id() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    for i in 0..5 {
        let e = store
            .append_event(
                &r.id,
                EventKind::Progress,
                i as f64 / 10.0,
                &format!("step {i}"),
                json!({ "i": i }),
            )
            .unwrap();
        assert_eq!(e.id, 3 + i);
        assert_eq!(e.run_id, r.id);
    }
    let all = store.events(&r.id, None).unwrap();
    assert_eq!(
        all.iter().map(|e| e.id).collect::<Vec<_>>(),
        (1..=7).collect::<Vec<_>>()
    );
    let tail = store.events(&r.id, Some(4)).unwrap();
    assert_eq!(tail.iter().map(|e| e.id).collect::<Vec<_>>(), [5, 6, 7]);
    assert_eq!(tail[0].message, "step 2");
    assert_eq!(tail[0].data, json!({ "i": 2 }));
    assert!(store.events(&r.id, Some(7)).unwrap().is_empty());
    assert!(store.events(&r.id, Some(1000)).unwrap().is_empty());
    // Ids continue across a restart.
    drop(store);
    let store = open(dir.path());
    let last = store.events(&r.id, None).unwrap().pop().unwrap();
    assert_eq!((last.id, last.kind.as_str()), (8, "failed"));
    let missing: RunId = "exp-20000101t000000-aaaaaa".parse().unwrap();
    assert!(matches!(
        store.events(&missing, None),
        Err(StoreError::NotFound(_))
    ));
    assert!(matches!(store.get(&missing), Err(StoreError::NotFound(_))));
}

#[test]
fn events_from_many_threads_get_distinct_consecutive_ids() {
    let dir = tempfile::tempdir().unwrap();
    let store = Arc::new(open(dir.path()));
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    let handles: Vec<_> = (0..4)
        .map(|t| {
            let (store, id) = (store.clone(), r.id.clone());
            std::thread::spawn(move || {
                for i in 0..25 {
                    store
                        .append_event(
                            &id,
                            EventKind::Progress,
                            0.0,
                            &format!("{t}/{i}"),
                            json!(null),
                        )
                        .unwrap();
                }
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
    let ids: Vec<u64> = store
        .events(&r.id, None)
        .unwrap()
        .iter()
        .map(|e| e.id)
        .collect();
    assert_eq!(ids, (1..=102).collect::<Vec<_>>());
}

const BAD_NAMES: &[&str] = &[
    "../x",
    "/etc/passwd",
    "a/../../b",
    ".hidden",
    "a\\b",
    "",
    "..",
    "a/./b",
    "a\0b",
    "a/b/c/d/e.txt",
];

#[test]
fn unsafe_file_names_are_refused_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let store = open(&data);
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    let staging = store.stage_dataset().unwrap();
    let before = tree(dir.path());
    for bad in BAD_NAMES {
        assert!(
            matches!(
                store.write_file(&r.id, bad, b"evil"),
                Err(StoreError::BadPath(_))
            ),
            "{bad:?}"
        );
        assert!(
            matches!(
                staging.write_file(bad, b"evil"),
                Err(StoreError::BadPath(_))
            ),
            "{bad:?}"
        );
        assert!(
            matches!(store.read_file(&r.id, bad), Err(StoreError::BadPath(_))),
            "{bad:?}"
        );
    }
    for own in ["run.json", "events.jsonl"] {
        assert!(matches!(
            store.write_file(&r.id, own, b"{}"),
            Err(StoreError::BadPath(_))
        ));
    }
    assert_eq!(tree(dir.path()), before);
    assert!(!dir.path().join("x").exists() && !dir.path().join("b").exists());
    assert!(store.get(&r.id).unwrap().result_files.is_empty());
}

#[test]
fn files_land_in_the_run_folder_and_are_recorded_once() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    let p = store.write_file(&r.id, "frames/a_ref.tif", b"v1").unwrap();
    assert_eq!(p, store.run_dir(&r.id).join("frames/a_ref.tif"));
    store.write_file(&r.id, "frames/a_ref.tif", b"v2").unwrap();
    store.write_file(&r.id, "plots/u.svg", b"<svg/>").unwrap();
    assert_eq!(store.read_file(&r.id, "frames/a_ref.tif").unwrap(), b"v2");
    assert_eq!(
        store.get(&r.id).unwrap().result_files,
        ["frames/a_ref.tif", "plots/u.svg"]
    );
    assert!(matches!(
        store.read_file(&r.id, "frames/none.tif"),
        Err(StoreError::NotFound(_))
    ));
    assert!(matches!(
        store.read_file(&r.id, "frames"),
        Err(StoreError::NotFound(_))
    ));
}

fn good_manifest() -> String {
    manifest_without(&[])
}

/// The manifest of a one-run dataset without the top-level `fields`.
fn manifest_without(fields: &[&str]) -> String {
    let mut m = json!({
        "format": "ffdic-dataset/1", "name": "bench-1", "scale_px_per_mm": 26.0,
        "camera": { "width": 64, "height": 48, "bit_depth": 16 },
        "runs": [ { "id": "a-x5", "reference": "a_ref.tif", "deformed": "a_x5.tif",
                    "stage": { "dx_mm": 5.0, "dy_mm": 0.0 } } ]
    });
    for f in fields {
        m.as_object_mut().unwrap().remove(*f);
    }
    m.to_string()
}

fn stage_and_commit(
    store: &RunStore,
    manifest: &str,
    frames: &[&str],
) -> Result<DatasetRecord, StoreError> {
    let staging = store.stage_dataset()?;
    staging.write_file("dataset.json", manifest.as_bytes())?;
    for f in frames {
        staging.write_file(f, b"not decoded: the manifest gives the size")?;
    }
    store.commit_dataset(staging, "", DatasetSource::Upload)
}

fn datasets_folder(store: &RunStore) -> Vec<String> {
    std::fs::read_dir(store.data_dir().join("datasets"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

#[test]
fn a_valid_dataset_is_committed_whole() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let rec = stage_and_commit(&store, &good_manifest(), &["a_ref.tif", "a_x5.tif"]).unwrap();
    assert!(rec.id.as_str().starts_with("ds-"));
    assert_eq!(
        (rec.name.as_str(), rec.source.to_string().as_str()),
        ("bench-1", "upload")
    );
    assert_eq!((rec.runs, rec.width, rec.height), (1, 64, 48));
    assert_eq!(rec.files, ["a_ref.tif", "a_x5.tif", "dataset.json"]);
    assert_eq!(datasets_folder(&store), [rec.id.to_string()]);
    let d = store.dataset_dir(&rec.id);
    assert!(d.join("record.json").is_file() && d.join("a_x5.tif").is_file());
    assert_eq!(store.get_dataset(&rec.id).unwrap(), rec);
    assert_eq!(store.list_datasets().unwrap(), std::slice::from_ref(&rec));
    ffdic::dataset::Manifest::read(&d).unwrap();
}

#[test]
fn a_failed_dataset_commit_leaves_no_folder_behind() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let missing_frame = stage_and_commit(&store, &good_manifest(), &["a_ref.tif"]);
    assert!(
        matches!(&missing_frame, Err(StoreError::Dataset(e)) if e.to_string().contains("a_x5.tif")),
        "{missing_frame:?}"
    );
    let corrupt = stage_and_commit(
        &store,
        "{ \"format\": \"ffdic-dataset/1\", ",
        &["a_ref.tif"],
    );
    assert!(
        matches!(corrupt, Err(StoreError::Dataset(_))),
        "{corrupt:?}"
    );
    let no_scale = manifest_without(&["scale_px_per_mm"]);
    let missing_field = stage_and_commit(&store, &no_scale, &["a_ref.tif", "a_x5.tif"]);
    assert!(
        matches!(&missing_field, Err(StoreError::Dataset(e)) if e.to_string().contains("scale_px_per_mm")),
        "{missing_field:?}"
    );
    let reserved = stage_and_commit(
        &store,
        &good_manifest(),
        &["a_ref.tif", "a_x5.tif", "record.json"],
    );
    assert!(
        matches!(reserved, Err(StoreError::BadPath(_))),
        "{reserved:?}"
    );
    let no_manifest = {
        let staging = store.stage_dataset().unwrap();
        staging.write_file("a_ref.tif", b"x").unwrap();
        store.commit_dataset(staging, "x", DatasetSource::Upload)
    };
    assert!(matches!(no_manifest, Err(StoreError::Dataset(_))));
    // A staging folder dropped without a commit (an upload that broke off) goes too.
    let abandoned = store.stage_dataset().unwrap();
    abandoned.write_file("a_ref.tif", b"x").unwrap();
    let path = abandoned.path().to_path_buf();
    assert!(path.is_dir());
    drop(abandoned);
    assert!(!path.exists());

    assert!(
        datasets_folder(&store).is_empty(),
        "{:?}",
        datasets_folder(&store)
    );
    assert!(store.list_datasets().unwrap().is_empty());
}

#[test]
fn an_experiment_export_is_imported_as_a_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = new_run(&store, RunKind::Experiment);
    store.set_status(&r.id, RunStatus::Running, "go").unwrap();
    // No camera block: the size comes from the reference frame's TIFF header.
    let manifest = manifest_without(&["camera"]);
    assert!(!manifest.contains("camera"), "{manifest}");
    let tif = ffdic::image::tiff_u16_bytes(5, 3, &[7u16; 15]).unwrap();
    store
        .write_file(&r.id, "frames/dataset.json", manifest.as_bytes())
        .unwrap();
    store.write_file(&r.id, "frames/a_ref.tif", &tif).unwrap();
    store.write_file(&r.id, "frames/a_x5.tif", &tif).unwrap();
    let frames = store.run_dir(&r.id).join("frames");
    let rec = store
        .import_dataset_dir(&frames, "study", DatasetSource::Experiment(r.id.clone()))
        .unwrap();
    assert_eq!((rec.width, rec.height, rec.runs), (5, 3, 1));
    assert_eq!(rec.name, "study");
    assert_eq!(rec.source, DatasetSource::Experiment(r.id.clone()));
    assert_eq!(rec.source.to_string(), format!("experiment:{}", r.id));
    assert_eq!(
        std::fs::read(store.dataset_dir(&rec.id).join("a_x5.tif")).unwrap(),
        tif
    );
    // The run's own folder is untouched, and its frames are not written a second time: the
    // dataset's file is the same inode.
    assert!(frames.join("a_ref.tif").is_file());
    {
        use std::os::unix::fs::MetadataExt;
        let inode = |p: &std::path::Path| std::fs::metadata(p).unwrap().ino();
        assert_eq!(
            inode(&frames.join("a_x5.tif")),
            inode(&store.dataset_dir(&rec.id).join("a_x5.tif"))
        );
    }
    let missing = store.import_dataset_dir(&dir.path().join("nowhere"), "x", DatasetSource::Upload);
    assert!(matches!(missing, Err(StoreError::NotFound(_))));
    assert_eq!(store.list_datasets().unwrap().len(), 1);
}

/// Issue 12, item 6: a second daemon on the same data folder marked the first one's live run
/// failed. The folder is now held by the first store; the second open is refused, naming it.
#[test]
fn a_second_store_on_the_same_folder_is_refused_and_leaves_live_runs_alone() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let run = new_run(&store, RunKind::Experiment);
    store
        .set_status(&run.id, RunStatus::Running, "running")
        .unwrap();
    match RunStore::open(dir.path()) {
        Err(StoreError::Locked { holder }) => {
            assert_eq!(holder, format!("pid {}", std::process::id()))
        }
        Err(other) => panic!("expected Locked, got {other}"),
        Ok(_) => panic!("a second store opened the held folder"),
    }
    assert_eq!(store.get(&run.id).unwrap().status, RunStatus::Running);
    drop(store);
    // Released with the store: the next open recovers the run as an earlier server's.
    let (_, report) = RunStore::open(dir.path()).unwrap();
    assert_eq!(report.failed, vec![run.id]);
}

/// Issue 12, item 7: a damaged page of the index stopped start-up. The index fails SQLite's
/// integrity check, is recreated and refilled from the folders (the truth).
#[test]
fn a_damaged_index_is_rebuilt_at_open() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let ids: Vec<RunId> = (0..40)
        .map(|_| new_run(&store, RunKind::Analysis).id)
        .collect();
    drop(store);
    let index = dir.path().join("index.sqlite");
    let mut bytes = std::fs::read(&index).expect("the index is a file after a clean close");
    assert!(bytes.len() > 4096, "{} bytes", bytes.len());
    // Page 2 onwards: the header stays readable, the b-tree pages are garbage.
    for b in &mut bytes[4096 + 8..] {
        *b = 0xA5;
    }
    std::fs::write(&index, &bytes).unwrap();
    let store = open(dir.path());
    let listed = store.list(None, None, 1000).unwrap();
    assert_eq!(listed.len(), ids.len());
}

/// A job's typed result is kept for an in-process caller only when it asked (`keep_results`),
/// handed out once, and never kept for a daemon (nobody would take it).
#[test]
fn job_results_are_kept_only_when_asked_and_taken_once() {
    use ffdic::service::{JobOutput, JobResult, Jobs, Lane};
    let run = |jobs: &Jobs| {
        let (record, _) = jobs
            .submit(
                RunKind::Analysis,
                Lane::Compute,
                json!({}),
                None,
                None,
                Box::new(|_| {
                    Ok(JobOutput {
                        message: "done".into(),
                        result: JobResult::Study {
                            rows: Vec::new(),
                            captures: Vec::new(),
                        },
                    })
                }),
            )
            .unwrap();
        let t0 = std::time::Instant::now();
        while !jobs.store().get(&record.id).unwrap().status.is_terminal() {
            assert!(t0.elapsed().as_secs() < 30, "the job never ended");
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        record.id
    };
    let dir = tempfile::tempdir().unwrap();
    let jobs = Jobs::start(Arc::new(open(dir.path())));
    let id = run(&jobs);
    assert!(jobs.take_result(&id).is_none(), "a daemon keeps nothing");
    jobs.keep_results();
    let id = run(&jobs);
    assert!(matches!(
        jobs.take_result(&id),
        Some(JobResult::Study { .. })
    ));
    assert!(jobs.take_result(&id).is_none(), "taken once");
    jobs.cancel_all();
    jobs.join_workers(std::time::Duration::from_secs(5));
}
