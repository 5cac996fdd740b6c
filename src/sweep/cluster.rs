//! A sweep on a cluster, through the cluster's own scheduler (no home-made one): a Slurm array
//! job whose tasks run shards (`ffdic sweep run DIR --index $SLURM_ARRAY_TASK_ID`) with a merge
//! job that depends on it, or a Kubernetes Indexed Job (`$(JOB_COMPLETION_INDEX)`). Both need
//! the sweep folder on storage every worker shares; results are one atomic file per task, so
//! workers never contend.

use serde_json::json;
use std::path::Path;

/// Slurm's default `MaxArraySize` is 1001 (indices 0 to 1000): above it, each array task runs
/// every shard whose index is its own modulo the array size.
pub const SLURM_MAX_ARRAY_TASKS: usize = 1000;

/// How the array job asks for its resources.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    /// Wall-time limit per array task, in Slurm's format (`30:00`, `1-00:00:00`).
    pub time: Option<String>,
    /// At most this many array tasks at once (`--array=0-N%K`).
    pub array_max: Option<usize>,
    pub cpus_per_task: usize,
}

/// The two batch scripts: the array job over the shards, and the merge.
#[derive(Clone, Debug, PartialEq)]
pub struct SlurmScripts {
    pub run: String,
    pub merge: String,
    /// Array tasks the run script asks for.
    pub array_tasks: usize,
}

fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// Scripts for `shards` shards of the sweep in `dir` (absolute, on shared storage), run by the
/// `ffdic` at `exe` (absolute, the same path on every node).
pub fn slurm_scripts(
    name: &str,
    dir: &Path,
    exe: &Path,
    shards: usize,
    options: &SlurmOptions,
) -> SlurmScripts {
    let array_tasks = shards.clamp(1, SLURM_MAX_ARRAY_TASKS);
    let (dir_q, exe_q) = (
        quote(&dir.display().to_string()),
        quote(&exe.display().to_string()),
    );
    let logs = dir.join("slurm");
    let header = |job: &str, log: &str| {
        let mut h = format!(
            "#!/bin/bash\n#SBATCH --job-name=ffdic-{job}-{name}\n#SBATCH --output={}\n",
            logs.join(log).display()
        );
        if let Some(p) = &options.partition {
            h += &format!("#SBATCH --partition={p}\n");
        }
        if let Some(t) = &options.time {
            h += &format!("#SBATCH --time={t}\n");
        }
        h
    };
    let throttle = options.array_max.map_or(String::new(), |k| format!("%{k}"));
    let selection = if array_tasks == shards {
        "--index \"$SLURM_ARRAY_TASK_ID\"".to_string()
    } else {
        format!("--shard \"$SLURM_ARRAY_TASK_ID/{array_tasks}\"")
    };
    let run = format!(
        "{}#SBATCH --array=0-{}{throttle}\n#SBATCH --cpus-per-task={}\n\
         # One shard per array task: render once, reduce and correlate per scheme, one result\n\
         # file per task (a shard already done is skipped, so a requeued task resumes).\n\
         exec {exe_q} sweep run {dir_q} {selection} --threads \"${{SLURM_CPUS_PER_TASK:-1}}\"\n",
        header("sweep", "run_%A_%a.out"),
        array_tasks - 1,
        options.cpus_per_task.max(1),
    );
    let merge = format!(
        "{}#SBATCH --cpus-per-task=1\nexec {exe_q} sweep merge {dir_q}\n",
        header("merge", "merge_%j.out")
    );
    SlurmScripts {
        run,
        merge,
        array_tasks,
    }
}

/// Where the sweep folder is inside the Kubernetes pods, and what runs them.
#[derive(Clone, Debug, PartialEq)]
pub struct K8sOptions {
    pub image: String,
    /// A PersistentVolumeClaim holding the sweep folder (ReadWriteMany for parallel pods).
    pub claim: String,
    /// Where the claim is mounted; the sweep folder is `mount_path/sub_path`.
    pub mount_path: String,
    pub sub_path: String,
    pub parallelism: usize,
    pub cpus_per_pod: usize,
}

/// A `batch/v1` Job in Indexed completion mode: one completion per shard, each pod running
/// `ffdic sweep run DIR --index $(JOB_COMPLETION_INDEX)` (the index Kubernetes sets).
pub fn k8s_job(name: &str, shards: usize, options: &K8sOptions) -> serde_json::Value {
    let dir = if options.sub_path.is_empty() || options.sub_path == "." {
        options.mount_path.clone()
    } else {
        format!(
            "{}/{}",
            options.mount_path.trim_end_matches('/'),
            options.sub_path
        )
    };
    let job_name: String = format!("ffdic-sweep-{name}")
        .to_ascii_lowercase()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .take(63)
        .collect();
    json!({
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": { "name": job_name.trim_end_matches('-'), "labels": { "app": "ffdic-sweep" } },
        "spec": {
            "completionMode": "Indexed",
            "completions": shards,
            "parallelism": options.parallelism.clamp(1, shards.max(1)),
            "backoffLimit": 3 * shards.max(1),
            "template": {
                "metadata": { "labels": { "app": "ffdic-sweep" } },
                "spec": {
                    "restartPolicy": "Never",
                    "containers": [{
                        "name": "sweep",
                        "image": options.image,
                        "command": ["ffdic"],
                        "args": ["sweep", "run", dir, "--index", "$(JOB_COMPLETION_INDEX)",
                                 "--threads", options.cpus_per_pod.max(1).to_string()],
                        "resources": { "requests": { "cpu": options.cpus_per_pod.max(1).to_string() } },
                        "volumeMounts": [{ "name": "sweep", "mountPath": options.mount_path }]
                    }],
                    "volumes": [{
                        "name": "sweep",
                        "persistentVolumeClaim": { "claimName": options.claim }
                    }]
                }
            }
        }
    })
}
