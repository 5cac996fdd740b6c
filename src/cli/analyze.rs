//! `ffdic analyze REF DEF [DEF…]`: DIC of one image pair, or of a sequence (several deformed
//! images, or one folder of them) analysed incrementally; summary on stdout, points and
//! settings on disk.

use super::analyze_card::{card_json, card_text, load_card};
use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::Args;
use ffdic::dic::{
    analyze_sequence, bias_against, Bias, DicResult, DicSettings, Interpolation, PoiGrid,
    PoiStatus, PolygonMask, PreparedReference, RasterMask, SequenceFrame, ShapeFunction, Summary,
};
use ffdic::image::{read_image, Image, Roi};
use serde_json::json;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// Reference image: TIFF (8- or 16-bit integer or 32-bit float grey, palette, grey+alpha),
    /// PNG (8- or 16-bit grey; colour as luma) or BMP, told apart by content.
    pub reference: PathBuf,
    /// Deformed image(s), same size as the reference. Several images, or one folder of frames
    /// (taken in name order), are analysed as a sequence: incrementally, the reference moving
    /// to the previous frame when correlation drops, displacements accumulated.
    #[arg(required = true)]
    pub deformed: Vec<PathBuf>,
    /// Subset side in px (odd).
    #[arg(long, default_value_t = DicSettings::default().subset_px)]
    pub subset: usize,
    /// Distance between points in px.
    #[arg(long, default_value_t = DicSettings::default().step_px)]
    pub step: usize,
    /// Rectangle of point centres X,Y,W,H in px (default: centred 800x800, clipped).
    #[arg(long)]
    pub roi: Option<Roi>,
    /// Strain window side in points (odd).
    #[arg(long, default_value_t = DicSettings::default().strain_window)]
    pub strain_window: usize,
    /// Interpolation: bspline3 or bspline5.
    #[arg(long, default_value = "bspline3")]
    pub interp: Interpolation,
    /// Subset shape function: affine (first order) or quadratic (second order, slower).
    #[arg(long, default_value = "affine")]
    pub shape: ShapeFunction,
    /// Gaussian pre-filter σ in px applied to both images (0: off).
    #[arg(long, default_value_t = DicSettings::default().prefilter_sigma_px)]
    pub prefilter_sigma: f64,
    /// Points whose ZNCC is below this are not valid (low_correlation).
    #[arg(long, default_value_t = DicSettings::default().min_zncc)]
    pub min_zncc: f64,
    /// Largest rigid motion the global search looks for, px.
    #[arg(long, default_value_t = DicSettings::default().max_motion_px)]
    pub max_motion: usize,
    /// Points whose predicted displacement standard deviation exceeds this are not valid
    /// (no_texture), px.
    #[arg(long, default_value_t = DicSettings::default().max_displacement_std_px)]
    pub max_displacement_std: f64,
    /// Normalised median test threshold (Westerweel & Scarano 2005: 2).
    #[arg(
        long,
        default_value_t = DicSettings::default().outlier_threshold.expect("on by default"),
        conflicts_with = "no_outlier_test"
    )]
    pub outlier_threshold: f64,
    /// Turn the neighbour (median) test off.
    #[arg(long)]
    pub no_outlier_test: bool,
    /// Mask image, same size as the reference: points on its zero pixels are not analysed.
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// Polygon mask, JSON: {"include": [[[x,y],…],…], "exclude": [[[x,y],…],…]} in px.
    #[arg(long)]
    pub mask_polygons: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write points.csv (points_NNNN.csv for a sequence) and settings.json into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The rigid move the stage was commanded to make, px (U,V): the summary adds the bias of
    /// the measured mean against it, with the 95 % interval of its random part, and the std.
    #[arg(long, value_name = "U,V", value_parser = parse_expected, allow_hyphen_values = true)]
    pub expected: Option<(f64, f64)>,
    /// The images' scale, px per mm (dataset.json's scale_px_per_mm): points.csv gains
    /// x_mm, y_mm, u_mm, v_mm.
    #[arg(long, value_name = "PX_PER_MM", value_parser = parse_scale)]
    pub scale: Option<f64>,
    /// A camera card (`ffdic calibrate`): a stored model's name or a TOML file. The summary adds
    /// the displacements with its lens distortion and target tilt taken off (a tilt needs
    /// --scale), points.csv gains u_card, v_card. One image pair only.
    #[arg(long, value_name = "NAME|FILE")]
    pub card: Option<String>,
    /// Data folder whose models/ holds the cards `--card NAME` finds.
    #[arg(long, default_value = "data")]
    pub data: PathBuf,
    /// Print one JSON document on stdout and nothing else.
    #[arg(long)]
    pub json: bool,
}

