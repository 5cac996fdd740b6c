//! A sweep's folder: `plan.json`, `results/{task id}.json` (one per task, written atomically so
//! workers on a shared folder never see half a file), and what merging writes: `map.csv`,
//! `recommendations.txt` and the heat maps `map_{statistic}_{panel}.svg`.

use super::merge::{conditions, merge, recommendations, Merged, STAT_NAMES};
use super::plan::{Plan, Shard};
use super::spec::SweepError;
use super::task::{run_shard, TaskResult};
use crate::report::Heatmap;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

fn write(path: &Path, bytes: &[u8]) -> Result<(), SweepError> {
    crate::store::write_atomically(path, bytes).map_err(|source| SweepError::Write {
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
/// `progress(done, total)` counts shards.
pub fn run_shards(
    dir: &Path,
    plan: &Plan,
    select: &(dyn Fn(usize) -> bool + Sync),
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<RunCounts, SweepError> {
    let chosen: Vec<&Shard> = plan.shards.iter().filter(|s| select(s.index)).collect();
    let (done, todo): (Vec<&Shard>, Vec<&Shard>) =
        chosen.into_iter().partition(|s| shard_done(dir, s));
    let finished = AtomicUsize::new(0);
    let total = todo.len();
    progress(0, total);
    let tasks: Vec<usize> = todo
        .par_iter()
        .map(|shard| -> Result<usize, SweepError> {
            let results = run_shard(plan, shard)?;
            for r in &results {
                write(
                    &result_path(dir, &r.id),
                    &serde_json::to_vec_pretty(r).expect("results serialise"),
                )?;
            }
            progress(finished.fetch_add(1, Ordering::Relaxed) + 1, total);
            Ok(results.len())
        })
        .collect::<Result<_, _>>()?;
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

/// The map as CSV: one row per cell, its axes, the realisations merged and each statistic's
/// mean and 95 % interval bounds.
pub fn map_csv(merged: &Merged) -> String {
    let mut header = vec![
        "print",
        "scheme",
        "fill_x",
        "fill_y",
        "full_well_e",
        "read_noise_e",
        "psf_sigma_px",
        "subpixel_x_px",
        "subpixel_y_px",
        "n",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    for s in STAT_NAMES {
        header.extend([s.to_string(), format!("{s}_lo"), format!("{s}_hi")]);
    }
    let rows: Vec<Vec<String>> = merged
        .cells
        .iter()
        .map(|c| {
            let t = &c.task;
            let (fx, fy) = t.scheme.linear_fill_factor();
            let (well, read) = t.noise.map_or((String::new(), String::new()), |n| {
                (n.full_well_e.to_string(), n.read_noise_e.to_string())
            });
            let mut row = vec![
                t.print.label(),
                t.scheme.name.clone(),
                fx.to_string(),
                fy.to_string(),
                well,
                read,
                t.psf_sigma_px.to_string(),
                t.subpixel_px[0].to_string(),
                t.subpixel_px[1].to_string(),
                c.n.to_string(),
            ];
            for (mean, [lo, hi]) in &c.values {
                row.extend([mean.to_string(), lo.to_string(), hi.to_string()]);
            }
            row
        })
        .collect();
    let header_refs: Vec<&str> = header.iter().map(String::as_str).collect();
    crate::report::csv(&header_refs, &rows)
}

/// Heat maps of std u, std v and std εxx over print × scheme, one per combination of the other
/// axes (a panel): `(file name, svg)`.
pub fn map_svgs(merged: &Merged) -> Vec<(String, String)> {
    let mut panels: Vec<String> = Vec::new();
    for c in &merged.cells {
        let p = conditions(&c.task);
        if !panels.contains(&p) {
            panels.push(p);
        }
    }
    let mut out = Vec::new();
    for (k, panel) in panels.iter().enumerate() {
        let cells: Vec<_> = merged
            .cells
            .iter()
            .filter(|c| conditions(&c.task) == *panel)
            .collect();
        let mut prints: Vec<String> = Vec::new();
        let mut schemes: Vec<String> = Vec::new();
        for c in &cells {
            let (p, s) = (c.task.print.label(), c.task.scheme.name.clone());
            if !prints.contains(&p) {
                prints.push(p);
            }
            if !schemes.contains(&s) {
                schemes.push(s);
            }
        }
        let xs: Vec<f64> = prints
            .iter()
            .enumerate()
            .map(|(i, p)| p.parse().unwrap_or(i as f64))
            .collect();
        for (stat, label) in [
            ("u_std_px", "std u [px]"),
            ("v_std_px", "std v [px]"),
            ("exx_std", "std εxx"),
        ] {
            let cells = &cells;
            let prints = &prints;
            let values = schemes
                .iter()
                .flat_map(|s| {
                    prints.iter().map(move |p| {
                        cells
                            .iter()
                            .find(|c| c.task.scheme.name == *s && c.task.print.label() == *p)
                            .map_or(f64::NAN, |c| c.stat(stat).0)
                    })
                })
                .collect();
            let map = Heatmap {
                title: format!("{label}: {panel}"),
                x_label: "print (dot diameter, reduced px)".into(),
                y_label: format!("scheme ({})", schemes.join(", ")),
                value_label: label.into(),
                xs: xs.clone(),
                ys: (0..schemes.len()).map(|i| i as f64).collect(),
                values,
                diverging: false,
            };
            out.push((format!("map_{stat}_{k}.svg"), map.to_svg(640, 360)));
        }
    }
    out
}

/// Recommendations as lines for people (10 % of the best std u).
pub fn recommendations_text(merged: &Merged) -> String {
    let mut s = String::new();
    for r in recommendations(merged, 0.10) {
        let (best, [lo, hi]) = r.best_u_std_px;
        s += &format!(
            "{} (fill {:.2} x {:.2}), {}: prints {} keep std u within 10 % of the best ({best:.5} px, 95 % interval {lo:.5}–{hi:.5}, at {})\n",
            r.scheme,
            r.fill_factor.0,
            r.fill_factor.1,
            r.conditions,
            r.within.join(", "),
            r.best_print,
        );
    }
    s
}

/// Merges the folder's results and writes `map.csv`, `recommendations.txt` and the heat maps.
pub fn merge_folder(dir: &Path) -> Result<Merged, SweepError> {
    let plan = Plan::read(dir)?;
    let merged = merge(&plan, &read_results(dir, &plan));
    write(&dir.join("map.csv"), map_csv(&merged).as_bytes())?;
    write(
        &dir.join("recommendations.txt"),
        recommendations_text(&merged).as_bytes(),
    )?;
    for (name, svg) in map_svgs(&merged) {
        write(&dir.join(name), svg.as_bytes())?;
    }
    Ok(merged)
}
