//! A comparison drawn: where the model fails — the residual map of each run and scheme, its
//! profiles against position, the mean residual against the sub-pixel fraction of the motion
//! (interpolation bias is periodic in it: Schreier, Braasch & Sutton, Opt. Eng. 39 (2000)) — and
//! the image statistics measured beside the model's.

use super::{distinct, BarChart, Heatmap, Mark, Series, XyPlot, XySeries};
use crate::diagnose::{Accuracy, Comparison, ImageComparison};

fn file_safe(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Every plot of a comparison as (file name, SVG text).
pub fn comparison_svgs(cmp: &Comparison) -> Vec<(String, String)> {
    let mut out = vec![(SUMMARY_SVG.to_string(), summary_svg(cmp))];
    out.extend(residual_map_svgs(cmp));
    out.extend(residual_profile_svgs(cmp));
    out.push(("residual_vs_fraction.svg".into(), fraction_svg(cmp)));
    out.push(("accuracy_vs_commanded.svg".into(), accuracy_svg(cmp)));
    for im in &cmp.images {
        out.extend(image_svgs(im));
    }
    out
}

/// The figure that leads a comparison: where the model fails, at a glance.
pub const SUMMARY_SVG: &str = "summary.svg";

/// The discrepancy and its three parts as small multiples on one axis: the total of every run
/// (groups) and scheme (series), each bar labelled with the part that dominates it, then the
/// parts alone — rigid (where the stage landed), field (an effect the model lacks), std
/// (noise) — each with its ±2 SE bar, so a part below its noise shows as a bar of error alone.
fn summary_svg(cmp: &Comparison) -> String {
    use crate::diagnose::RunComparison;
    type Part = fn(&RunComparison) -> (f64, f64);
    let runs = distinct(cmp.runs.iter().map(|r| r.id.clone()));
    let schemes = distinct(cmp.runs.iter().map(|r| r.scheme.clone()));
    let find =
        |run: &str, scheme: &str| cmp.runs.iter().find(|r| r.id == run && r.scheme == scheme);
    let panel = |title: String, part: Part, labelled: bool| BarChart {
        title,
        y_label: "[px]".into(),
        groups: runs.clone(),
        series: schemes
            .iter()
            .map(|scheme| {
                let of = |run: &String| find(run, scheme).map(part);
                Series {
                    name: scheme.clone(),
                    values: runs
                        .iter()
                        .map(|r| of(r).map_or(f64::NAN, |p| p.0))
                        .collect(),
                    labels: runs
                        .iter()
                        .map(|r| find(r, scheme).filter(|_| labelled).map(dominant_part))
                        .collect(),
                    errors: runs
                        .iter()
                        .map(|r| of(r).map(|(v, se)| [(v - 2.0 * se).max(0.0), v + 2.0 * se]))
                        .collect(),
                }
            })
            .collect(),
    };
    let pm = super::length_pm;
    let parts: [(String, Part, bool); 4] = [
        (
            format!(
                "discrepancy D: {} px",
                pm(cmp.discrepancy_px, cmp.discrepancy_se_px)
            ),
            |r| (r.discrepancy_px, r.se.discrepancy_se_px),
            true,
        ),
        (
            format!(
                "rigid (stage landing, bias): {}",
                pm(cmp.parts.rigid_px, cmp.parts_se.rigid_px)
            ),
            |r| (r.rigid_px, r.se.rigid_se_px),
            false,
        ),
        (
            format!(
                "field (an effect missing): {}",
                pm(cmp.parts.field_px, cmp.parts_se.field_px)
            ),
            |r| (r.field_px, r.se.field_se_px),
            false,
        ),
        (
            format!(
                "std (random error): {}",
                pm(cmp.parts.std_px, cmp.parts_se.std_px)
            ),
            |r| (r.std_px, r.se.std_se_px),
            false,
        ),
    ];
    let panels: Vec<BarChart> = parts
        .into_iter()
        .map(|(title, part, labelled)| panel(title, part, labelled))
        .collect();
    super::small_multiples(
        "Discrepancy per run and scheme, and its three parts (bars ±2 SE; one axis)",
        &panels,
        2,
        460,
        340,
    )
}

/// The largest of a run's three parts, named.
fn dominant_part(r: &crate::diagnose::RunComparison) -> String {
    // Reversed: `max_by` keeps the last of equals, and a tie goes to the first named.
    [
        ("rigid", r.rigid_px),
        ("field", r.field_px),
        ("std", r.std_px),
    ]
    .into_iter()
    .rev()
    .filter(|(_, px)| !px.is_nan())
    .max_by(|a, b| a.1.total_cmp(&b.1))
    .map_or("—", |(name, _)| name)
    .to_string()
}

/// The residual maps (Δu and Δv) of each run and scheme.
fn residual_map_svgs(cmp: &Comparison) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for r in &cmp.runs {
        for (comp, values) in [("u", &r.residual.du), ("v", &r.residual.dv)] {
            let map = Heatmap {
                title: format!(
                    "Residual Δ{comp} (measured − model), run {}, {}",
                    r.id, r.scheme
                ),
                x_label: "x [px]".into(),
                y_label: "y [px]".into(),
                value_label: format!("Δ{comp} [px]"),
                xs: r.residual.xs.clone(),
                ys: r.residual.ys.clone(),
                values: values.clone(),
                diverging: true,
                x_tick_labels: Vec::new(),
                y_tick_labels: Vec::new(),
                markers: Vec::new(),
            };
            out.push((
                format!(
                    "residual_{}_{}_{comp}.svg",
                    file_safe(&r.id),
                    file_safe(&r.scheme)
                ),
                map.to_svg(640, 520),
            ));
        }
    }
    out
}

