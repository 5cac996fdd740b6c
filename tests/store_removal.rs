//! Issue 36, quotas and deletion in the run store: deleting runs, datasets and models (refused
//! while in use), the run folders' quota, and the retention policy.

use ffdic::store::{
    folder_bytes, DatasetId, DatasetRecord, DatasetSource, Retention, RunKind, RunRecord,
    RunStatus, RunStore, StoreError,
};
use serde_json::json;
use std::path::Path;
use std::time::{Duration, SystemTime};

fn open(dir: &Path) -> RunStore {
    RunStore::open(dir).expect("store opens").0
}

fn run_of(
    store: &RunStore,
    kind: RunKind,
    request: serde_json::Value,
    dataset: Option<DatasetId>,
) -> RunRecord {
    store.create_run(kind, request, None, dataset).unwrap().0
}

fn ended(store: &RunStore, r: &RunRecord) {
    store
        .set_status(&r.id, RunStatus::Running, "running")
        .unwrap();
    store
        .set_status(&r.id, RunStatus::Succeeded, "done")
        .unwrap();
}

/// A one-run dataset imported from a folder (the frames are not decoded: the manifest gives
/// their size).
fn dataset(store: &RunStore, scratch: &Path) -> DatasetRecord {
    let src = scratch.join(format!("src-{}", rand_suffix()));
    std::fs::create_dir_all(&src).unwrap();
    let manifest = json!({
        "format": "ffdic-dataset/1", "name": "d", "scale_px_per_mm": 26.0,
        "camera": { "width": 64, "height": 48, "bit_depth": 16 },
        "runs": [ { "id": "a-x5", "reference": "ref.tif", "deformed": "x5.tif",
                    "stage": { "dx_mm": 5.0, "dy_mm": 0.0 } } ]
    });
    std::fs::write(src.join("dataset.json"), manifest.to_string()).unwrap();
    for f in ["ref.tif", "x5.tif"] {
        std::fs::write(src.join(f), [7u8; 1000]).unwrap();
    }
    store
        .import_dataset_dir(&src, "d", DatasetSource::Upload)
        .unwrap()
}

/// The ids of every run, newest first.
fn listed(store: &RunStore) -> Vec<ffdic::store::RunId> {
    let runs = store.list(None, None, 100).unwrap();
    runs.into_iter().map(|r| r.id).collect()
}

fn rand_suffix() -> String {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    N.fetch_add(1, Ordering::SeqCst).to_string()
}

#[test]
fn a_run_is_deleted_once_ended_and_its_bytes_leave_the_count() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = run_of(&store, RunKind::Analysis, json!({}), None);
    store
        .write_file(&r.id, "results/big.bin", &[1u8; 50_000])
        .unwrap();
    // Queued or running: refused, nothing changes.
    assert!(matches!(store.delete_run(&r.id), Err(StoreError::InUse(_))));
    store
        .set_status(&r.id, RunStatus::Running, "running")
        .unwrap();
    assert!(matches!(store.delete_run(&r.id), Err(StoreError::InUse(_))));
    assert!(store.get(&r.id).is_ok());
    store
        .set_status(&r.id, RunStatus::Succeeded, "done")
        .unwrap();
    // Ended: the count holds the whole folder (file, events, run.json), as measured.
    let folder = folder_bytes(&store.run_dir(&r.id)).unwrap();
    assert!(folder > 50_000);
    assert_eq!(store.runs_bytes(), folder);
    let gone = store.delete_run(&r.id).unwrap();
    assert_eq!(gone.id, r.id);
    assert_eq!(store.runs_bytes(), 0);
    assert!(!store.run_dir(&r.id).exists());
    assert!(matches!(store.get(&r.id), Err(StoreError::NotFound(_))));
    assert!(store.list(None, None, 10).unwrap().is_empty());
    assert!(matches!(
        store.delete_run(&r.id),
        Err(StoreError::NotFound(_))
    ));
    // Nothing hidden is left behind either.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path().join("runs"))
        .unwrap()
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn a_dataset_in_use_is_not_deleted_and_no_run_can_name_a_deleted_one() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let d = dataset(&store, dir.path());
    let user = run_of(&store, RunKind::Comparison, json!({}), Some(d.id.clone()));
    match store.delete_dataset(&d.id) {
        Err(StoreError::InUse(m)) => assert!(m.contains(user.id.as_str()), "{m}"),
        other => panic!("{other:?}"),
    }
    assert!(store.get_dataset(&d.id).is_ok());
    ended(&store, &user);
    store.delete_dataset(&d.id).unwrap();
    assert!(matches!(
        store.get_dataset(&d.id),
        Err(StoreError::NotFound(_))
    ));
    assert!(store.list_datasets().unwrap().is_empty());
    assert_eq!(store.datasets_bytes().unwrap(), 0);
    // The ended run keeps its record; a new one cannot name the dataset.
    assert!(store.get(&user.id).is_ok());
    assert!(matches!(
        store.create_run(RunKind::Analysis, json!({}), None, Some(d.id.clone())),
        Err(StoreError::NotFound(_))
    ));
}

