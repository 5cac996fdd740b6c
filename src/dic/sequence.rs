//! Incremental analysis of an image sequence: each frame is correlated against the current
//! reference, and the reference moves to the previous frame when the correlation drops, with
//! displacements accumulated at the points of the first frame (Pan, Wu & Xia, "Incremental
//! calculation for large deformation measurement using reliability-guided digital image
//! correlation", Opt. Lasers Eng. 50 (2012)). A sequence that strains or turns far beyond what
//! one subset can follow is measured link by link.

use super::strain::compute_strains;
use super::{DicError, DicResult, DicSettings, PoiResult, PoiStatus, PreparedReference, Summary};
use crate::image::{Image, Roi};

/// The reference moves to the previous frame when a frame keeps fewer valid points than this
/// fraction of those the current reference's first frame kept.
pub const REFERENCE_UPDATE_FRACTION: f64 = 0.95;

/// One frame of a sequence: displacements accumulated since the first frame, on its grid.
#[derive(Clone, Debug)]
pub struct SequenceFrame {
    /// Index of the frame in the sequence (the first deformed frame is 1).
    pub index: usize,
    /// Index of the frame that served as reference for this one (0: the first frame).
    pub reference_index: usize,
    pub result: DicResult,
}

/// Analyses `frames` (the deformed images, in order) against `reference`, calling
/// `on_frame` after each. Returns every frame's accumulated result.
pub fn analyze_sequence(
    reference: &Image,
    frames: impl IntoIterator<Item = Image>,
    settings: &DicSettings,
    mut on_frame: impl FnMut(&SequenceFrame),
) -> Result<Vec<SequenceFrame>, DicError> {
    let first = PreparedReference::new(reference, settings)?;
    let grid0 = first.grid().clone();
    let n0 = grid0.len();
    let positions: Vec<(f64, f64)> = grid0
        .ys
        .iter()
        .flat_map(|&y| grid0.xs.iter().map(move |&x| (x as f64, y as f64)))
        .collect();
    // Accumulated displacement of every first-frame point up to the current reference (None
    // once a point is lost) and the status that lost it.
    let mut at_reference: Vec<Option<(f64, f64)>> = vec![Some((0.0, 0.0)); n0];
    let mut latest: Vec<Option<(f64, f64)>> = at_reference.clone();
    let mut lost_status = vec![PoiStatus::Converged; n0];
    let mut current = first;
    let mut reference_index = 0usize;
    let mut baseline_valid: Option<usize> = None;
    let mut previous: Option<Image> = None;
    let mut out = Vec::new();
    for (k, frame) in frames.into_iter().enumerate() {
        let index = k + 1;
        let mut link = current.correlate(&frame, None)?;
        let dropped = baseline_valid
            .is_some_and(|b| (link.valid_count() as f64) < REFERENCE_UPDATE_FRACTION * b as f64);
        if dropped && reference_index + 1 < index {
            if let Some(prev) = previous.take() {
                // The new reference's grid covers where the first frame's points are now.
                at_reference = latest.clone();
                let roi = bounding_roi(&positions, &at_reference, settings, &prev);
                let moved_settings = DicSettings {
                    roi,
                    ..settings.clone()
                };
                current = PreparedReference::new(&prev, &moved_settings)?;
                reference_index = index - 1;
                link = current.correlate(&frame, None)?;
                baseline_valid = None;
            }
        }
        if baseline_valid.is_none() {
            baseline_valid = Some(link.valid_count());
        }
        // Accumulate: each first-frame point, where the current reference sees it, plus the
        // link's displacement there.
        let mut points = Vec::with_capacity(n0);
        for (i, &(x, y)) in positions.iter().enumerate() {
            let sampled = at_reference[i].and_then(|(u0, v0)| {
                sample(&link, x + u0, y + v0).map(|(du, dv, zncc)| (u0 + du, v0 + dv, zncc))
            });
            match sampled {
                Some((u, v, zncc)) => {
                    latest[i] = Some((u, v));
                    let mut p = PoiResult::invalid(x, y, PoiStatus::Converged, zncc, 0);
                    // Subset gradients are not accumulated (they stay NaN); strains come
                    // from the strain window over the accumulated field.
                    (p.u, p.v) = (u, v);
                    points.push(p);
                }
                None => {
                    if latest[i].is_some() {
                        lost_status[i] = nearest_status(&link, x, y, at_reference[i]);
                    }
                    latest[i] = None;
                    points.push(PoiResult::invalid(x, y, lost_status[i], f64::NAN, 0));
                }
            }
        }
        compute_strains(&grid0, &mut points, settings.strain_window);
        let summary = Summary::with_intervals(
            &points,
            grid0.nx(),
            grid0.ny(),
            super::CorrelationLengths::of(settings),
        );
        let result = DicResult {
            settings: settings.clone(),
            grid: grid0.clone(),
            points,
            global_offset_px: link.global_offset_px,
            strain_gauge_px: settings.strain_gauge_px(),
            summary,
        };
        let done = SequenceFrame {
            index,
            reference_index,
            result,
        };
        on_frame(&done);
        out.push(done);
        previous = Some(frame);
    }
    Ok(out)
}