fn parse_scale(text: &str) -> Result<f64, String> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|s| s.is_finite() && *s > 0.0)
        .ok_or_else(|| format!("'{text}': a scale in px per mm, a positive number"))
}

/// What the strain columns hold, in settings.json and the points file's docs.
const STRAIN_DEFINITION: &str = "small-strain tensor from the displacement gradient of a strain window (a plane fitted to u and v): exx = du/dx, eyy = dv/dy, exy = (du/dy + dv/dx)/2; dimensionless (x 1e6 for microstrain)";

/// `0.5,-0.1` as (0.5, −0.1) px.
fn parse_expected(text: &str) -> Result<(f64, f64), String> {
    super::number_pair(text, "U,V in px, e.g. 0.5,0")
}

pub fn run(args: &AnalyzeArgs) -> Result<()> {
    let (reference, _) = read_image(&args.reference)?;
    let frames = deformed_paths(&args.deformed)?;
    let settings = settings(args)?;
    if let Some(note) = roi_note(&settings, reference.width(), reference.height()) {
        eprintln!("{note}");
    }
    let mask = match &args.mask {
        Some(path) => Some(RasterMask::from_image(&read_image(path)?.0)),
        None => None,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    if frames.len() == 1 {
        let (deformed, _) = read_image(&frames[0])?;
        return run_pair(args, &settings, mask.as_ref(), &reference, &deformed, &pool);
    }
    if mask.is_some() {
        bail!("--mask applies to one image pair; for a sequence use --mask-polygons");
    }
    if args.expected.is_some() {
        bail!("--expected applies to one image pair (a sequence's frames each moved differently)");
    }
    if args.card.is_some() {
        bail!("--card applies to one image pair");
    }
    run_sequence(args, &settings, &reference, &frames, &pool)
}

/// What became of a stated ROI that reaches beyond the image: never clipped in silence.
fn roi_note(settings: &DicSettings, width: usize, height: usize) -> Option<String> {
    let roi = settings.roi?;
    let kept = roi.clip(width, height)?;
    if kept == roi {
        return None;
    }
    let points = PoiGrid::new(settings, width, height).map_or(0, |g| g.nx() * g.ny());
    Some(format!(
        "note: --roi {roi} reaches beyond the {width}x{height} image; analysed inside {kept} ({points} points)"
    ))
}

fn settings(args: &AnalyzeArgs) -> Result<DicSettings> {
    let mask = match &args.mask_polygons {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            let polygons: PolygonMask = serde_json::from_str(&text)
                .with_context(|| format!("{} is not a polygon mask", path.display()))?;
            Some(polygons)
        }
        None => None,
    };
    Ok(DicSettings {
        subset_px: args.subset,
        step_px: args.step,
        roi: args.roi,
        strain_window: args.strain_window,
        interpolation: args.interp,
        shape: args.shape,
        prefilter_sigma_px: args.prefilter_sigma,
        min_zncc: args.min_zncc,
        max_motion_px: args.max_motion,
        max_displacement_std_px: args.max_displacement_std,
        outlier_threshold: (!args.no_outlier_test).then_some(args.outlier_threshold),
        mask,
        ..DicSettings::default()
    })
}

/// The deformed images: the paths given, or the frames (TIFF, PNG, BMP) of one folder in name
/// order.
fn deformed_paths(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    if let [dir] = given {
        if dir.is_dir() {
            let frames = ffdic::image::frame_files(dir)
                .with_context(|| format!("cannot list {}", dir.display()))?;
            if frames.is_empty() {
                bail!("{} holds no .tif, .tiff, .png or .bmp image", dir.display());
            }
            return Ok(frames);
        }
    }
    Ok(given.to_vec())
}

