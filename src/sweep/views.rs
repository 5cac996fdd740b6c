//! What a merged sweep is shown as: the table (`map.csv`, and `map.json` for programs and the
//! dashboard), the recommendations for people, heat maps of the error over print × scheme with
//! the paper's patterns marked, and the bias against the sub-pixel part of the move.

use super::merge::{conditions, conditions_but, recommendations, CellStats, Merged, STAT_NAMES};
use super::plan::Plan;
use super::spec::{NoiseLevel, PrintAxis};
use crate::model::SpecklePattern;
use crate::reduce::Scheme;
use crate::report::{distinct, Heatmap, HeatmapMarker, Mark, XyPlot, XySeries};
use serde::Serialize;
use std::collections::BTreeMap;

/// The paper's scale on its 2x2-reduced images (26 px/mm at full resolution, §3): its dots of
/// 0.5 mm (a, c) and 0.24 mm (b) are 6.5 px and 3.1 px there, the units of the print axis.
const PAPER_REDUCED_PX_PER_MM: f64 = 13.0;

/// One file merging writes: a table or an SVG figure (`figure`).
#[derive(Clone, Debug, PartialEq)]
pub struct MapFile {
    pub name: String,
    pub bytes: Vec<u8>,
    pub figure: bool,
}

/// Every file of a merged sweep: `map.csv`, `map.json`, `recommendations.txt`, `map.arrow`
/// (with the default feature `arrow`), the heat maps
/// `map_{statistic}_{panel}.svg` and, when the sweep has a sub-pixel axis with two values or
/// more, `bias_{u|v}_{scheme}_{panel}.svg`.
pub fn map_files(plan: &Plan, merged: &Merged) -> Vec<MapFile> {
    let figures: Vec<(String, String)> = map_svgs(merged)
        .into_iter()
        .chain(bias_svgs(merged))
        .collect();
    let document = map_document(plan, merged, figures.iter().map(|f| f.0.clone()).collect());
    let table = |name: &str, bytes: Vec<u8>| MapFile {
        name: name.to_string(),
        bytes,
        figure: false,
    };
    let mut files = vec![
        table("map.csv", map_csv(merged).into_bytes()),
        table(
            "map.json",
            serde_json::to_vec_pretty(&document).expect("the map serialises"),
        ),
        table(
            "recommendations.txt",
            recommendations_text(merged).into_bytes(),
        ),
    ];
    #[cfg(feature = "arrow")]
    files.push(table(
        "map.arrow",
        super::arrow::map_arrow(&plan.spec.name, merged),
    ));
    files.extend(figures.into_iter().map(|(name, svg)| MapFile {
        name,
        bytes: svg.into_bytes(),
        figure: true,
    }));
    files
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
        "aperture_x",
        "aperture_y",
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
            let (ax, ay) = t.aperture.map_or((String::new(), String::new()), |[x, y]| {
                (x.to_string(), y.to_string())
            });
            let mut row = vec![
                t.print.label(),
                t.scheme.name.clone(),
                fx.to_string(),
                fy.to_string(),
                well,
                read,
                t.psf_sigma_px.to_string(),
                ax,
                ay,
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

/// A statistic's mean over a cell's realisations and its 95 % interval (null where undefined).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IntervalJson {
    pub mean: f64,
    pub lo: f64,
    pub hi: f64,
}

/// One cell of `map.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CellJson {
    pub print: String,
    pub scheme: String,
    pub fill_x: f64,
    pub fill_y: f64,
    /// `None`: the model's own sensor noise.
    pub noise: Option<NoiseLevel>,
    pub psf_sigma_px: f64,
    /// The sensor's own pixel aperture `[fx, fy]`; `None`: the model's.
    pub pixel_aperture: Option<[f64; 2]>,
    pub subpixel_px: [f64; 2],
    /// Realisations merged.
    pub n: usize,
    pub stats: BTreeMap<&'static str, IntervalJson>,
}

/// One line of the recommendations in `map.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecommendationJson {
    pub scheme: String,
    pub fill_x: f64,
    pub fill_y: f64,
    pub conditions: String,
    pub best_print: String,
    pub best_u_std_px: IntervalJson,
    /// Prints whose mean std u is within 10 % of the best.
    pub within_10_percent: Vec<String>,
}