/// The mean residual against x and against y: small multiples, one plot per scheme, a line per
/// run and component (a few series each, in colours that do not repeat).
fn residual_profile_svgs(cmp: &Comparison) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for scheme in distinct(cmp.runs.iter().map(|r| r.scheme.clone())) {
        for (name, along_x) in [("x", true), ("y", false)] {
            let mut plot = XyPlot::new(
                &format!("Residual against {name}, {scheme}"),
                &format!("{name} [px]"),
                "mean residual [px]",
            );
            plot.zero_line = true;
            for r in cmp.runs.iter().filter(|r| r.scheme == scheme) {
                let prof = if along_x {
                    &r.residual.profile_x
                } else {
                    &r.residual.profile_y
                };
                for (k, comp) in [(1usize, "u"), (2, "v")] {
                    plot.series.push(XySeries {
                        name: format!("Δ{comp} {}", r.id),
                        points: prof.iter().map(|p| (p[0], p[k])).collect(),
                        mark: Mark::LinePoints,
                        y_err: Vec::new(),
                    });
                }
            }
            out.push((
                format!("residual_vs_{name}_{}.svg", file_safe(&scheme)),
                plot.to_svg(760, 460 + 16 * plot.series.len() as u32),
            ));
        }
    }
    out
}

/// Each run's mean residual against the sub-pixel fraction of its displacement.
fn fraction_svg(cmp: &Comparison) -> String {
    let mut frac = XyPlot::new(
        "Mean residual against sub-pixel fraction",
        "sub-pixel fraction of the measured displacement [px]",
        "mean residual [px]",
    );
    frac.zero_line = true;
    for (k, comp) in [(0usize, "u"), (1, "v")] {
        let mut pts: Vec<(f64, f64)> = cmp
            .runs
            .iter()
            .map(|r| (r.subpixel_fraction[k], r.mean_diff_px[k]))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        frac.series.push(XySeries {
            name: format!("Δ{comp} against fraction of {comp}"),
            points: pts,
            mark: Mark::Points,
            y_err: Vec::new(),
        });
    }
    frac.to_svg(700, 460)
}