fn run_pair(
    args: &AnalyzeArgs,
    settings: &DicSettings,
    mask: Option<&RasterMask>,
    reference: &Image,
    deformed: &Image,
    pool: &rayon::ThreadPool,
) -> Result<()> {
    let card = match &args.card {
        Some(given) => Some(load_card(
            given,
            &args.data,
            (reference.width(), reference.height()),
            args.scale,
        )?),
        None => None,
    };
    let bar = ProgressBar::new(!args.json, "correlating");
    let started = Instant::now();
    let result = pool.install(|| -> Result<DicResult> {
        let prepared = PreparedReference::with_mask(reference, settings, mask)?;
        Ok(prepared.correlate(deformed, Some(&|d, t| bar.update(d, t)))?)
    })?;
    let elapsed_s = started.elapsed().as_secs_f64();
    bar.finish();

    if let Some(dir) = &args.out {
        create_dir(dir)?;
        let corrected = card.as_ref().map(|c| c.corrected(None, &result.points));
        write_atomic(
            &dir.join("points.csv"),
            points_csv(&result, args.scale, corrected.as_deref()).as_bytes(),
        )?;
        let doc = settings_json(&result, args, &args.deformed[0]);
        write_atomic(
            &dir.join("settings.json"),
            serde_json::to_string_pretty(&doc)?.as_bytes(),
        )?;
    }
    let bias = args.expected.map(|e| bias_against(&result, e));
    let mut doc = ffdic::report::dic_summary_json(&result);
    doc["elapsed_s"] = json!(elapsed_s);
    doc["settings"] = settings_json(&result, args, &args.deformed[0]);
    if let Some([u, v]) = &bias {
        doc["bias"] = json!({ "u": u, "v": v });
    }
    if let Some(card) = &card {
        doc["card"] = card_json(card, &result);
    }
    let mut out = std::io::stdout().lock();
    if args.json {
        writeln!(out, "{doc}")?;
    } else {
        let s = &result.summary;
        writeln!(
            out,
            "{} points, {} valid, {:.3} s ({:.0} POI/s)",
            s.points,
            s.valid,
            elapsed_s,
            s.points as f64 / elapsed_s
        )?;
        write_statuses(&mut out, &result)?;
        write_summary(&mut out, s)?;
        if let Some(bias) = &bias {
            write_bias(&mut out, bias)?;
        }
        if let Some(card) = &card {
            write!(out, "{}", card_text(card, &result))?;
        }
    }
    if result.summary.valid == 0 && result.summary.points > 0 {
        // Everything is written above (nothing lost); the exit status says it failed.
        bail!("{}", no_valid_point(&result, settings));
    }
    Ok(())
}

/// Why an analysis kept no point, from the most common status of the points it analysed.
fn no_valid_point(result: &DicResult, settings: &DicSettings) -> String {
    // In name order, so that a tie goes to the same status every time.
    let counts = result.status_counts();
    let masked = counts
        .iter()
        .find(|(s, _)| *s == PoiStatus::Masked)
        .map_or(0, |(_, n)| *n);
    let analysed = result.summary.points - masked;
    let Some(&(status, n)) = counts
        .iter()
        .filter(|(s, _)| *s != PoiStatus::Masked)
        .max_by_key(|(_, n)| *n)
    else {
        return format!(
            "no valid point: the mask excludes all {} points",
            result.summary.points
        );
    };
    let cause = match status {
        PoiStatus::LeftImage => "the motion carries the subsets out of the image: a smaller ROI \
                                 (--roi) or subset (--subset), or check the pairing of the images"
            .to_string(),
        PoiStatus::NoContrast | PoiStatus::NoTexture => {
            "the reference has no usable speckle texture in the ROI \
             (flat or blank there; --roi elsewhere, or a larger --subset)"
                .to_string()
        }
        PoiStatus::LowCorrelation if settings.min_zncc > 0.95 => format!(
            "--min-zncc {} is stricter than noisy images reach",
            settings.min_zncc
        ),
        PoiStatus::LowCorrelation
        | PoiStatus::NotConverged
        | PoiStatus::Implausible
        | PoiStatus::Outlier
        | PoiStatus::Converged
        | PoiStatus::Masked => format!(
            "the images may not show the same speckle, or the motion exceeds --max-motion ({} px) \
             or is more than a translation with moderate rotation and strain",
            settings.max_motion_px
        ),
    };
    let masked_note = if masked > 0 {
        format!("; {masked} masked")
    } else {
        String::new()
    };
    format!(
        "no valid point ({n} of {analysed} analysed points {}{masked_note}): {cause}",
        status.as_str()
    )
}