/// `map.json`: what the daemon serves at `GET /sweeps/{id}/map` and the dashboard draws.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MapDocument {
    pub name: String,
    pub ffdic_version: String,
    pub tasks: usize,
    pub missing_tasks: usize,
    pub statistics: Vec<&'static str>,
    pub cells: Vec<CellJson>,
    pub recommendations: Vec<RecommendationJson>,
    /// File names of the figures written beside it.
    pub figures: Vec<String>,
}

fn interval((mean, [lo, hi]): (f64, [f64; 2])) -> IntervalJson {
    IntervalJson { mean, lo, hi }
}

pub fn map_document(plan: &Plan, merged: &Merged, figures: Vec<String>) -> MapDocument {
    let cells = merged
        .cells
        .iter()
        .map(|c| {
            let t = &c.task;
            let (fill_x, fill_y) = t.scheme.linear_fill_factor();
            CellJson {
                print: t.print.label(),
                scheme: t.scheme.name.clone(),
                fill_x,
                fill_y,
                noise: t.noise,
                psf_sigma_px: t.psf_sigma_px,
                pixel_aperture: t.aperture,
                subpixel_px: t.subpixel_px,
                n: c.n,
                stats: STAT_NAMES
                    .iter()
                    .zip(&c.values)
                    .map(|(name, v)| (*name, interval(*v)))
                    .collect(),
            }
        })
        .collect();
    let recommendations = recommendations(merged, 0.10)
        .into_iter()
        .map(|r| RecommendationJson {
            scheme: r.scheme,
            fill_x: r.fill_factor.0,
            fill_y: r.fill_factor.1,
            conditions: r.conditions,
            best_print: r.best_print,
            best_u_std_px: interval(r.best_u_std_px),
            within_10_percent: r.within,
        })
        .collect();
    MapDocument {
        name: plan.spec.name.clone(),
        ffdic_version: plan.ffdic_version.clone(),
        tasks: plan.task_count(),
        missing_tasks: merged.missing.len(),
        statistics: STAT_NAMES.to_vec(),
        cells,
        recommendations,
        figures,
    }
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

/// Where the paper's patterns sit on a print axis (column index, fractional between two dot
/// diameters) — a and b by their dot diameter at the paper's reduced scale, a print given as a
/// paper preset at its own column.
fn paper_columns(prints: &[PrintAxis]) -> Vec<(f64, &'static str)> {
    let mut out = Vec::new();
    for label in ["a", "b", "c"] {
        if let Some(i) = prints
            .iter()
            .position(|p| *p == PrintAxis::Pattern(label.to_string()))
        {
            out.push((i as f64, label));
            continue;
        }
        // c is a's print defocused and at lower contrast: no dot diameter stands for it.
        if label == "c" {
            continue;
        }
        let preset = SpecklePattern::preset(label).expect("the paper's presets exist");
        let d = preset.dot_diameter_mm * PAPER_REDUCED_PX_PER_MM;
        let diameter = |p: &PrintAxis| match p {
            PrintAxis::DotDiameterPx(d) => Some(*d),
            PrintAxis::Pattern(_) => None,
        };
        let place = prints.windows(2).enumerate().find_map(|(i, w)| {
            let (d0, d1) = (diameter(&w[0])?, diameter(&w[1])?);
            (d0 <= d && d <= d1 && d1 > d0).then(|| i as f64 + (d - d0) / (d1 - d0))
        });
        if let Some(x) = place {
            out.push((x, label));
        }
    }
    out
}

/// Heat maps of std u, std v and std εxx over print × scheme, one per combination of the other
/// axes (a panel): `(file name, svg)`. Circles mark the paper's nine measurements (its patterns
/// at its three fill factors) where the map's axes hold them.
pub fn map_svgs(merged: &Merged) -> Vec<(String, String)> {
    let panels = distinct(merged.cells.iter().map(|c| conditions(&c.task)));
    let mut out = Vec::new();
    for (k, panel) in panels.iter().enumerate() {
        let cells: Vec<&CellStats> = merged
            .cells
            .iter()
            .filter(|c| conditions(&c.task) == *panel)
            .collect();
        let prints = distinct(cells.iter().map(|c| c.task.print.clone()));
        let schemes = distinct(cells.iter().map(|c| c.task.scheme.clone()));
        let markers: Vec<HeatmapMarker> = paper_columns(&prints)
            .into_iter()
            .flat_map(|(x, label)| {
                let schemes = &schemes;
                Scheme::presets().into_iter().filter_map(move |preset| {
                    let row = schemes.iter().position(|s| *s == preset)?;
                    Some(HeatmapMarker {
                        x,
                        y: row as f64,
                        label: label.to_string(),
                    })
                })
            })
            .collect();
        for (stat, label) in [
            ("u_std_px", "std u [px]"),
            ("v_std_px", "std v [px]"),
            ("exx_std", "std εxx"),
        ] {
            let values = schemes
                .iter()
                .flat_map(|s| {
                    prints.iter().map(|p| {
                        cells
                            .iter()
                            .find(|c| c.task.scheme == *s && c.task.print == *p)
                            .map_or(f64::NAN, |c| c.stat(stat).0)
                    })
                })
                .collect();
            let map = Heatmap {
                title: format!("{label}: {panel}"),
                x_label: if markers.is_empty() {
                    "print (dot diameter, reduced px)".into()
                } else {
                    "print (dot diameter, reduced px); ○ the paper's patterns".into()
                },
                y_label: "fill-factor scheme".into(),
                value_label: label.into(),
                xs: (0..prints.len()).map(|i| i as f64).collect(),
                ys: (0..schemes.len()).map(|i| i as f64).collect(),
                values,
                diverging: false,
                x_tick_labels: prints
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (i as f64, p.label()))
                    .collect(),
                y_tick_labels: schemes
                    .iter()
                    .enumerate()
                    .map(|(i, s)| (i as f64, s.name.clone()))
                    .collect(),
                markers: markers.clone(),
            };
            out.push((format!("map_{stat}_{k}.svg"), map.to_svg(780, 380)));
        }
    }
    out
}

