//! `ffdic diagnose DATASET`: fit every catalogue effect the model lacks, rank by ΔBIC and by the
//! drop of the discrepancy, name the verdict, the confounded pairs and what the dataset cannot
//! reveal; `--write-model` writes the model with the winner added.

use super::compare::{load_analysis_model, AnalysisArgs};
use super::ProgressBar;
use anyhow::{Context, Result};
use clap::Args;
use ffdic::diagnose::{diagnose, Diagnosis};
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Dataset folder (format ffdic-dataset/1).
    pub dataset: PathBuf,
    /// Analysis model (default: config/models/baseline.toml, embedded).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Print one JSON document and nothing else.
    #[arg(long)]
    pub json: bool,
    /// Write the model with the winner added (TOML).
    #[arg(long)]
    pub write_model: Option<PathBuf>,
    #[command(flatten)]
    pub analysis: AnalysisArgs,
}

pub fn diagnosis_text(d: &Diagnosis) -> String {
    let g = |x: f64| format!("{x:.4e}");
    let rows: Vec<Vec<String>> = d
        .candidates
        .iter()
        .map(|c| {
            let params: Vec<String> = c
                .params
                .iter()
                .map(|(k, v)| match c.stderr.get(k) {
                    Some(se) => format!("{k}={} ± {}", g(*v), g(*se)),
                    None => format!("{k}={}", g(*v)),
                })
                .collect();
            vec![
                c.effect.clone(),
                format!("{:.1}", c.delta_bic),
                format!("{:.5}", c.discrepancy_px),
                format!("{:+.5}", c.drop_px),
                if c.significant { "yes" } else { "no" }.into(),
                params.join(", "),
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
        "\nmodel {} ({}): discrepancy {:.5} px; verdict: {}\n",
        d.model.name, d.model.version, d.discrepancy_px, d.verdict
    );
    if let Some(a) = &d.after {
        s += &format!("with {} added: {:.5} px\n", d.verdict, a.discrepancy_px);
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

pub fn run(args: &DiagnoseArgs) -> Result<()> {
    let model = load_analysis_model(&args.model)?;
    let options = args.analysis.options()?;
    let bar = ProgressBar::new(!args.json, "fitting candidates");
    let d = diagnose(&args.dataset, &model, &options, &|done, total| {
        bar.update(done, total);
        true
    })?;
    bar.finish();
    if let Some(path) = &args.write_model {
        match &d.winner_model {
            Some(m) => std::fs::write(path, m.to_toml())
                .with_context(|| format!("cannot write {}", path.display()))?,
            None => eprintln!("verdict none: no model written to {}", path.display()),
        }
    }
    if args.json {
        println!("{}", serde_json::to_string(&d)?);
    } else {
        print!("{}", diagnosis_text(&d));
        if let (Some(path), Some(_)) = (&args.write_model, &d.winner_model) {
            println!("model with {} written to {}", d.verdict, path.display());
        }
    }
    Ok(())
}
