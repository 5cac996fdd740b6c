//! `ffdic dataset init DIR`: a `dataset.json` for a folder of frames captured by hand — one
//! reference, optional static repeats, the rest a step series in name order.

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use ffdic::dataset::{init_folder, FolderInit, Manifest, Step};
use std::path::{Path, PathBuf};

#[derive(Debug, Args)]
pub struct DatasetArgs {
    #[command(subcommand)]
    pub command: DatasetCommand,
}

#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Write DIR/dataset.json for a folder of frames (TIFF, PNG, BMP): a reference, its static repeats, and
    /// the other frames in name order as a step series (frame k moved by k steps).
    Init(InitArgs),
}

#[derive(Debug, Args)]
pub struct InitArgs {
    /// The folder of frames (.tif, .tiff, .png, .bmp).
    pub dir: PathBuf,
    /// The images' scale, px per mm (a ruler or a calibration target in the field of view).
    #[arg(long, value_name = "PX_PER_MM")]
    pub scale: f64,
    /// The reference frame (default: reference.tif, ref.tif, a name starting with ref, else the
    /// first by name).
    #[arg(long, value_name = "FILE")]
    pub reference: Option<String>,
    /// A static frame of the reference position (repeatable): the camera's noise floor.
    #[arg(long, value_name = "FILE")]
    pub repeat: Vec<String>,
    /// The stage's step between frames, mm (DX,DY).
    #[arg(long, value_name = "DX,DY", value_parser = parse_pair, allow_hyphen_values = true,
          conflicts_with = "step_px", required_unless_present = "step_px")]
    pub step_mm: Option<(f64, f64)>,
    /// The step in px (U,V), converted with --scale.
    #[arg(long, value_name = "U,V", value_parser = parse_pair, allow_hyphen_values = true)]
    pub step_px: Option<(f64, f64)>,
    /// The dataset's name (default: the folder's).
    #[arg(long)]
    pub name: Option<String>,
    /// The print's label (a pattern name for the tables).
    #[arg(long, value_name = "LABEL")]
    pub pattern: Option<String>,
    /// The stage's stated repeatability, µm (1σ per axis).
    #[arg(long, value_name = "UM")]
    pub stage_repeatability_um: Option<f64>,
    /// Replace an existing dataset.json.
    #[arg(long)]
    pub force: bool,
}

fn parse_pair(text: &str) -> Result<(f64, f64), String> {
    super::number_pair(text, "two numbers X,Y, e.g. 0.005,0")
}

pub fn run(args: &DatasetArgs) -> Result<()> {
    match &args.command {
        DatasetCommand::Init(init) => run_init(init),
    }
}

fn run_init(args: &InitArgs) -> Result<()> {
    let step = match (args.step_mm, args.step_px) {
        (Some((dx, dy)), _) => Step::Mm(dx, dy),
        (None, Some((u, v))) => Step::Px(u, v),
        (None, None) => bail!("the step: --step-mm DX,DY or --step-px U,V"),
    };
    let init = FolderInit {
        scale_px_per_mm: args.scale,
        step,
        reference: args.reference.clone(),
        repeats: args.repeat.clone(),
        name: args.name.clone(),
        pattern: args.pattern.clone(),
        stage_repeatability_um: args.stage_repeatability_um,
        force: args.force,
    };
    let manifest = init_folder(&args.dir, &init)?;
    print_summary(&manifest, &args.dir.join("dataset.json"));
    Ok(())
}

fn print_summary(m: &Manifest, path: &Path) {
    let k = m.scale_px_per_mm;
    println!(
        "wrote {}: {} runs against {}{} at {k} px/mm",
        path.display(),
        m.runs.len(),
        m.runs[0].reference,
        if m.runs[0].repeat.is_empty() {
            String::new()
        } else {
            format!(" (repeats {})", m.runs[0].repeat.join(", "))
        }
    );
    println!(
        "{:<16} {:<24} {:>22} {:>22}",
        "run", "frame", "move [mm]", "move [px]"
    );
    for r in &m.runs {
        let (dx, dy) = (r.stage.dx_mm, r.stage.dy_mm);
        println!(
            "{:<16} {:<24} {:>22} {:>22}",
            r.id,
            r.deformed,
            format!("({}, {})", round(dx), round(dy)),
            format!("({}, {})", round(dx * k), round(dy * k))
        );
    }
}

/// A step's multiple without the binary tail (0.30000000000000004 → 0.3).
fn round(x: f64) -> String {
    let s = format!("{:.9}", x);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}
