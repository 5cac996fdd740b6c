//! One analysis: prepare the reference once (interpolation coefficients, gradients, grid), then
//! correlate any number of deformed images against it, in parallel over grid rows.
//!
//! Initial guesses: a global phase correlation gives the integer rigid offset. The first point of
//! each grid row refines its own integer displacement by a ZNCC search around that offset; every
//! further point starts IC-GN from the prediction of its converged left neighbour (the affine
//! field moved by one step), in the spirit of reliability-guided propagation (Pan,
//! "Reliability-guided digital image correlation for image deformation measurement", Appl. Opt.
//! 48 (2009)). When that start does not converge to a good correlation — a discontinuity, a
//! neighbour gone wrong — the point falls back to its own integer search, so no point inherits
//! an error it cannot check.
//!
//! Rows are independent tasks processed left to right, so the result does not depend on the
//! number of threads.

use super::bspline::BSplineImage;
use super::fft_guess::global_offset;
use super::icgn::{Scratch, SubsetReference};
use super::integer_search::integer_search;
use super::prefilter::gaussian_blur;
use super::strain::compute_strains;
use super::{DicError, DicResult, DicSettings, PoiGrid, PoiResult, PoiStatus, Summary, Warp};
use crate::image::Image;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Progress callback: (points done, points in all). Called from worker threads.
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// The reference image with everything the correlation needs from it.
pub struct PreparedReference {
    /// The reference after the pre-filter.
    image: Image,
    settings: DicSettings,
    grid: PoiGrid,
    grad_x: Vec<f32>,
    grad_y: Vec<f32>,
}

impl PreparedReference {
    pub fn new(image: &Image, settings: &DicSettings) -> Result<Self, DicError> {
        settings.validate()?;
        let grid = PoiGrid::new(settings, image.width(), image.height())?;
        let image = gaussian_blur(image, settings.prefilter_sigma_px);
        let (grad_x, grad_y) = BSplineImage::new(&image, settings.interpolation).gradient_images();
        Ok(Self {
            image,
            settings: settings.clone(),
            grid,
            grad_x,
            grad_y,
        })
    }

    pub fn grid(&self) -> &PoiGrid {
        &self.grid
    }

    pub fn settings(&self) -> &DicSettings {
        &self.settings
    }

    /// Correlates `deformed` against the reference and derives strains and statistics.
    pub fn correlate(
        &self,
        deformed: &Image,
        progress: Option<Progress<'_>>,
    ) -> Result<DicResult, DicError> {
        let (w, h) = (self.image.width(), self.image.height());
        if (deformed.width(), deformed.height()) != (w, h) {
            return Err(DicError::SizeMismatch {
                ref_w: w,
                ref_h: h,
                def_w: deformed.width(),
                def_h: deformed.height(),
            });
        }
        let s = &self.settings;
        let deformed = &gaussian_blur(deformed, s.prefilter_sigma_px);
        let offset = global_offset(&self.image, deformed, self.grid.roi, s.max_motion_px);
        let def_spline = BSplineImage::new(deformed, s.interpolation);
        let (nx, ny) = (self.grid.nx(), self.grid.ny());
        let total = nx * ny;
        let done = AtomicUsize::new(0);
        let half = s.half_subset();
        let rows: Vec<Vec<PoiResult>> = (0..ny)
            .into_par_iter()
            .map_init(
                || Scratch::new(half),
                |scratch, j| {
                    let row = self.correlate_row(j, deformed, &def_spline, offset, scratch);
                    let n = done.fetch_add(nx, Ordering::Relaxed) + nx;
                    if let Some(report) = progress {
                        report(n, total);
                    }
                    row
                },
            )
            .collect();
        let mut points: Vec<PoiResult> = rows.into_iter().flatten().collect();
        compute_strains(&self.grid, &mut points, s.strain_window);
        let summary = Summary::of(&points);
        Ok(DicResult {
            settings: s.clone(),
            grid: self.grid.clone(),
            points,
            global_offset_px: offset,
            strain_gauge_px: s.strain_gauge_px(),
            summary,
        })
    }

