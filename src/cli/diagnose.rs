//! `ffdic diagnose DATASET`: fit every catalogue effect the model lacks, rank by ΔBIC and by the
//! drop of the discrepancy, name the verdict, the confounded pairs and what the dataset cannot
//! reveal; `--write-model` writes the model with the winner added.

use super::compare::{load_analysis_model, AnalysisArgs};
use super::diagnose_on_bench::{on_bench, OnBench};
use super::ProgressBar;
use anyhow::{Context, Result};
use clap::Args;
use ffdic::diagnose::{diagnose_rounds, Candidate, Diagnosis, Method, Rounds, MAX_ROUNDS};
use ffdic::model::effects::{join_effects, verdict_name};
use ffdic::report::{length_pm, parameters_text, plus_minus, significant};
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Dataset folder (format ffdic-dataset/1), or its dataset.json.
    #[arg(value_parser = super::dataset_folder)]
    pub dataset: PathBuf,
    /// Analysis model: a TOML file, or a model name — embedded (baseline, paper-bench,
    /// paper-bench-distortion) or stored by the daemon in DATA/models (default: baseline).
    #[arg(long, value_name = "FILE|NAME")]
    pub model: Option<String>,
    /// Print one JSON document and nothing else.
    #[arg(long)]
    pub json: bool,
    /// Write the model with the winner added (TOML).
    #[arg(long)]
    pub write_model: Option<PathBuf>,
    /// Add the winner and diagnose again, up to this many rounds (stops at `none`).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=MAX_ROUNDS as u64))]
    pub rounds: u64,
    /// Then resolve on the bench what the diagnosis left open: capture the runs that separate
    /// the pairs the dataset's design confounds and reveal the effects it cannot (moves of
    /// several sizes along x and y, a sub-pixel step series, static frames, on the dataset's
    /// target), append them to the dataset as new runs (a new dataset in DATA/datasets) and
    /// diagnose again.
    #[arg(long)]
    pub on_bench: bool,
    /// With --on-bench: the daemon config naming the bench (default: the embedded config, the
    /// mock bench); its data folder is replaced by --data.
    #[arg(long, requires = "on_bench")]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub analysis: AnalysisArgs,
}

/// "yes", or "no: " and the criteria the candidate fails.
fn significance(c: &Candidate) -> String {
    if c.significant {
        return "yes".into();
    }
    let k = &c.criteria;
    let mut why = Vec::new();
    if !k.beyond_null {
        // A fit whose χ² is not curved at its end (at a bound of its range, or flat) has no
        // standard error, and so no distance from none to state (`stderr` leaves it out).
        why.push(if c.stderr.is_empty() && !c.params.is_empty() {
            "no standard error at the fit".to_string()
        } else {
            "within 2 SE of none".to_string()
        });
    }
    let excluded = c.method == Method::Excluded;
    if excluded {
        why.push("not rendered (excluded below)".into());
    }
    if k.beyond_null && !excluded && !k.delta_bic_ok {
        why.push("ΔBIC ≥ −10".into());
    }
    if k.beyond_null && !excluded && !k.drop_ok {
        why.push(format!(
            "drop {} px, image χ² drop {}",
            plus_minus(k.drop_px, k.drop_se_px),
            plus_minus(k.image_chi2_drop, k.image_chi2_se)
        ));
    }
    if !k.within_range {
        why.push("at the range's bound".into());
    }
    if !k.separable_from_print {
        why.push("confounded with the print's or the light's non-uniformity".into());
    }
    format!("no: {}", why.join("; "))
}

pub fn diagnosis_text(d: &Diagnosis) -> String {
    let rows: Vec<Vec<String>> = d
        .candidates
        .iter()
        .map(|c| {
            vec![
                c.effect.to_string(),
                format!("{:.1}", c.delta_bic),
                significant(c.discrepancy_px, 3),
                plus_minus(c.drop_px, c.criteria.drop_se_px),
                significance(c),
                parameters_text(&c.params, &c.stderr),
            ]
        })
        .collect();
    let mut s = ffdic::report::text_table(
        &[
            "effect",
            "ΔBIC",
            "D [px]",
            "drop [px]",
            "significant",
            "parameters",
        ],
        &rows,
    );
    s += &format!(
        "\nmodel {} ({}): discrepancy {} px; verdict: {}\n",
        d.model.name,
        d.model.version,
        length_pm(d.discrepancy_px, d.discrepancy_se_px),
        verdict_name(&d.verdict)
    );
    for c in d
        .candidates
        .iter()
        .filter_map(|c| c.criteria.outside_range.as_ref().map(|o| (c, o)))
    {
        s += &format!("{} outside the catalogue's range: {}\n", c.0.effect, c.1);
    }
    s += &format!("unexplained by the model: {}\n", d.unexplained.summary);
    if let Some(a) = &d.after {
        s += &format!(
            "with {} added: {} px{}\n",
            verdict_name(&d.verdict),
            length_pm(a.discrepancy_px, a.discrepancy_se_px),
            d.explained_fraction.map_or(String::new(), |f| format!(
                " ({:.0} % of the unexplained low-order field)",
                100.0 * f
            ))
        );
    }
    if let Some(left) = &d.unexplained_after {
        s += &format!(
            "{}left with it: {}\n",
            if d.partial { "partial verdict: " } else { "" },
            left.summary
        );
    }
    if let Some(w) = &d.withheld {
        s += &format!("not named: {}\n", w.reason);
    }
    for c in d
        .candidates
        .iter()
        .filter(|c| Some(&c.effect) == d.verdict.as_ref())
    {
        for note in &c.notes {
            s += &format!("{}: {note}\n", c.effect);
        }
    }
    for c in &d.confounded {
        s += &format!(
            "confounded ({}): {} and {} — separate them with {}\n",
            c.evidence, c.effects[0], c.effects[1], c.separate_with
        );
    }
    for n in &d.not_identifiable {
        s += &format!(
            "not identifiable: {} — {}; add {}\n",
            n.effect, n.reason, n.runs_to_add
        );
    }
    s
}

