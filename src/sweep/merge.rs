//! Results gathered into cells (every axis but the seed): the mean of each statistic over the
//! cell's realisations with its 95 % Student-t interval, and what the map recommends.

use super::plan::{Plan, TaskInput};
use super::task::TaskResult;
use crate::stats::mean_interval;
use std::collections::HashMap;

/// The statistics of a cell, in the order of [`CellStats::values`].
pub const STAT_NAMES: [&str; 8] = [
    "u_std_px",
    "v_std_px",
    "u_bias_px",
    "v_bias_px",
    "exx_std",
    "eyy_std",
    "exy_std",
    "valid_fraction",
];

/// One cell of the map.
#[derive(Clone, Debug, PartialEq)]
pub struct CellStats {
    /// The cell's first task (its axes; the seed is that task's).
    pub task: TaskInput,
    /// Realisations with a result.
    pub n: usize,
    /// Per statistic of [`STAT_NAMES`]: mean and 95 % interval over realisations.
    pub values: Vec<(f64, [f64; 2])>,
}

impl CellStats {
    pub fn stat(&self, name: &str) -> (f64, [f64; 2]) {
        let i = STAT_NAMES
            .iter()
            .position(|n| *n == name)
            .expect("a known statistic");
        self.values[i]
    }
}

/// The merged sweep: cells in plan order, and the tasks without a result.
#[derive(Clone, Debug, PartialEq)]
pub struct Merged {
    pub cells: Vec<CellStats>,
    pub missing: Vec<String>,
}

fn stats_of(r: &TaskResult) -> [f64; 8] {
    [
        r.u_std_px,
        r.v_std_px,
        r.u_bias_px,
        r.v_bias_px,
        r.exx_std,
        r.eyy_std,
        r.exy_std,
        if r.points > 0 {
            r.valid as f64 / r.points as f64
        } else {
            f64::NAN
        },
    ]
}

/// Groups `results` (by task id) into the plan's cells.
pub fn merge(plan: &Plan, results: &HashMap<String, TaskResult>) -> Merged {
    let mut order: Vec<String> = Vec::new();
    let mut cells: HashMap<String, (TaskInput, Vec<[f64; 8]>)> = HashMap::new();
    let mut missing = Vec::new();
    for task in plan.shards.iter().flat_map(|s| &s.tasks) {
        let key = task.cell_key();
        let entry = cells.entry(key.clone()).or_insert_with(|| {
            order.push(key);
            (task.clone(), Vec::new())
        });
        match results.get(&task.id) {
            Some(r) => entry.1.push(stats_of(r)),
            None => missing.push(task.id.clone()),
        }
    }
    let cells = order
        .iter()
        .map(|key| {
            let (task, rows) = &cells[key];
            let values = (0..STAT_NAMES.len())
                .map(|i| {
                    let xs: Vec<f64> = rows.iter().map(|r| r[i]).collect();
                    mean_interval(&xs)
                })
                .collect();
            CellStats {
                task: task.clone(),
                n: rows.len(),
                values,
            }
        })
        .collect();
    Merged { cells, missing }
}

/// "For this scheme, noise, blur and move, prints of N–M keep std u within 10 % of the best."
#[derive(Clone, Debug, PartialEq)]
pub struct Recommendation {
    pub scheme: String,
    pub fill_factor: (f64, f64),
    /// The cell's other axes, as text.
    pub conditions: String,
    pub best_print: String,
    pub best_u_std_px: (f64, [f64; 2]),
    /// Prints whose mean std u is within `tolerance` of the best, in plan order.
    pub within: Vec<String>,
}

/// For every combination of the axes but the print, the prints within `tolerance` (0.1 = 10 %)
/// of the smallest mean std u.
pub fn recommendations(merged: &Merged, tolerance: f64) -> Vec<Recommendation> {
    let mut groups: Vec<(String, Vec<&CellStats>)> = Vec::new();
    for cell in &merged.cells {
        let conditions = conditions(&cell.task);
        let key = format!("{}|{conditions}", cell.task.scheme.name);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, cells)) => cells.push(cell),
            None => groups.push((key, vec![cell])),
        }
    }
    groups
        .into_iter()
        .filter_map(|(_, cells)| {
            let best = cells
                .iter()
                .filter(|c| c.stat("u_std_px").0.is_finite())
                .min_by(|a, b| a.stat("u_std_px").0.total_cmp(&b.stat("u_std_px").0))?;
            let best_u = best.stat("u_std_px");
            let t = &best.task;
            Some(Recommendation {
                scheme: t.scheme.name.clone(),
                fill_factor: t.scheme.linear_fill_factor(),
                conditions: conditions(t),
                best_print: t.print.label(),
                best_u_std_px: best_u,
                within: cells
                    .iter()
                    .filter(|c| c.stat("u_std_px").0 <= best_u.0 * (1.0 + tolerance))
                    .map(|c| c.task.print.label())
                    .collect(),
            })
        })
        .collect()
}

/// A cell's axes other than the print and the scheme, for people.
pub fn conditions(t: &TaskInput) -> String {
    conditions_but(t, None)
}

/// The conditions of a task in words, leaving out the sub-pixel position along `free_axis`
/// (0 = x, 1 = y) when a figure has it on its abscissa.
pub fn conditions_but(t: &TaskInput, free_axis: Option<usize>) -> String {
    let noise = t.noise.map_or("of the model".to_string(), |n| {
        format!(
            "{} e⁻ full well / {} e⁻ read",
            n.full_well_e, n.read_noise_e
        )
    });
    let subpixel = match free_axis {
        None => format!("({}, {})", t.subpixel_px[0], t.subpixel_px[1]),
        Some(axis) => format!("{} {}", ["x", "y"][1 - axis], t.subpixel_px[1 - axis]),
    };
    format!(
        "noise {noise}, PSF σ {} px{}, sub-pixel {subpixel} px",
        t.psf_sigma_px,
        aperture_text(t),
    )
}

/// ", pixel aperture fx x fy" when the task sets one.
pub fn aperture_text(t: &TaskInput) -> String {
    t.aperture.map_or(String::new(), |[fx, fy]| {
        format!(", pixel aperture {fx} x {fy}")
    })
}