fn run_sequence(
    args: &AnalyzeArgs,
    settings: &DicSettings,
    reference: &Image,
    frames: &[PathBuf],
    pool: &rayon::ThreadPool,
) -> Result<()> {
    // Frames are read one at a time as the analysis reaches them; a read error stops it.
    let mut read_error: Option<anyhow::Error> = None;
    let images = frames.iter().map_while(|path| match read_image(path) {
        Ok((image, _)) => Some(image),
        Err(e) => {
            read_error = Some(e.into());
            None
        }
    });
    let bar = ProgressBar::new(!args.json, "frames");
    let started = Instant::now();
    let mut written: Result<()> = Ok(());
    let results = pool.install(|| {
        analyze_sequence(reference, images, settings, |frame: &SequenceFrame| {
            bar.update(frame.index, frames.len());
            if let (Some(dir), Ok(())) = (&args.out, &written) {
                written = create_dir(dir).and_then(|_| {
                    write_atomic(
                        &dir.join(format!("points_{:04}.csv", frame.index)),
                        points_csv(&frame.result, args.scale, None).as_bytes(),
                    )
                });
            }
        })
    })?;
    bar.finish();
    if let Some(e) = read_error {
        return Err(e);
    }
    written?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let frame_docs: Vec<serde_json::Value> = results
        .iter()
        .map(|f| {
            let mut doc = ffdic::report::dic_summary_json(&f.result);
            doc["index"] = json!(f.index);
            doc["file"] = json!(frames[f.index - 1]);
            doc["reference_index"] = json!(f.reference_index);
            doc
        })
        .collect();
    let settings_doc = results
        .first()
        .map(|f| settings_json(&f.result, args, &frames[0]))
        .unwrap_or(serde_json::Value::Null);
    if let Some(dir) = &args.out {
        let doc = json!({ "settings": settings_doc, "frames": frame_docs });
        write_atomic(
            &dir.join("settings.json"),
            serde_json::to_string_pretty(&doc)?.as_bytes(),
        )?;
    }
    let mut out = std::io::stdout().lock();
    if args.json {
        let doc = json!({ "frames": frame_docs, "elapsed_s": elapsed_s, "settings": settings_doc });
        writeln!(out, "{doc}")?;
        return Ok(());
    }
    writeln!(
        out,
        "{} frames in {elapsed_s:.3} s; displacements accumulated from {}",
        results.len(),
        args.reference.display()
    )?;
    writeln!(
        out,
        "{:>5} {:>4} {:>7} {:>12} {:>12} {:>10} {:>10}  file",
        "frame", "ref", "valid", "u mean px", "v mean px", "exx µε", "eyy µε"
    )?;
    for f in &results {
        let s = &f.result.summary;
        writeln!(
            out,
            "{:>5} {:>4} {:>7} {:>12.5} {:>12.5} {:>10.0} {:>10.0}  {}",
            f.index,
            f.reference_index,
            s.valid,
            s.u.mean,
            s.v.mean,
            s.exx.mean * 1e6,
            s.eyy.mean * 1e6,
            frames[f.index - 1].display()
        )?;
    }
    Ok(())
}

fn write_statuses(out: &mut impl Write, result: &DicResult) -> Result<()> {
    let counts = result.status_counts();
    if counts.len() > 1 {
        let parts: Vec<String> = counts
            .iter()
            .map(|(status, n)| format!("{} {n}", status.as_str()))
            .collect();
        writeln!(out, "statuses: {}", parts.join(", "))?;
    }
    Ok(())
}