/// Bilinear interpolation of the link's u, v (and the lowest ZNCC) at (x, y); None unless all
/// four surrounding grid points are valid. At a grid point it returns that point exactly.
fn sample(link: &DicResult, x: f64, y: f64) -> Option<(f64, f64, f64)> {
    let g = &link.grid;
    let step = g.step_px as f64;
    let fi = (x - g.xs[0] as f64) / step;
    let fj = (y - g.ys[0] as f64) / step;
    if !(fi >= 0.0 && fj >= 0.0 && fi <= (g.nx() - 1) as f64 && fj <= (g.ny() - 1) as f64) {
        return None;
    }
    let (i0, j0) = (
        (fi.floor() as usize).min(g.nx().saturating_sub(2)),
        (fj.floor() as usize).min(g.ny().saturating_sub(2)),
    );
    let (tx, ty) = (fi - i0 as f64, fj - j0 as f64);
    let (mut u, mut v, mut zncc) = (0.0, 0.0, f64::INFINITY);
    for (di, dj, w) in [
        (0, 0, (1.0 - tx) * (1.0 - ty)),
        (1, 0, tx * (1.0 - ty)),
        (0, 1, (1.0 - tx) * ty),
        (1, 1, tx * ty),
    ] {
        let (i, j) = ((i0 + di).min(g.nx() - 1), (j0 + dj).min(g.ny() - 1));
        let p = &link.points[j * g.nx() + i];
        if w == 0.0 {
            continue;
        }
        if !p.status.is_valid() {
            return None;
        }
        u += w * p.u;
        v += w * p.v;
        zncc = zncc.min(p.zncc);
    }
    Some((u, v, zncc))
}

/// The status of the link's grid point nearest where a lost point was.
fn nearest_status(link: &DicResult, x: f64, y: f64, at: Option<(f64, f64)>) -> PoiStatus {
    let Some((u0, v0)) = at else {
        return PoiStatus::NotConverged;
    };
    let g = &link.grid;
    let step = g.step_px as f64;
    let i = ((x + u0 - g.xs[0] as f64) / step).round();
    let j = ((y + v0 - g.ys[0] as f64) / step).round();
    if i < 0.0 || j < 0.0 || i >= g.nx() as f64 || j >= g.ny() as f64 {
        return PoiStatus::LeftImage;
    }
    let p = &link.points[j as usize * g.nx() + i as usize];
    if p.status.is_valid() {
        PoiStatus::NotConverged
    } else {
        p.status
    }
}

/// The ROI of a new reference: the span of the first frame's points where they are now,
/// widened by one step so the interpolation has neighbours, clipped to the image.
fn bounding_roi(
    positions: &[(f64, f64)],
    displacements: &[Option<(f64, f64)>],
    settings: &DicSettings,
    image: &Image,
) -> Option<Roi> {
    let (mut x0, mut y0, mut x1, mut y1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for (&(x, y), d) in positions.iter().zip(displacements) {
        if let Some((u, v)) = d {
            x0 = x0.min(x + u);
            y0 = y0.min(y + v);
            x1 = x1.max(x + u);
            y1 = y1.max(y + v);
        }
    }
    if !x0.is_finite() {
        return settings.roi;
    }
    let pad = settings.step_px as f64;
    let (w, h) = (image.width() as f64, image.height() as f64);
    let (x0, y0) = ((x0 - pad).max(0.0).floor(), (y0 - pad).max(0.0).floor());
    let (x1, y1) = (
        (x1 + pad).min(w - 1.0).ceil(),
        (y1 + pad).min(h - 1.0).ceil(),
    );
    Some(Roi::new(
        x0 as usize,
        y0 as usize,
        (x1 - x0) as usize,
        (y1 - y0) as usize,
    ))
}
