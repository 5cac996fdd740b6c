//! `ffdic analyze REF DEF`: DIC of one image pair, summary on stdout, points and settings on disk.

use super::ProgressBar;
use anyhow::{Context, Result};
use clap::Args;
use ffdic::dic::{DicResult, DicSettings, Interpolation, PreparedReference};
use ffdic::image::{read_tiff, Roi};
use serde_json::json;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// Reference image (8- or 16-bit grayscale TIFF).
    pub reference: PathBuf,
    /// Deformed image, same size as the reference.
    pub deformed: PathBuf,
    /// Subset side in px (odd).
    #[arg(long, default_value_t = 41)]
    pub subset: usize,
    /// Distance between points in px.
    #[arg(long, default_value_t = 20)]
    pub step: usize,
    /// Rectangle of point centres X,Y,W,H in px (default: centred 800x800, clipped).
    #[arg(long)]
    pub roi: Option<Roi>,
    /// Strain window side in points (odd).
    #[arg(long, default_value_t = 7)]
    pub strain_window: usize,
    /// Interpolation: bspline3 or bspline5.
    #[arg(long, default_value = "bspline3")]
    pub interp: Interpolation,
    /// Gaussian pre-filter σ in px applied to both images (0: off).
    #[arg(long, default_value_t = 0.7)]
    pub prefilter_sigma: f64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write points.csv and settings.json into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON document on stdout and nothing else.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &AnalyzeArgs) -> Result<()> {
    let (reference, _) = read_tiff(&args.reference)?;
    let (deformed, _) = read_tiff(&args.deformed)?;
    let settings = DicSettings {
        subset_px: args.subset,
        step_px: args.step,
        roi: args.roi,
        strain_window: args.strain_window,
        interpolation: args.interp,
        prefilter_sigma_px: args.prefilter_sigma,
        ..DicSettings::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    let bar = ProgressBar::new(!args.json, "correlating");
    let started = Instant::now();
    let result = pool.install(|| -> Result<DicResult> {
        let prepared = PreparedReference::new(&reference, &settings)?;
        Ok(prepared.correlate(&deformed, Some(&|d, t| bar.update(d, t)))?)
    })?;
    let elapsed_s = started.elapsed().as_secs_f64();
    bar.finish();

    if let Some(dir) = &args.out {
        write_outputs(dir, &result, args)?;
    }
    let summary = result.summary;
    let doc = json!({
        "points": summary.points,
        "valid": summary.valid,
        "u": summary.u, "v": summary.v,
        "exx": summary.exx, "eyy": summary.eyy, "exy": summary.exy,
        "global_offset_px": result.global_offset_px,
        "elapsed_s": elapsed_s,
        "settings": settings_json(&result, args),
    });
    let mut out = std::io::stdout().lock();
    if args.json {
        writeln!(out, "{doc}")?;
    } else {
        let s = &summary;
        writeln!(
            out,
            "{} points, {} valid, {:.3} s ({:.0} POI/s)",
            s.points,
            s.valid,
            elapsed_s,
            s.points as f64 / elapsed_s
        )?;
        for (name, st, scale, unit) in [
            ("u", s.u, 1.0, "px"),
            ("v", s.v, 1.0, "px"),
            ("exx", s.exx, 1e6, "µε"),
            ("eyy", s.eyy, 1e6, "µε"),
            ("exy", s.exy, 1e6, "µε"),
        ] {
            writeln!(
                out,
                "{name:>4}: mean {:>12.5} std {:>10.5} min {:>12.5} max {:>12.5} {unit}",
                st.mean * scale,
                st.std * scale,
                st.min * scale,
                st.max * scale
            )?;
        }
    }
    Ok(())
}

fn settings_json(result: &DicResult, args: &AnalyzeArgs) -> serde_json::Value {
    json!({
        "reference": args.reference,
        "deformed": args.deformed,
        "dic": result.settings,
        "roi": result.grid.roi,
        "grid": { "nx": result.grid.nx(), "ny": result.grid.ny() },
        "strain_gauge_px": result.strain_gauge_px,
        "criterion": "znssd",
        "shape_function": "first_order",
        "algorithm": "icgn",
        "ffdic_version": ffdic::VERSION,
    })
}

fn write_outputs(dir: &Path, result: &DicResult, args: &AnalyzeArgs) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut csv = String::from("x,y,u,v,exx,eyy,exy,zncc,iterations,status\n");
    for p in &result.points {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{}\n",
            p.x,
            p.y,
            p.u,
            p.v,
            p.exx,
            p.eyy,
            p.exy,
            p.zncc,
            p.iterations,
            p.status.as_str()
        ));
    }
    write_atomic(&dir.join("points.csv"), csv.as_bytes())?;
    let settings = serde_json::to_string_pretty(&settings_json(result, args))?;
    write_atomic(&dir.join("settings.json"), settings.as_bytes())
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    ffdic::store::write_atomically(path, bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}