/// The bias of u against the sub-pixel part of the move in x (and of v against y), one line per
/// print, one figure per scheme and panel: the systematic error interpolation and the pixel
/// aperture leave, which a sweep's mean over positions would hide.
pub fn bias_svgs(merged: &Merged) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (axis, component, stat) in [(0, "u", "u_bias_px"), (1, "v", "v_bias_px")] {
        let positions = distinct(merged.cells.iter().map(|c| c.task.subpixel_px[axis]));
        if positions.len() < 2 {
            continue;
        }
        let panels = distinct(
            merged
                .cells
                .iter()
                .map(|c| conditions_but(&c.task, Some(axis))),
        );
        let schemes = distinct(merged.cells.iter().map(|c| c.task.scheme.name.clone()));
        for (k, panel) in panels.iter().enumerate() {
            for scheme in &schemes {
                let cells: Vec<&CellStats> = merged
                    .cells
                    .iter()
                    .filter(|c| {
                        c.task.scheme.name == *scheme
                            && conditions_but(&c.task, Some(axis)) == *panel
                    })
                    .collect();
                let prints = distinct(cells.iter().map(|c| c.task.print.label()));
                let mut plot = XyPlot::new(
                    &format!("bias of {component}, {scheme}: {panel}"),
                    &format!(
                        "sub-pixel part of the move in {} [reduced px]",
                        ["x", "y"][axis]
                    ),
                    &format!("mean {component} − truth [px]"),
                );
                plot.zero_line = true;
                plot.series = prints
                    .iter()
                    .map(|p| {
                        let mut points: Vec<(f64, f64)> = cells
                            .iter()
                            .filter(|c| c.task.print.label() == *p)
                            .map(|c| (c.task.subpixel_px[axis], c.stat(stat).0))
                            .collect();
                        points.sort_by(|a, b| a.0.total_cmp(&b.0));
                        XySeries {
                            name: format!("dots {p}"),
                            points,
                            mark: Mark::LinePoints,
                            y_err: Vec::new(),
                        }
                    })
                    .collect();
                let file_scheme: String = scheme
                    .chars()
                    .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                    .collect();
                out.push((
                    format!("bias_{component}_{file_scheme}_{k}.svg"),
                    plot.to_svg(640, 420),
                ));
            }
        }
    }
    out
}