fn write_summary(out: &mut impl Write, s: &Summary) -> Result<()> {
    // Decimals a person reads: 1e-5 px resolves a displacement's std, 0.1 µε a strain's.
    for (name, st, scale, unit, dp) in [
        ("u", s.u, 1.0, "px", 5),
        ("v", s.v, 1.0, "px", 5),
        ("exx", s.exx, 1e6, "µε", 1),
        ("eyy", s.eyy, 1e6, "µε", 1),
        ("exy", s.exy, 1e6, "µε", 1),
    ] {
        let ci = interval_text(st.std_ci95.map(|x| x * scale), dp);
        writeln!(
            out,
            "{name:>4}: mean {:>12.dp$} std {:>10.dp$} {ci:<22} min {:>12.dp$} max {:>12.dp$} {unit}",
            st.mean * scale,
            st.std * scale,
            st.min * scale,
            st.max * scale
        )?;
    }
    writeln!(
        out,
        "      [95 % interval of the std: block bootstrap over the grid; ≈ 25 % too narrow, see docs/study.md]"
    )?;
    Ok(())
}

/// `[lo, hi]` to `dp` decimals, `[—]` when the interval was not computed.
fn interval_text([lo, hi]: [f64; 2], dp: usize) -> String {
    if lo.is_finite() && hi.is_finite() {
        format!("[{lo:.dp$}, {hi:.dp$}]")
    } else {
        "[—]".to_string()
    }
}

fn write_bias(out: &mut impl Write, bias: &[Bias; 2]) -> Result<()> {
    writeln!(out, "against the commanded move:")?;
    for (name, b) in ["u", "v"].iter().zip(bias) {
        let ci = interval_text(b.bias_ci95_px, 5);
        writeln!(
            out,
            "{name:>4}: expected {:>10.5} measured {:>10.5} bias {:>10.5} {ci:<22} std {:>9.5} px",
            b.expected_px, b.mean_px, b.bias_px, b.std_px
        )?;
    }
    writeln!(
        out,
        "      [95 % interval of the bias's random part: block bootstrap of the mean; ≈ 25 % too narrow]"
    )?;
    Ok(())
}

fn settings_json(result: &DicResult, args: &AnalyzeArgs, deformed: &Path) -> serde_json::Value {
    let mut doc = ffdic::report::dic_settings_json(result);
    doc["reference"] = json!(args.reference);
    doc["deformed"] = json!(deformed);
    doc["mask"] = json!(args.mask);
    doc["strain"] = json!(STRAIN_DEFINITION);
    if let Some(scale) = args.scale {
        doc["scale_px_per_mm"] = json!(scale);
    }
    doc
}

/// One row per point: position and displacement in px (and in mm with a scale), the strain
/// ([`STRAIN_DEFINITION`]), the match quality, and with a card the corrected displacement.
fn points_csv(
    result: &DicResult,
    scale_px_per_mm: Option<f64>,
    card: Option<&[(f64, f64)]>,
) -> String {
    let mut csv = String::from("x,y,u,v,exx,eyy,exy,zncc,u_std_px,v_std_px,iterations,status");
    if scale_px_per_mm.is_some() {
        csv.push_str(",x_mm,y_mm,u_mm,v_mm");
    }
    if card.is_some() {
        csv.push_str(",u_card,v_card");
    }
    csv.push('\n');
    for (i, p) in result.points.iter().enumerate() {
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            p.x,
            p.y,
            p.u,
            p.v,
            p.exx,
            p.eyy,
            p.exy,
            p.zncc,
            p.u_std_px,
            p.v_std_px,
            p.iterations,
            p.status.as_str()
        ));
        if let Some(k) = scale_px_per_mm {
            csv.push_str(&format!(",{},{},{},{}", p.x / k, p.y / k, p.u / k, p.v / k));
        }
        if let Some((u, v)) = card.and_then(|c| c.get(i)) {
            csv.push_str(&format!(",{u},{v}"));
        }
        csv.push('\n');
    }
    csv
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    ffdic::atomic_write::write_atomically(path, bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}
