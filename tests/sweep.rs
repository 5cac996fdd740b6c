//! `ffdic sweep` (issue 15): plans are deterministic and content-addressed, a killed run
//! resumes, and a sweep split into shards (as Slurm array tasks run it) merges to the same map as
//! one uninterrupted local run.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn ffdic() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ffdic"));
    c.env("RUST_LOG", "warn");
    c
}

fn smoke_spec() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sweeps/smoke.toml")
}

fn ok(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "{:?}: {}",
        c,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn plan(spec: &Path, dir: &Path) -> serde_json::Value {
    ok(ffdic()
        .args(["sweep", "plan"])
        .arg(spec)
        .arg("--out")
        .arg(dir));
    serde_json::from_slice(&std::fs::read(dir.join("plan.json")).unwrap()).unwrap()
}

fn task_ids(plan: &serde_json::Value) -> Vec<String> {
    plan["shards"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| s["tasks"].as_array().unwrap().iter())
        .map(|t| t["id"].as_str().unwrap().to_string())
        .collect()
}

/// The results written whole, not counting a result's hidden temporary file
/// (`atomic_write::write_atomically`'s `.NAME.tmp`, which a kill mid-write leaves behind).
fn results(dir: &Path) -> usize {
    result_files(dir).len()
}

fn result_files(dir: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir.join("results"))
        .map(|d| {
            d.map(|e| e.unwrap().path())
                .filter(|p| !p.file_name().unwrap().to_string_lossy().starts_with('.'))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn plans_are_deterministic_and_a_changed_axis_keeps_the_other_tasks() {
    let tmp = tempfile::tempdir().unwrap();
    let a = plan(&smoke_spec(), &tmp.path().join("a"));
    let b = plan(&smoke_spec(), &tmp.path().join("b"));
    assert_eq!(a, b, "the same spec plans the same tasks");
    let ids = task_ids(&a);
    assert!(
        ids.len() <= 60,
        "the smoke sweep has at most 60 tasks: {}",
        ids.len()
    );
    let unique: std::collections::HashSet<_> = ids.iter().collect();
    assert_eq!(unique.len(), ids.len(), "task ids are unique");

    // One more dot size and one more scheme: every earlier task keeps its id.
    let text = std::fs::read_to_string(smoke_spec())
        .unwrap()
        .replace("[2.0, 4.0, 7.0]", "[2.0, 4.0, 5.5, 7.0]")
        .replace(
            r#"schemes = ["ff100", "ff50", "ff25"]"#,
            r#"schemes = ["ff100", "ff50", "ff25", { name = "ff33", x = { block = 3, first = 1, active = 1 }, y = { block = 3, first = 0, active = 3 } }]"#,
        );
    let wider = tmp.path().join("wider.toml");
    std::fs::write(&wider, text).unwrap();
    let c = plan(&wider, &tmp.path().join("c"));
    let more = task_ids(&c);
    assert_eq!(more.len(), ids.len() / 3 * 4 / 3 * 4);
    for id in &ids {
        assert!(more.contains(id), "task {id} lost its id when an axis grew");
    }
    // A changed DIC setting changes every id (results made with other settings are not reused).
    let text = std::fs::read_to_string(smoke_spec())
        .unwrap()
        .replace("step_px = 16", "step_px = 12");
    let other = tmp.path().join("other.toml");
    std::fs::write(&other, text).unwrap();
    let d = plan(&other, &tmp.path().join("d"));
    assert!(task_ids(&d).iter().all(|id| !ids.contains(id)));
}

#[test]
fn a_killed_and_sharded_sweep_merges_to_the_map_of_one_local_run() {
    let tmp = tempfile::tempdir().unwrap();
    // One uninterrupted local run.
    let whole = tmp.path().join("whole");
    plan(&smoke_spec(), &whole);
    ok(ffdic().args(["sweep", "run"]).arg(&whole));
    let summary = ok(ffdic().args(["sweep", "merge"]).arg(&whole));
    let total = task_ids(&plan(&smoke_spec(), &whole)).len();
    assert_eq!(results(&whole), total);
    assert!(
        summary.contains("keep std u within 10 % of the best"),
        "{summary}"
    );

    // The same sweep killed (SIGKILL) part-way, resumed, then finished shard by shard as array
    // tasks would (`--shard I/N`, `--index I`).
    let split = tmp.path().join("split");
    let p = plan(&smoke_spec(), &split);
    let shards = p["shards"].as_array().unwrap().len();
    let mut child = ffdic()
        .args(["sweep", "run", "--threads", "1"])
        .arg(&split)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while results(&split) < 3 && started.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let after_kill = results(&split);
    assert!(
        after_kill >= 3,
        "the run wrote results before it was killed"
    );
    // No partial file under a result's name: every result present parses (written atomically;
    // the kill may leave a hidden temporary file, which is not a result).
    for path in result_files(&split) {
        let bytes = std::fs::read(&path).unwrap();
        serde_json::from_slice::<serde_json::Value>(&bytes).expect("a whole result");
    }
    if after_kill < total {
        let out = ok(ffdic().args(["sweep", "run", "--shard", "0/3"]).arg(&split));
        assert!(
            out.contains("already done") || out.contains("shards run"),
            "{out}"
        );
    }
    let out = ok(ffdic().args(["sweep", "run", "--index", "1"]).arg(&split));
    assert!(out.contains("shards run"), "{out}");
    ok(ffdic().args(["sweep", "run", "--shard", "1/3"]).arg(&split));
    ok(ffdic().args(["sweep", "run", "--shard", "2/3"]).arg(&split));
    let again = ok(ffdic().args(["sweep", "run"]).arg(&split));
    assert!(
        again.starts_with("0 shards run") && again.contains(&format!("{shards} already done")),
        "{again}"
    );
    ok(ffdic().args(["sweep", "merge"]).arg(&split));
    assert_eq!(
        std::fs::read_to_string(split.join("map.csv")).unwrap(),
        std::fs::read_to_string(whole.join("map.csv")).unwrap(),
        "the resumed, sharded sweep's map equals the single run's"
    );
    for name in [
        "recommendations.txt",
        "map_u_std_px_0.svg",
        "map_v_std_px_1.svg",
    ] {
        assert!(split.join(name).is_file(), "{name}");
    }
}

/// The smoke spec with an axis added under `[axes]`.
fn smoke_with(dir: &Path, name: &str, axis_line: &str) -> PathBuf {
    let text = std::fs::read_to_string(smoke_spec())
        .unwrap()
        .replace("[axes]\n", &format!("[axes]\n{axis_line}\n"));
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn the_pixel_aperture_is_an_axis_of_its_own() {
    let tmp = tempfile::tempdir().unwrap();
    let one = plan(
        &smoke_with(tmp.path(), "one", "pixel_aperture = [[1.0, 1.0]]"),
        &tmp.path().join("one"),
    );
    let two = plan(
        &smoke_with(
            tmp.path(),
            "two",
            "pixel_aperture = [[1.0, 1.0], [0.25, 1.0]]",
        ),
        &tmp.path().join("two"),
    );
    let (ids_one, ids_two) = (task_ids(&one), task_ids(&two));
    assert_eq!(ids_two.len(), 2 * ids_one.len());
    for id in &ids_one {
        assert!(
            ids_two.contains(id),
            "task {id} lost its id when the aperture axis grew"
        );
    }
    // Without the axis, the tasks are the model's own aperture: other renderings, other ids.
    let none = task_ids(&plan(&smoke_spec(), &tmp.path().join("none")));
    assert!(none.iter().all(|id| !ids_one.contains(id)));

    // Run the 2-px prints only: each aperture is a cell of its own and reaches the renderer
    // (a quarter-width aperture changes what the pixels see, so the errors differ).
    let small = smoke_with(
        tmp.path(),
        "small",
        "pixel_aperture = [[1.0, 1.0], [0.25, 1.0]]",
    );
    let text = std::fs::read_to_string(&small)
        .unwrap()
        .replace("[2.0, 4.0, 7.0]", "[2.0]");
    std::fs::write(&small, text).unwrap();
    let dir = tmp.path().join("small-run");
    plan(&small, &dir);
    ok(ffdic().args(["sweep", "run"]).arg(&dir));
    ok(ffdic().args(["sweep", "merge"]).arg(&dir));
    let csv = std::fs::read_to_string(dir.join("map.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert_eq!(
        rows.len(),
        2 * 3 * 2,
        "2 apertures x 3 schemes x 2 positions"
    );
    let u_std = |aperture_x: &str, scheme: &str, subpixel: &str| -> f64 {
        rows.iter()
            .find(|r| {
                r[col("aperture_x")] == aperture_x
                    && r[col("scheme")] == scheme
                    && r[col("subpixel_x_px")] == subpixel
            })
            .unwrap()[col("u_std_px")]
        .parse()
        .unwrap()
    };
    for scheme in ["ff100", "ff50", "ff25"] {
        for subpixel in ["0", "0.5"] {
            assert_ne!(
                u_std("1", scheme, subpixel),
                u_std("0.25", scheme, subpixel),
                "{scheme} at {subpixel}: the aperture changed nothing"
            );
        }
    }
}

#[test]
fn bad_specs_and_selections_are_refused_with_the_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = tmp.path().join("bad.toml");
    for (edit, reason) in [
        (("seeds = 3", "seeds = 0"), "seeds"),
        (("[2.0, 4.0, 7.0]", "[2.0, -1.0]"), "dot_diameter_px"),
        (("\"ff25\"]", "\"ff7\"]"), "schemes"),
        (("subset_px = 31", "subset_px = 30"), "dic"),
    ] {
        let text = std::fs::read_to_string(smoke_spec())
            .unwrap()
            .replace(edit.0, edit.1);
        std::fs::write(&bad, text).unwrap();
        let out = ffdic()
            .args(["sweep", "plan"])
            .arg(&bad)
            .arg("--out")
            .arg(tmp.path().join("x"))
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(reason), "{reason}: {err}");
    }
    let dir = tmp.path().join("ok");
    plan(&smoke_spec(), &dir);
    for args in [["--index", "999"], ["--shard", "3/3"]] {
        let out = ffdic()
            .args(["sweep", "run"])
            .args(args)
            .arg(&dir)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        assert_eq!(results(&dir), 0);
    }
}

#[test]
fn the_cluster_files_have_what_slurm_and_kubernetes_need() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("s");
    let p = plan(&smoke_spec(), &dir);
    let shards = p["shards"].as_array().unwrap().len();
    ok(ffdic()
        .args([
            "sweep",
            "slurm",
            "--no-submit",
            "--partition",
            "short",
            "--array-max",
            "4",
        ])
        .arg(&dir));
    let run = std::fs::read_to_string(dir.join("slurm/run.sbatch")).unwrap();
    assert!(run.starts_with("#!/bin/bash\n"));
    assert!(
        run.contains(&format!("#SBATCH --array=0-{}%4\n", shards - 1)),
        "{run}"
    );
    assert!(run.contains("#SBATCH --partition=short\n"));
    assert!(run.contains("sweep run") && run.contains("--index \"$SLURM_ARRAY_TASK_ID\""));
    let merge = std::fs::read_to_string(dir.join("slurm/merge.sbatch")).unwrap();
    assert!(merge.contains("sweep merge"));

    ok(ffdic()
        .args([
            "sweep",
            "k8s",
            "--image",
            "registry.example/ffdic:0.1",
            "--claim",
            "sweeps",
        ])
        .args(["--sub-path", "smoke", "--parallelism", "4"])
        .arg(&dir));
    let job: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("k8s/job.json")).unwrap()).unwrap();
    // The fields a batch/v1 Indexed Job must have (Kubernetes API reference, Job v1).
    assert_eq!(job["apiVersion"], "batch/v1");
    assert_eq!(job["kind"], "Job");
    let name = job["metadata"]["name"].as_str().unwrap();
    assert!(
        name.len() <= 63
            && name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
            && !name.starts_with('-')
            && !name.ends_with('-'),
        "a DNS-1123 label: {name}"
    );
    let spec = &job["spec"];
    assert_eq!(spec["completionMode"], "Indexed");
    assert_eq!(spec["completions"], shards);
    assert_eq!(spec["parallelism"], 4);
    let pod = &spec["template"]["spec"];
    assert!(["Never", "OnFailure"].contains(&pod["restartPolicy"].as_str().unwrap()));
    let container = &pod["containers"][0];
    assert_eq!(container["image"], "registry.example/ffdic:0.1");
    let args: Vec<&str> = container["args"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    assert_eq!(
        &args[..5],
        [
            "sweep",
            "run",
            "/sweep/smoke",
            "--index",
            "$(JOB_COMPLETION_INDEX)"
        ]
    );
    let mount = &container["volumeMounts"][0];
    let volume = &pod["volumes"][0];
    assert_eq!(
        mount["name"], volume["name"],
        "the mount names a volume of the pod"
    );
    assert_eq!(volume["persistentVolumeClaim"]["claimName"], "sweeps");
}
