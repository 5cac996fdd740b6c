//! A sweep's folder: `plan.json`, `results/{task id}.json` (one per task, written atomically so
//! workers on a shared folder never see half a file), and what merging writes (see
//! [`super::views`]): `map.csv`, `map.json`, `recommendations.txt` and the figures.

use super::merge::{merge, Merged};
use super::plan::{Plan, Shard};
use super::spec::SweepError;
use super::task::{run_shard, TaskResult};
use super::views::map_files;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

fn write(path: &Path, bytes: &[u8]) -> Result<(), SweepError> {
    crate::atomic_write::write_atomically(path, bytes).map_err(|source| SweepError::Write {
        path: path.to_owned(),
        source,
    })
}

fn result_path(dir: &Path, id: &str) -> PathBuf {
    dir.join("results").join(format!("{id}.json"))
}

/// Writes `DIR/plan.json` (and creates `DIR/results/`).
pub fn write_plan(dir: &Path, plan: &Plan) -> Result<(), SweepError> {
    let results = dir.join("results");
    std::fs::create_dir_all(&results).map_err(|source| SweepError::Write {
        path: results,
        source,
    })?;
    write(
        &dir.join("plan.json"),
        &serde_json::to_vec_pretty(plan).expect("plans serialise"),
    )
}

/// Whether every task of `shard` has its result.
pub fn shard_done(dir: &Path, shard: &Shard) -> bool {
    shard
        .tasks
        .iter()
        .all(|t| result_path(dir, &t.id).is_file())
}

/// What one call of [`run_shards`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RunCounts {
    pub shards_run: usize,
    pub shards_skipped: usize,
    pub tasks_run: usize,
}

/// Runs the shards of `plan` whose index `select` accepts, in parallel (rayon), skipping those
/// already done; each task's result is written as soon as its shard finishes.
/// `progress(done, total)` counts shards and answers whether to go on: once it says no, no
/// further shard starts (those running finish and keep their results) and the call ends with
/// [`SweepError::Cancelled`].
pub fn run_shards(
    dir: &Path,
    plan: &Plan,
    select: &(dyn Fn(usize) -> bool + Sync),
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
) -> Result<RunCounts, SweepError> {
    let chosen: Vec<&Shard> = plan.shards.iter().filter(|s| select(s.index)).collect();
    let (done, todo): (Vec<&Shard>, Vec<&Shard>) =
        chosen.into_iter().partition(|s| shard_done(dir, s));
    let finished = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let total = todo.len();
    if !progress(0, total) {
        return Err(SweepError::Cancelled);
    }
    let tasks: Vec<usize> = todo
        .par_iter()
        .map(|shard| -> Result<usize, SweepError> {
            if stop.load(Ordering::Relaxed) {
                return Err(SweepError::Cancelled);
            }
            // Asked again with the count reported last: a shard stops within a point.
            let cancelled = || {
                stop.load(Ordering::Relaxed) || !progress(finished.load(Ordering::Relaxed), total)
            };
            let results = run_shard(plan, shard, &cancelled)?;
            for r in &results {
                write(
                    &result_path(dir, &r.id),
                    &serde_json::to_vec_pretty(r).expect("results serialise"),
                )?;
            }
            if !progress(finished.fetch_add(1, Ordering::Relaxed) + 1, total) {
                stop.store(true, Ordering::Relaxed);
            }
            Ok(results.len())
        })
        .collect::<Result<_, _>>()?;
    if stop.load(Ordering::Relaxed) {
        return Err(SweepError::Cancelled);
    }
    Ok(RunCounts {
        shards_run: total,
        shards_skipped: done.len(),
        tasks_run: tasks.iter().sum(),
    })
}

/// Every result of the plan's tasks found in `DIR/results` (unreadable files count as missing).
pub fn read_results(dir: &Path, plan: &Plan) -> HashMap<String, TaskResult> {
    plan.shards
        .iter()
        .flat_map(|s| &s.tasks)
        .filter_map(|t| {
            let text = std::fs::read(result_path(dir, &t.id)).ok()?;
            let r: TaskResult = serde_json::from_slice(&text).ok()?;
            (r.id == t.id).then(|| (t.id.clone(), r))
        })
        .collect()
}

/// Merges the folder's results and writes every file of [`map_files`] into it.
pub fn merge_folder(dir: &Path) -> Result<Merged, SweepError> {
    let plan = Plan::read(dir)?;
    let merged = merge(&plan, &read_results(dir, &plan));
    for file in map_files(&plan, &merged) {
        write(&dir.join(&file.name), &file.bytes)?;
    }
    Ok(merged)
}
