//! `ffdic sweep plan|run|merge`: a design map over dot size, fill factor, noise, blur and the
//! sub-pixel part of the move (see `ffdic::sweep`).

use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use ffdic::sweep::{
    k8s_job, merge_folder, plan, recommendations_text, run_shards, shard_done, slurm_scripts,
    write_plan, K8sOptions, Plan, SlurmOptions, SweepSpec,
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
        /// The sweep's folder, as `sweep plan --out` made it.
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
    /// Gather the results into DIR/map.csv (and map.arrow, map.json), the heat maps, the bias
    /// plots and DIR/recommendations.txt.
    Merge {
        /// The sweep's folder, its shards run.
        dir: PathBuf,
    },
    /// Submit the shards as a Slurm array job (`sbatch`) and a merge job that depends on it.
    /// DIR and this ffdic must be at the same path on every node (shared storage).
    Slurm {
        /// The sweep's folder, as `sweep plan --out` made it.
        dir: PathBuf,
        /// The Slurm partition (sbatch --partition; default: the cluster's default partition).
        #[arg(long)]
        partition: Option<String>,
        /// Wall-time limit per array task (`30:00`, `1-00:00:00`).
        #[arg(long)]
        time: Option<String>,
        /// At most K array tasks at once.
        #[arg(long, value_name = "K")]
        array_max: Option<usize>,
        /// Cores per array task (sbatch --cpus-per-task; each task runs its shard on them).
        #[arg(long, default_value_t = 1)]
        cpus_per_task: usize,
        /// Write DIR/slurm/run.sbatch and merge.sbatch without submitting them.
        #[arg(long)]
        no_submit: bool,
    },
    /// Write a Kubernetes Indexed Job (DIR/k8s/job.json; `kubectl apply -f` it) whose pods run
    /// one shard each from a shared volume.
    K8s {
        /// The sweep's folder, as `sweep plan --out` made it.
        dir: PathBuf,
        /// Container image with `ffdic` on its PATH.
        #[arg(long)]
        image: String,
        /// PersistentVolumeClaim holding the sweep folder (ReadWriteMany).
        #[arg(long)]
        claim: String,
        /// Where the claim is mounted in the pods.
        #[arg(long, default_value = "/sweep")]
        mount_path: String,
        /// The sweep folder inside the claim.
        #[arg(long, default_value = ".")]
        sub_path: String,
        /// Pods at once.
        #[arg(long, default_value_t = 8)]
        parallelism: usize,
        /// Cores each pod requests (and runs its shard on).
        #[arg(long, default_value_t = 1)]
        cpus_per_pod: usize,
    },
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
        SweepCommand::Slurm {
            dir,
            partition,
            time,
            array_max,
            cpus_per_task,
            no_submit,
        } => slurm_command(
            dir,
            &SlurmOptions {
                partition: partition.clone(),
                time: time.clone(),
                array_max: *array_max,
                cpus_per_task: *cpus_per_task,
            },
            !no_submit,
        ),
        SweepCommand::K8s {
            dir,
            image,
            claim,
            mount_path,
            sub_path,
            parallelism,
            cpus_per_pod,
        } => k8s_command(
            dir,
            &K8sOptions {
                image: image.clone(),
                claim: claim.clone(),
                mount_path: mount_path.clone(),
                sub_path: sub_path.clone(),
                parallelism: *parallelism,
                cpus_per_pod: *cpus_per_pod,
            },
        ),
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
    // Counts already shown come again (a shard asks before every point): drawn once.
    let shown = std::sync::atomic::AtomicUsize::new(usize::MAX);
    let counts = pool.install(|| {
        run_shards(dir, &plan, &select, &|d, t| {
            if shown.swap(d, std::sync::atomic::Ordering::Relaxed) != d {
                bar.update(d, t);
            }
            true
        })
    })?;
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
        "{} cells in {} (and map.arrow, map.json); heat maps map_*.svg, bias plots bias_*.svg, recommendations.txt",
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

fn write_file(path: &Path, text: &str) -> Result<()> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Runs `sbatch --parsable ARGS SCRIPT`; the job id it prints.
fn sbatch(args: &[String], script: &Path) -> Result<String> {
    let out = std::process::Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .arg(script)
        .output()
        .context("cannot run sbatch (is Slurm's client installed and SLURM_CONF set?)")?;
    if !out.status.success() {
        bail!(
            "sbatch {} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    // `--parsable` prints "jobid" or "jobid;cluster".
    Ok(text
        .trim()
        .split(';')
        .next()
        .unwrap_or_default()
        .to_string())
}

fn slurm_command(dir: &Path, options: &SlurmOptions, submit: bool) -> Result<()> {
    let dir = dir
        .canonicalize()
        .with_context(|| format!("{} (plan the sweep first)", dir.display()))?;
    let plan = Plan::read(&dir)?;
    let exe = std::env::current_exe().context("cannot locate this ffdic")?;
    let scripts = slurm_scripts(&plan.spec.name, &dir, &exe, plan.shards.len(), options);
    let (run, merge) = (dir.join("slurm/run.sbatch"), dir.join("slurm/merge.sbatch"));
    write_file(&run, &scripts.run)?;
    write_file(&merge, &scripts.merge)?;
    if !submit {
        println!(
            "{} and {} written ({} array tasks for {} shards)",
            run.display(),
            merge.display(),
            scripts.array_tasks,
            plan.shards.len()
        );
        return Ok(());
    }
    let array = sbatch(&[], &run)?;
    let merge_job = sbatch(&[format!("--dependency=afterok:{array}")], &merge)?;
    println!(
        "submitted array job {array} ({} tasks for {} shards) and merge job {merge_job} (after it); logs in {}",
        scripts.array_tasks,
        plan.shards.len(),
        dir.join("slurm").display()
    );
    Ok(())
}

fn k8s_command(dir: &Path, options: &K8sOptions) -> Result<()> {
    let plan = Plan::read(dir)?;
    let job = k8s_job(&plan.spec.name, plan.shards.len(), options);
    let path = dir.join("k8s/job.json");
    write_file(&path, &(serde_json::to_string_pretty(&job)? + "\n"))?;
    println!(
        "{} written: an Indexed Job of {} completions (`kubectl apply -f` it; merge afterwards with `ffdic sweep merge`)",
        path.display(),
        plan.shards.len()
    );
    Ok(())
}
