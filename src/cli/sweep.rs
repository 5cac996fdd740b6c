//! `ffdic sweep plan|run|merge`: a design map over dot size, fill factor, noise, blur and the
//! sub-pixel part of the move (see `ffdic::sweep`).

use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use ffdic::sweep::{
    merge_folder, plan, recommendations_text, run_shards, shard_done, write_plan, Plan, SweepSpec,
};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, Args)]
pub struct SweepArgs {
    #[command(subcommand)]
    pub command: SweepCommand,
}

#[derive(Debug, Subcommand)]
pub enum SweepCommand {
    /// Expand a sweep spec into tasks named by content hash (DIR/plan.json).
    Plan {
        /// The sweep spec (see config/sweeps/).
        spec: PathBuf,
        /// The sweep's folder (shared by every worker).
        #[arg(long)]
        out: PathBuf,
        /// Data folder whose models/ holds a model the spec names (besides the embedded ones).
        #[arg(long, default_value = "data")]
        data: PathBuf,
    },
    /// Run the planned shards not done yet (all by default, in parallel).
    Run {
        dir: PathBuf,
        /// Only the shards whose index is I modulo N (`--shard 0/4`).
        #[arg(long, value_name = "I/N", conflicts_with = "index")]
        shard: Option<String>,
        /// Only shard I (a Slurm array task's $SLURM_ARRAY_TASK_ID).
        #[arg(long)]
        index: Option<usize>,
        /// Worker threads (default: every core).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Gather the results into DIR/map.csv, the heat maps and DIR/recommendations.txt.
    Merge { dir: PathBuf },
}

pub fn run(args: &SweepArgs) -> Result<()> {
    match &args.command {
        SweepCommand::Plan { spec, out, data } => plan_command(spec, out, data),
        SweepCommand::Run {
            dir,
            shard,
            index,
            threads,
        } => run_command(dir, shard.as_deref(), *index, *threads),
        SweepCommand::Merge { dir } => merge_command(dir),
    }
}

fn plan_command(spec_path: &Path, out: &Path, data: &Path) -> Result<()> {
    let spec = SweepSpec::load(spec_path)?;
    let model = match &spec.model {
        Some(name) => Some(ffdic::service::find_analysis_model(Some(name), data)?),
        None => None,
    };
    let plan = plan(&spec, model.as_ref())?;
    write_plan(out, &plan)?;
    let done = plan.shards.iter().filter(|s| shard_done(out, s)).count();
    println!(
        "{}: {} tasks in {} shards written to {} ({done} shards already have their results)",
        spec.name,
        plan.task_count(),
        plan.shards.len(),
        out.join("plan.json").display()
    );
    Ok(())
}

/// `I/N` → (I, N).
fn parse_shard(text: &str) -> Result<(usize, usize)> {
    let (i, n) = text
        .split_once('/')
        .with_context(|| format!("--shard {text}: expected I/N, e.g. 0/4"))?;
    let (i, n): (usize, usize) = (
        i.trim().parse().context("--shard: I is not a number")?,
        n.trim().parse().context("--shard: N is not a number")?,
    );
    if n == 0 || i >= n {
        bail!("--shard {text}: need 0 <= I < N");
    }
    Ok((i, n))
}

fn run_command(
    dir: &Path,
    shard: Option<&str>,
    index: Option<usize>,
    threads: Option<usize>,
) -> Result<()> {
    let plan = Plan::read(dir)?;
    if let Some(i) = index {
        if i >= plan.shards.len() {
            bail!(
                "--index {i}: the plan has {} shards (0 to {})",
                plan.shards.len(),
                plan.shards.len().saturating_sub(1)
            );
        }
    }
    let modulo = shard.map(parse_shard).transpose()?;
    let select = move |k: usize| match (index, modulo) {
        (Some(i), _) => k == i,
        (None, Some((i, n))) => k % n == i,
        (None, None) => true,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    let bar = ProgressBar::new(true, "shards");
    let started = Instant::now();
    let counts = pool.install(|| run_shards(dir, &plan, &select, &|d, t| bar.update(d, t)))?;
    bar.finish();
    let elapsed_s = started.elapsed().as_secs_f64();
    println!(
        "{} shards run ({} tasks) in {elapsed_s:.1} s ({:.2} tasks/s), {} already done",
        counts.shards_run,
        counts.tasks_run,
        counts.tasks_run as f64 / elapsed_s.max(1e-9),
        counts.shards_skipped
    );
    Ok(())
}

fn merge_command(dir: &Path) -> Result<()> {
    let merged = merge_folder(dir)?;
    print!("{}", recommendations_text(&merged));
    println!(
        "{} cells in {}; heat maps map_*.svg, recommendations.txt",
        merged.cells.len(),
        dir.join("map.csv").display()
    );
    if !merged.missing.is_empty() {
        eprintln!(
            "warning: {} tasks have no result yet (`ffdic sweep run {}`); their cells merge fewer realisations",
            merged.missing.len(),
            dir.display()
        );
    }
    Ok(())
}
