//! Design maps: the paper's question — how much does a lower fill factor cost, and which dot size
//! keeps the cost small — swept over dot size, fill-factor scheme, sensor noise, PSF blur and
//! the sub-pixel part of the move, with an interval over speckle realisations (seeds).
//!
//! A sweep spec (`config/sweeps/*.toml`) is planned into tasks, each named by the content hash
//! of everything that makes its result (camera, print, model, move, seed, scheme, DIC settings,
//! ffdic version): re-planning gives the same names, and a changed axis leaves the results of
//! unchanged tasks valid. Tasks that share a rendering (all schemes of one print, noise, blur,
//! move and seed) form a shard, the unit a worker runs: the pair is rendered once and reduced
//! once per scheme. Results are one JSON file per task, written atomically, so a killed run
//! resumes where it stopped and any number of workers (local threads, Slurm array tasks) can
//! share a folder. Merging groups the tasks of a cell (everything but the seed) into means with
//! 95 % Student-t intervals, the map.

#[cfg(feature = "arrow")]
mod arrow;
mod cluster;
mod folder;
mod merge;
mod plan;
mod spec;
mod task;
mod views;

#[cfg(feature = "arrow")]
pub use arrow::map_arrow;
pub use cluster::{
    k8s_job, slurm_scripts, K8sOptions, SlurmOptions, SlurmScripts, SLURM_MAX_ARRAY_TASKS,
};
pub use folder::{merge_folder, read_results, run_shards, shard_done, write_plan, RunCounts};
pub use merge::{
    conditions, merge, recommendations, CellStats, Merged, Recommendation, STAT_NAMES,
};
pub use plan::{plan, Plan, Shard, TaskInput};
pub use spec::{
    NoiseLevel, PrintAxis, SweepError, SweepSpec, MAX_MOVE_MM, MAX_SEEDS, MAX_SENSOR_SIDE_PX,
    MAX_TASKS, MIN_SENSOR_SIDE_PX,
};
pub use task::{run_shard, TaskResult};
pub use views::{
    bias_svgs, map_csv, map_document, map_files, map_svgs, recommendations_text, CellJson,
    IntervalJson, MapDocument, MapFile, RecommendationJson,
};