/// The fall over the rounds, one line each.
pub fn rounds_text(r: &Rounds) -> String {
    let mut s = String::from("\nrounds:\n");
    for (k, round) in r.rounds.iter().enumerate() {
        let params = parameters_text(&round.params, &round.stderr);
        s += &format!(
            "  {}. {}: {} px → verdict {}{}{}\n",
            k + 1,
            round.model,
            length_pm(round.discrepancy_px, round.discrepancy_se_px),
            verdict_name(&round.verdict),
            if params.is_empty() {
                String::new()
            } else {
                format!(" ({params})")
            },
            round
                .after_px
                .map_or(String::new(), |a| format!(" → {} px", significant(a, 3)))
        );
    }
    s += &format!(
        "found: {}; final discrepancy {} px\nleft unexplained: {}\n",
        if r.verdicts.is_empty() {
            "none".to_string()
        } else {
            join_effects(&r.verdicts, ", ")
        },
        significant(r.final_discrepancy_px, 3),
        r.final_unexplained.summary
    );
    s
}

pub fn run(args: &DiagnoseArgs) -> Result<()> {
    let model = load_analysis_model(&args.model, &args.analysis.data)?;
    let options = args.analysis.options()?;
    let (r, bench) = match args.on_bench {
        true => {
            let mut config = match &args.config {
                Some(p) => ffdic::service::DaemonConfig::load(p)?,
                None => ffdic::service::DaemonConfig::embedded(),
            };
            config.data_dir = args.analysis.data.clone();
            let setting = (&model, &options, args.rounds as usize);
            let (before, b) = on_bench(&args.dataset, setting, config, !args.json)?;
            (before, Some(b))
        }
        false => {
            let bar = ProgressBar::new(!args.json, "fitting candidates");
            let r = diagnose_rounds(
                &args.dataset,
                &model,
                &options,
                args.rounds as usize,
                &|done, total| {
                    bar.update(done, total);
                    true
                },
            )?;
            bar.finish();
            (r, None)
        }
    };
    if let Some(path) = &args.write_model {
        if r.verdicts.is_empty() {
            eprintln!("verdict none: no model written to {}", path.display());
        } else {
            std::fs::write(path, r.final_model.to_toml())
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    if args.json {
        let mut doc = r.to_json();
        if let Some(b) = &bench {
            let mut on_bench = serde_json::to_value(&b.bench)?;
            on_bench["folder"] = serde_json::json!(b.folder);
            doc = serde_json::json!({
                "before": doc,
                "on_bench": on_bench,
                "after": b.after.as_ref().map(Rounds::to_json),
            });
        }
        println!("{doc}");
        return Ok(());
    }
    print_rounds(&r, args);
    if let (Some(path), false) = (&args.write_model, r.verdicts.is_empty()) {
        println!(
            "model with {} written to {}",
            join_effects(&r.verdicts, ", "),
            path.display()
        );
    }
    if let Some(b) = &bench {
        print!("{}", on_bench_text(b));
        if let Some(after) = &b.after {
            print_rounds(after, args);
        }
    }
    Ok(())
}

/// What the bench captured, and where the merged dataset is.
fn on_bench_text(b: &OnBench) -> String {
    let (Some(plan), Some(folder)) = (&b.bench.plan, &b.folder) else {
        return format!("\n== on the bench: {}\n", b.message);
    };
    let runs: Vec<&str> = b.bench.runs.iter().map(|r| r.describe()).collect();
    let moves: Vec<String> = plan
        .moves
        .iter()
        .map(|m| format!("({:.3}, {:.3})", m.dx_mm, m.dy_mm))
        .collect();
    let pairs: Vec<String> = b
        .bench
        .design
        .iter()
        .flat_map(|d| &d.pairs)
        .map(|p| {
            format!(
                "{}/{} {:.3} -> {:.3}",
                p.effects[0], p.effects[1], p.correlation_before, p.correlation_after
            )
        })
        .collect();
    let steps: usize = plan.step_series.iter().map(|s| s.count).sum();
    format!(
        "\n== on the bench: {} (moves {} mm, {} phase-scan steps, {} static frames){}; the dataset with them: {}\n",
        runs.join(", "),
        moves.join(" "),
        steps,
        plan.static_frames,
        match pairs.is_empty() {
            true => String::new(),
            false => format!("; signature correlations {}", pairs.join(", ")),
        },
        folder.display()
    )
}

/// A diagnosis's rounds as text (with `--rounds` > 1 the fall over them too).
fn print_rounds(r: &Rounds, args: &DiagnoseArgs) {
    for (k, d) in r.diagnoses.iter().enumerate() {
        if r.diagnoses.len() > 1 {
            println!("== round {}", k + 1);
        }
        print!("{}", diagnosis_text(d));
    }
    if args.rounds > 1 {
        print!("{}", rounds_text(r));
    }
}