    fn correlate_row(
        &self,
        j: usize,
        deformed: &Image,
        def_spline: &BSplineImage,
        offset: (i64, i64),
        scratch: &mut Scratch,
    ) -> Vec<PoiResult> {
        let s = &self.settings;
        let y0 = self.grid.ys[j];
        let mut previous: Option<Warp> = None;
        let mut out = Vec::with_capacity(self.grid.nx());
        for &x0 in &self.grid.xs {
            let (x, y) = (x0 as f64, y0 as f64);
            let predicted = previous.map(|w| w.moved_by(s.step_px as f64, 0.0));
            let result =
                self.correlate_point((x0, y0), deformed, def_spline, offset, predicted, scratch);
            previous = match result.status {
                PoiStatus::Converged => Some(Warp {
                    u: result.u,
                    ux: result.du_dx,
                    uy: result.du_dy,
                    v: result.v,
                    vx: result.dv_dx,
                    vy: result.dv_dy,
                }),
                _ => None,
            };
            debug_assert!(result.x == x && result.y == y);
            out.push(result);
        }
        out
    }

    fn correlate_point(
        &self,
        (x0, y0): (usize, usize),
        deformed: &Image,
        def_spline: &BSplineImage,
        offset: (i64, i64),
        predicted: Option<Warp>,
        scratch: &mut Scratch,
    ) -> PoiResult {
        let s = &self.settings;
        let half = s.half_subset();
        let (x, y) = (x0 as f64, y0 as f64);
        let Some(sref) = SubsetReference::prepare(
            &self.image,
            &self.grad_x,
            &self.grad_y,
            (x0, y0),
            half,
            scratch,
        ) else {
            return PoiResult::invalid(x, y, PoiStatus::NoContrast, f64::NAN, 0);
        };
        // A converged neighbour's prediction is usually within a few thousandths of a pixel:
        // IC-GN starts from it directly. Points without one, and points whose propagated start
        // does not converge to a good correlation, get the integer ZNCC search.
        let propagated = predicted
            .map(|p| sref.solve(def_spline, p, s.convergence_px, s.max_iterations, scratch));
        let outcome = match propagated {
            Some(o) if o.status == PoiStatus::Converged && o.zncc >= s.min_zncc => o,
            _ => {
                let centre = predicted.map_or(offset, |p| (p.u.round() as i64, p.v.round() as i64));
                let Some(best) = integer_search(
                    &scratch.f0,
                    sref.df,
                    deformed,
                    (x0, y0),
                    half,
                    centre,
                    s.search_radius_px as i64,
                ) else {
                    return PoiResult::invalid(x, y, PoiStatus::LeftImage, f64::NAN, 0);
                };
                let start = Warp::translation(best.u as f64, best.v as f64);
                sref.solve(
                    def_spline,
                    start,
                    s.convergence_px,
                    s.max_iterations,
                    scratch,
                )
            }
        };
        let status = match outcome.status {
            PoiStatus::Converged if !(outcome.zncc >= s.min_zncc) => PoiStatus::LowCorrelation,
            other => other,
        };
        if status != PoiStatus::Converged {
            return PoiResult::invalid(x, y, status, outcome.zncc, outcome.iterations);
        }
        let w = outcome.warp;
        PoiResult {
            x,
            y,
            u: w.u,
            v: w.v,
            du_dx: w.ux,
            du_dy: w.uy,
            dv_dx: w.vx,
            dv_dy: w.vy,
            exx: f64::NAN,
            eyy: f64::NAN,
            exy: f64::NAN,
            zncc: outcome.zncc,
            iterations: outcome.iterations,
            status,
        }
    }
}

/// Prepares the reference and correlates one deformed image: the whole analysis of one pair.
pub fn analyze(
    reference: &Image,
    deformed: &Image,
    settings: &DicSettings,
    progress: Option<Progress<'_>>,
) -> Result<DicResult, DicError> {
    PreparedReference::new(reference, settings)?.correlate(deformed, progress)
}