#[test]
fn a_model_in_use_is_not_deleted_and_its_name_stays_its_text() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let text = "name = \"m1\"\n";
    store.save_model("m1", text).unwrap();
    let user = run_of(&store, RunKind::Diagnosis, json!({ "model": "m1" }), None);
    assert!(matches!(
        store.delete_model("m1"),
        Err(StoreError::InUse(_))
    ));
    ended(&store, &user);
    store.delete_model("m1").unwrap();
    assert!(store.list_models().unwrap().is_empty());
    assert!(matches!(
        store.read_model("m1"),
        Err(StoreError::NotFound(_))
    ));
    assert!(matches!(
        store.delete_model("m1"),
        Err(StoreError::NotFound(_))
    ));
    // Another text under the name is refused; the same text comes back.
    assert!(matches!(
        store.save_model("m1", "name = \"m1\"\n# other\n"),
        Err(StoreError::Conflict(_))
    ));
    store.save_model("m1", text).unwrap();
    assert_eq!(store.list_models().unwrap(), vec!["m1".to_string()]);
}

#[test]
fn no_write_passes_the_run_folders_quota() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = run_of(&store, RunKind::Experiment, json!({}), None);
    store.set_runs_quota(store.runs_bytes() + 100_000);
    store
        .write_file(&r.id, "frames/a.tif", &[0u8; 60_000])
        .unwrap();
    let before = store.runs_bytes();
    match store.write_file(&r.id, "frames/b.tif", &[0u8; 60_000]) {
        Err(StoreError::QuotaFull {
            needed_bytes,
            used_bytes,
            ..
        }) => assert_eq!((needed_bytes, used_bytes), (60_000, before)),
        other => panic!("{other:?}"),
    }
    assert!(!store.run_dir(&r.id).join("frames/b.tif").exists());
    assert_eq!(store.runs_bytes(), before);
    assert!(store.check_runs_room(60_000).is_err());
    assert!(store.check_runs_room(30_000).is_ok());
    // The count survives a restart: measured from the folders.
    store
        .set_status(&r.id, RunStatus::Cancelled, "stop")
        .unwrap();
    let counted = store.runs_bytes();
    drop(store);
    let store = open(dir.path());
    assert_eq!(store.runs_bytes(), counted);
    assert_eq!(counted, folder_bytes(&dir.path().join("runs")).unwrap());
}

#[test]
fn retention_deletes_ended_runs_by_count_and_by_age_and_keeps_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let mut runs = Vec::new();
    for _ in 0..5 {
        let r = run_of(&store, RunKind::Analysis, json!({}), None);
        ended(&store, &r);
        runs.push(r);
        std::thread::sleep(Duration::from_millis(5));
    }
    let queued = run_of(&store, RunKind::Analysis, json!({}), None);
    // Keep everything: nothing goes.
    assert!(store
        .prune(&Retention::default(), SystemTime::now())
        .unwrap()
        .runs
        .is_empty());
    // The newest three ended runs stay; the queued one is no ended run.
    let by_count = Retention {
        max_age_days: 0,
        max_ended_runs: 3,
    };
    let pruned = store.prune(&by_count, SystemTime::now()).unwrap();
    assert_eq!(pruned.runs, vec![runs[1].id.clone(), runs[0].id.clone()]);
    assert!(pruned.bytes > 0);
    let left = listed(&store);
    assert_eq!(
        left,
        vec![
            queued.id.clone(),
            runs[4].id.clone(),
            runs[3].id.clone(),
            runs[2].id.clone()
        ]
    );
    // By age: ten days from now every ended run is older than a week; the queued one stays.
    let by_age = Retention {
        max_age_days: 7,
        max_ended_runs: 0,
    };
    assert!(store
        .prune(&by_age, SystemTime::now())
        .unwrap()
        .runs
        .is_empty());
    let later = SystemTime::now() + Duration::from_secs(10 * 86_400);
    assert_eq!(store.prune(&by_age, later).unwrap().runs.len(), 3);
    let left = listed(&store);
    assert_eq!(left, vec![queued.id]);
}

#[test]
fn a_deletion_a_crash_interrupted_is_finished_at_the_next_open() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(dir.path());
    let r = run_of(&store, RunKind::Analysis, json!({}), None);
    ended(&store, &r);
    drop(store);
    // What a crash between the rename and the removal leaves.
    let runs = dir.path().join("runs");
    std::fs::rename(
        runs.join(r.id.as_str()),
        runs.join(format!(".deleting-{}", r.id)),
    )
    .unwrap();
    let store = open(dir.path());
    assert!(std::fs::read_dir(&runs).unwrap().next().is_none());
    assert!(store.list(None, None, 10).unwrap().is_empty());
    assert_eq!(store.runs_bytes(), 0);
}