/// The measured side against the commanded move, each run and scheme a point: the bias (mean −
/// commanded) with ±2 standard errors and the std, px of the analysed images, against the
/// commanded displacement — for a sub-pixel step series the S-curve of interpolation bias
/// (Schreier, Braasch & Sutton, Opt. Eng. 39 (2000)); for moves of several sizes, how the
/// error grows with the move (the stage's own error included).
fn accuracy_svg(cmp: &Comparison) -> String {
    let mut plot = XyPlot::new(
        "Bias and std against the commanded move",
        "commanded displacement [px]",
        "bias (± 2 SE) and std [px]",
    );
    plot.zero_line = true;
    for (k, comp) in [(0usize, "u"), (1, "v")] {
        let mut runs: Vec<&Accuracy> = cmp.runs.iter().map(|r| &r.accuracy).collect();
        runs.sort_by(|a, b| a.commanded_px[k].total_cmp(&b.commanded_px[k]));
        // An axis the stage never moved along has nothing to show against its commanded value.
        if runs.iter().all(|a| a.commanded_px[k] == 0.0) {
            continue;
        }
        plot.series.push(XySeries {
            name: format!("bias of {comp}"),
            points: runs
                .iter()
                .map(|a| (a.commanded_px[k], a.bias_px[k]))
                .collect(),
            mark: Mark::LinePoints,
            y_err: runs.iter().map(|a| 2.0 * a.bias_se_px[k]).collect(),
        });
        plot.series.push(XySeries {
            name: format!("std of {comp}"),
            points: runs
                .iter()
                .map(|a| (a.commanded_px[k], a.std_px[k]))
                .collect(),
            mark: Mark::Points,
            y_err: Vec::new(),
        });
    }
    plot.to_svg(700, 460)
}

/// The image statistics of one frame, measured beside model: its power spectra, and for a
/// reference its photon-transfer curve and mean-intensity ratio map.
fn image_svgs(im: &ImageComparison) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let tag = match &im.run {
        Some(run) => format!("moved_{}", file_safe(run)),
        None => format!("reference_{}", file_safe(&im.pattern)),
    };
    let mut spec = XyPlot::new(
        &format!("Power spectrum, {tag}"),
        "f [cycles/px]",
        "P / mean² [1/(cycles/px)]",
    );
    spec.log_x = true;
    spec.log_y = true;
    for (name, s) in [
        ("along x, measured", &im.measured.psd_x),
        ("along x, model", &im.model.psd_x),
        ("along y, measured", &im.measured.psd_y),
        ("along y, model", &im.model.psd_y),
    ] {
        spec.series.push(XySeries {
            name: name.into(),
            points: s.iter().map(|b| (b.f, b.value)).collect(),
            mark: Mark::LinePoints,
            y_err: Vec::new(),
        });
    }
    out.push((format!("spectrum_{tag}.svg"), spec.to_svg(700, 520)));
    if im.run.is_none() {
        let mut ptc = XyPlot::new(
            &format!("Noise against mean, {tag}"),
            "mean [DN]",
            "noise variance [DN²]",
        );
        for (name, s) in [("measured", &im.measured.ptc), ("model", &im.model.ptc)] {
            ptc.series.push(XySeries {
                name: name.into(),
                points: s.iter().map(|p| (p.mean_dn, p.variance_dn2)).collect(),
                mark: Mark::LinePoints,
                y_err: Vec::new(),
            });
        }
        out.push((format!("noise_vs_mean_{tag}.svg"), ptc.to_svg(700, 460)));
        let ratio: Vec<f64> = im
            .measured
            .mean_map
            .values
            .iter()
            .zip(&im.model.mean_map.values)
            .map(|(a, b)| a / b - 1.0)
            .collect();
        let map = Heatmap {
            title: format!("Mean intensity, measured / model − 1, {tag}"),
            x_label: "x [px]".into(),
            y_label: "y [px]".into(),
            value_label: "relative difference [1]".into(),
            xs: im.measured.mean_map.xs.clone(),
            ys: im.measured.mean_map.ys.clone(),
            values: ratio,
            diverging: true,
            x_tick_labels: Vec::new(),
            y_tick_labels: Vec::new(),
            markers: Vec::new(),
        };
        out.push((format!("mean_map_{tag}.svg"), map.to_svg(640, 520)));
    }
    out
}
