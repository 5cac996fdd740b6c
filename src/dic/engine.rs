//! One analysis: prepare the reference once (interpolation coefficients, gradients, grid, mask),
//! then correlate any number of deformed images against it.
//!
//! A correlation runs in four stages, each parallel over points and each independent of the
//! number of threads:
//! 1. **Seeds** on a coarse lattice: an integer ZNCC search around the global rigid offset
//!    (phase correlation), then IC-GN. When fewer than half the seeds hold, the motion is not
//!    a translation: a Fourier-Mellin similarity (rotation, scale, translation) predicts each
//!    failed seed's full first-order shape and IC-GN starts from it.
//! 2. **Propagation** from the seeds ([`super::propagate`]): each point starts from its best
//!    valid neighbour's shape.
//! 3. **Search** where propagation could not reach or failed: an integer search around the
//!    prediction of the nearest valid point, then another round of propagation.
//! 4. **Validation**: every point is judged on its own evidence ([`super::validate`]) as it is
//!    solved, then against the field: its texture against the image noise, its ZNSSD against the field's median (a partial match
//!    at a discontinuity), and the normalised median test; a point that fails is solved
//!    once more from the neighbour that agrees best with the median, and keeps the `outlier`
//!    status if it still fails.

use super::bspline::BSplineImage;
use super::fft_guess::ReferenceSpectrum;
use super::icgn::{Scratch, SubsetReference};
use super::integer_search::integer_search;
use super::mask::{analysed_points, RasterMask};
use super::prefilter::gaussian_blur;
use super::propagate::{seed_indices, warp_of, Field};
use super::quadratic::{QuadraticSolve, QuadraticWarp};
use super::similarity::{estimate_similarity, Similarity};
use super::strain::compute_strains;
use super::validate::{
    median_test_failures, noise_std, own_status, relative_correlation_failures,
    MIN_TEXTURE_TO_NOISE,
};
use super::{
    DicError, DicResult, DicSettings, PoiGrid, PoiResult, PoiStatus, ShapeFunction, Summary, Warp,
};
use crate::image::{Image, ImageView};
use rayon::prelude::*;

/// Progress callback: (points done, points in all). Called from the calling thread.
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// What a caller watches a correlation with: its progress, and whether to give it up.
#[derive(Clone, Copy, Default)]
pub struct Watch<'a> {
    pub progress: Option<Progress<'a>>,
    /// Asked before every point is solved, from any thread: once it says `true`, the remaining
    /// points are skipped and the correlation ends with [`DicError::Cancelled`] — within one
    /// point's IC-GN, not one whole field (a dense 1.4 M-point field once ignored a cancel for
    /// minutes).
    pub cancelled: Option<&'a (dyn Fn() -> bool + Sync)>,
}

impl Watch<'_> {
    fn is_cancelled(&self) -> bool {
        self.cancelled.is_some_and(|c| c())
    }
}

/// Seed lattice spacing, in grid points: ≈100 seeds on the paper's dense 161x161 grid, a few
/// on a small one.
const SEED_SPACING_POINTS: usize = 16;
/// A seed guides propagation only if its ZNCC is within this of the best seed's: a seed that
/// IC-GN pulled onto a wrong match correlates far worse than the true ones, and would otherwise
/// lead a whole region astray before any neighbour could object.
const SEED_ZNCC_MARGIN: f64 = 0.15;
/// Rounds of search-then-propagate for the points propagation leaves.
const SEARCH_ROUNDS: usize = 3;

/// The reference image with everything the correlation needs from it.
pub struct PreparedReference {
    /// The reference after the pre-filter.
    image: Image,
    settings: DicSettings,
    grid: PoiGrid,
    grad_x: Vec<f32>,
    grad_y: Vec<f32>,
    /// Per grid point (row-major): inside the mask.
    analysed: Vec<bool>,
    /// Per grid point: grey-level standard deviation of its pre-filtered reference subset.
    subset_std: Vec<f64>,
    /// The global offset's reference window, transformed once for every deformed frame; `None`
    /// for a reference without texture (offset (0, 0)).
    offset_reference: Option<ReferenceSpectrum>,
}

/// How a seed's first guess is made.
#[derive(Clone, Copy, Debug)]
enum Guess {
    Translation((i64, i64)),
    Similarity(Similarity),
}

impl Guess {
    fn warp_at(&self, x: f64, y: f64) -> Warp {
        match self {
            Guess::Translation((u, v)) => Warp::translation(*u as f64, *v as f64),
            Guess::Similarity(s) => s.warp_at(x, y),
        }
    }
}

impl PreparedReference {
    /// The reference, pre-filtered, its B-spline gradients and its grid. `image` is an
    /// [`Image`] or any borrowed [`ImageView`]: it is read once, by the pre-filter.
    pub fn new<'a>(
        image: impl Into<ImageView<'a>>,
        settings: &DicSettings,
    ) -> Result<Self, DicError> {
        Self::with_mask(image, settings, None)
    }

    /// As [`PreparedReference::new`], with a raster mask (non-zero pixels analysed) on top of
    /// the settings' polygons.
    pub fn with_mask<'a>(
        image: impl Into<ImageView<'a>>,
        settings: &DicSettings,
        mask: Option<&RasterMask>,
    ) -> Result<Self, DicError> {
        let image = image.into();
        settings.validate()?;
        if let Some(m) = mask {
            if m.size() != (image.width(), image.height()) {
                return Err(DicError::MaskSize {
                    mask_w: m.size().0,
                    mask_h: m.size().1,
                    width: image.width(),
                    height: image.height(),
                });
            }
        }
        let grid = PoiGrid::new(settings, image.width(), image.height())?;
        let analysed = analysed_points(&grid, settings.mask.as_ref(), mask);
        let image = gaussian_blur(image, settings.prefilter_sigma_px);
        let (grad_x, grad_y) = BSplineImage::new(&image, settings.interpolation).gradient_images();
        let subset_std = subset_stds(&image, &grid, settings.half_subset());
        let size = (image.width(), image.height());
        let offset_reference =
            ReferenceSpectrum::of_image(&image, grid.roi, settings.max_motion_px, size);
        Ok(Self {
            offset_reference,
            subset_std,
            image,
            settings: settings.clone(),
            grid,
            grad_x,
            grad_y,
            analysed,
        })
    }

    pub fn grid(&self) -> &PoiGrid {
        &self.grid
    }

    pub fn settings(&self) -> &DicSettings {
        &self.settings
    }

    /// Correlates `deformed` against the reference and derives strains and statistics.
    pub fn correlate<'a>(
        &self,
        deformed: impl Into<ImageView<'a>>,
        progress: Option<Progress<'_>>,
    ) -> Result<DicResult, DicError> {
        self.correlate_watched(
            deformed,
            Watch {
                progress,
                cancelled: None,
            },
        )
    }

    /// As [`PreparedReference::correlate`], with a caller that may give it up ([`Watch`]).
    pub fn correlate_watched<'a>(
        &self,
        deformed: impl Into<ImageView<'a>>,
        watch: Watch<'_>,
    ) -> Result<DicResult, DicError> {
        let progress = watch.progress;
        let deformed = deformed.into();
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
        let offset = self
            .offset_reference
            .as_ref()
            .map_or((0, 0), |r| r.offset_in(deformed));
        if watch.is_cancelled() {
            return Err(DicError::Cancelled);
        }
        let pair = Pair {
            reference: self,
            deformed,
            spline: BSplineImage::new(deformed, s.interpolation),
            watch,
        };
        let (nx, ny) = (self.grid.nx(), self.grid.ny());
        let total = nx * ny;
        // Progress counts points decided so far: solved at least once (valid or not) or masked.
        let report = |field: &Field| {
            if let Some(report) = progress {
                let done = (0..total)
                    .filter(|&k| field.result(k).is_some() || field.is_masked(k))
                    .count();
                report(done, total);
            }
        };
        let mut field = Field::new(nx, ny, &self.analysed);
        let guess = pair.seed(&mut field, offset);
        report(&field);
        pair.propagate_and_search(&mut field, &guess, &report);
        if watch.is_cancelled() {
            return Err(DicError::Cancelled);
        }
        let mut points = field.into_points(&self.grid.xs, &self.grid.ys);
        pair.judge(&mut points);
        if watch.is_cancelled() {
            return Err(DicError::Cancelled);
        }
        compute_strains(&self.grid, &mut points, s.strain_window);
        let summary = Summary::with_intervals(
            &points,
            self.grid.nx(),
            self.grid.ny(),
            super::CorrelationLengths::of(s),
        );
        Ok(DicResult {
            settings: s.clone(),
            grid: self.grid.clone(),
            points,
            global_offset_px: offset,
            strain_gauge_px: s.strain_gauge_px(),
            summary,
        })
    }

    fn position(&self, k: usize) -> (f64, f64) {
        let nx = self.grid.nx();
        (self.grid.xs[k % nx] as f64, self.grid.ys[k / nx] as f64)
    }

    /// The start of the valid 3x3 neighbour whose prediction of point k lies nearest the
    /// neighbours' median prediction.
    fn agreeing_neighbour_start(&self, points: &[PoiResult], k: usize) -> Option<Warp> {
        let (nx, ny) = (self.grid.nx(), self.grid.ny());
        let (i, j) = (k % nx, k / nx);
        let (x, y) = self.position(k);
        let mut predictions: Vec<Warp> = Vec::with_capacity(8);
        for jj in j.saturating_sub(1)..=(j + 1).min(ny - 1) {
            for ii in i.saturating_sub(1)..=(i + 1).min(nx - 1) {
                let n = &points[jj * nx + ii];
                if (ii, jj) != (i, j) && n.status.is_valid() {
                    predictions.push(warp_of(n).moved_by(x - n.x, y - n.y));
                }
            }
        }
        if predictions.is_empty() {
            return None;
        }
        let median = |f: fn(&Warp) -> f64| {
            let mut v: Vec<f64> = predictions.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (mu, mv) = (median(|w| w.u), median(|w| w.v));
        predictions.into_iter().min_by(|a, b| {
            let da = (a.u - mu).hypot(a.v - mv);
            let db = (b.u - mu).hypot(b.v - mv);
            da.total_cmp(&db)
        })
    }
}

/// The reference and one pre-filtered deformed image.
struct Pair<'a> {
    reference: &'a PreparedReference,
    deformed: &'a Image,
    spline: BSplineImage,
    watch: Watch<'a>,
}

impl Pair<'_> {
    /// Step 1, the seeds: points on a coarse lattice solved from the global guess — the rigid
    /// offset, or the similarity once it has been estimated when fewer than half of the seeds
    /// hold (it also serves the search for points with no valid point anywhere). Seeds within
    /// `SEED_ZNCC_MARGIN` of the best guide the propagation.
    fn seed(&self, field: &mut Field, offset: (i64, i64)) -> Guess {
        let r = self.reference;
        let seeds: Vec<usize> = seed_indices(r.grid.nx(), r.grid.ny(), SEED_SPACING_POINTS)
            .into_iter()
            .filter(|&k| !field.is_masked(k))
            .collect();
        let mut guess = Guess::Translation(offset);
        let mut seed_results =
            self.solve_all(&seeds, |k, scratch| self.solve_seed(k, &guess, scratch));
        let held = |results: &[PoiResult]| results.iter().filter(|r| r.status.is_valid()).count();
        if 2 * held(&seed_results) < seeds.len() {
            if let Some(sim) = estimate_similarity(
                &r.image,
                self.deformed,
                r.grid.roi,
                offset,
                r.settings.max_motion_px,
            ) {
                guess = Guess::Similarity(sim);
                let again: Vec<usize> = (0..seeds.len())
                    .filter(|&i| !seed_results[i].status.is_valid())
                    .collect();
                let ks: Vec<usize> = again.iter().map(|&i| seeds[i]).collect();
                let retried = self.solve_all(&ks, |k, scratch| self.solve_seed(k, &guess, scratch));
                for (i, r) in again.into_iter().zip(retried) {
                    seed_results[i] = r;
                }
            }
        }
        let best_seed = seed_results
            .iter()
            .filter(|r| r.status.is_valid())
            .map(|r| r.zncc)
            .fold(f64::NEG_INFINITY, f64::max);
        for (&k, r) in seeds.iter().zip(seed_results) {
            let guides = r.status.is_valid() && r.zncc >= best_seed - SEED_ZNCC_MARGIN;
            field.record(k, r, guides);
        }
        guess
    }

    /// Steps 2 and 3: propagation from the guides, then a search where it did not reach, for at
    /// most `SEARCH_ROUNDS` rounds or until a round gains nothing.
    fn propagate_and_search(&self, field: &mut Field, guess: &Guess, report: &dyn Fn(&Field)) {
        let r = self.reference;
        for _ in 0..SEARCH_ROUNDS {
            loop {
                let tasks = field.frontier(&r.grid.xs, &r.grid.ys);
                if tasks.is_empty() || self.watch.is_cancelled() {
                    break;
                }
                let results = self.solve_tasks(&tasks, |t, scratch| {
                    self.solve_from(t.index, t.start, scratch)
                });
                for (t, r) in tasks.iter().zip(results) {
                    let valid = r.status.is_valid();
                    field.record_task(t, r, valid);
                }
                report(field);
            }
            let unresolved = field.unresolved();
            if unresolved.is_empty() || self.watch.is_cancelled() {
                break;
            }
            let nearest = field.nearest_valid();
            let predictions: Vec<Warp> = unresolved
                .iter()
                .map(|&k| match nearest[k] {
                    Some(n) => {
                        let from = field.result(n).expect("a valid point has a result");
                        let (x, y) = r.position(k);
                        warp_of(from).moved_by(x - from.x, y - from.y)
                    }
                    None => {
                        let (x, y) = r.position(k);
                        guess.warp_at(x, y)
                    }
                })
                .collect();
            let jobs: Vec<(usize, Warp)> = unresolved.into_iter().zip(predictions).collect();
            let results = self.solve_tasks(&jobs, |&(k, p), scratch| {
                self.solve_searching(k, p, scratch)
            });
            let mut gained = 0;
            for (&(k, _), r) in jobs.iter().zip(results) {
                let valid = r.status.is_valid();
                gained += valid as usize;
                field.record(k, r, valid);
            }
            report(field);
            if gained == 0 {
                break;
            }
        }
    }

    /// Step 4, the field's verdict: points with too little texture for the noise, a correlation
    /// far below the field's, or failing the neighbour (median) test after one retry from an
    /// agreeing neighbour are rejected.
    fn judge(&self, points: &mut [PoiResult]) {
        let (s, r) = (&self.reference.settings, self.reference);
        let (nx, ny) = (r.grid.nx(), r.grid.ny());
        let side = s.subset_px;
        if let Some(noise) = noise_std(points, &r.subset_std, side * side) {
            for (p, &sd) in points.iter_mut().zip(&r.subset_std) {
                let judged = !matches!(
                    p.status,
                    PoiStatus::Masked | PoiStatus::LeftImage | PoiStatus::NoContrast
                );
                if judged && sd < MIN_TEXTURE_TO_NOISE * noise {
                    *p = p.rejected(PoiStatus::NoTexture);
                }
            }
        }
        if let Some(ratio) = s.max_znssd_ratio {
            for k in relative_correlation_failures(points, ratio) {
                points[k] = points[k].rejected(PoiStatus::LowCorrelation);
            }
        }
        if let Some(threshold) = s.outlier_threshold {
            let failures = median_test_failures(points, nx, ny, threshold);
            let starts: Vec<(usize, Warp)> = failures
                .iter()
                .filter_map(|&k| r.agreeing_neighbour_start(points, k).map(|w| (k, w)))
                .collect();
            let retried =
                self.solve_tasks(&starts, |&(k, w), scratch| self.solve_from(k, w, scratch));
            for (&(k, _), r) in starts.iter().zip(retried) {
                points[k] = r;
            }
            for k in median_test_failures(points, nx, ny, threshold) {
                points[k] = points[k].rejected(PoiStatus::Outlier);
            }
        }
    }

    /// Solves every item in parallel, in order, with one scratch buffer per worker.
    fn solve_tasks<T: Sync>(
        &self,
        items: &[T],
        solve: impl Fn(&T, &mut Scratch) -> PoiResult + Sync,
    ) -> Vec<PoiResult> {
        let half = self.reference.settings.half_subset();
        items
            .par_iter()
            .map_init(
                || Scratch::new(half),
                |scratch, item| {
                    if self.watch.is_cancelled() {
                        // Never read: a cancelled correlation returns no field.
                        PoiResult::invalid(f64::NAN, f64::NAN, PoiStatus::NoContrast, f64::NAN, 0)
                    } else {
                        solve(item, scratch)
                    }
                },
            )
            .collect()
    }

    fn solve_all(
        &self,
        points: &[usize],
        solve: impl Fn(usize, &mut Scratch) -> PoiResult + Sync,
    ) -> Vec<PoiResult> {
        self.solve_tasks(points, |&k, scratch| solve(k, scratch))
    }

    /// Loads the reference subset of point k; Err with the finished result when it has none.
    fn subset(&self, k: usize, scratch: &mut Scratch) -> Result<SubsetReference, PoiResult> {
        let r = self.reference;
        let (x, y) = r.position(k);
        SubsetReference::prepare(
            &r.image,
            &r.grad_x,
            &r.grad_y,
            (x as usize, y as usize),
            r.settings.half_subset(),
            scratch,
        )
        .ok_or_else(|| PoiResult::invalid(x, y, PoiStatus::NoContrast, f64::NAN, 0))
    }

    /// IC-GN from `start`, judged on the point's own evidence.
    fn solve_from(&self, k: usize, start: Warp, scratch: &mut Scratch) -> PoiResult {
        match self.subset(k, scratch) {
            Ok(sref) => self.icgn(k, &sref, start, scratch),
            Err(done) => done,
        }
    }

    fn icgn(
        &self,
        k: usize,
        sref: &SubsetReference,
        start: Warp,
        scratch: &mut Scratch,
    ) -> PoiResult {
        let s = &self.reference.settings;
        let (x, y) = self.reference.position(k);
        let (w, zncc, iterations, status, (u_std_px, v_std_px)) = match s.shape {
            ShapeFunction::Affine => {
                let o = sref.solve(
                    &self.spline,
                    start,
                    s.convergence_px,
                    s.max_iterations,
                    scratch,
                );
                let std = if o.residual_ss.is_finite() {
                    sref.displacement_std(o.residual_ss)
                } else {
                    (f64::NAN, f64::NAN)
                };
                (o.warp, o.zncc, o.iterations, o.status, std)
            }
            ShapeFunction::Quadratic => {
                let solve = QuadraticSolve {
                    deformed: &self.spline,
                    centre: (sref.x0, sref.y0),
                    half: sref.half,
                    df: sref.df,
                };
                let o = solve.run(
                    QuadraticWarp::from_affine(&start),
                    s.convergence_px,
                    s.max_iterations,
                    scratch,
                );
                (o.warp.affine(), o.zncc, o.iterations, o.status, o.std_px)
            }
        };
        let mut p = PoiResult {
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
            zncc,
            u_std_px,
            v_std_px,
            iterations,
            status,
        };
        p.status = own_status(&p, s);
        if p.status.is_valid() {
            p
        } else {
            p.rejected(p.status)
        }
    }

    /// An integer ZNCC search around `predicted`, then IC-GN with the predicted gradients.
    fn solve_searching(&self, k: usize, predicted: Warp, scratch: &mut Scratch) -> PoiResult {
        let s = &self.reference.settings;
        let sref = match self.subset(k, scratch) {
            Ok(sref) => sref,
            Err(done) => return done,
        };
        let centre = (predicted.u.round() as i64, predicted.v.round() as i64);
        let Some(best) = integer_search(
            &scratch.f0,
            sref.df,
            self.deformed,
            (sref.x0, sref.y0),
            sref.half,
            centre,
            s.search_radius_px as i64,
        ) else {
            let (x, y) = self.reference.position(k);
            return PoiResult::invalid(x, y, PoiStatus::LeftImage, f64::NAN, 0);
        };
        let start = Warp {
            u: best.u as f64,
            v: best.v as f64,
            ..predicted
        };
        self.icgn(k, &sref, start, scratch)
    }

    /// A seed: from the guess directly when it carries a shape, else (or when that fails) from
    /// an integer search around it.
    fn solve_seed(&self, k: usize, guess: &Guess, scratch: &mut Scratch) -> PoiResult {
        let (x, y) = self.reference.position(k);
        let predicted = guess.warp_at(x, y);
        if let Guess::Similarity(_) = guess {
            let direct = self.solve_from(k, predicted, scratch);
            if direct.status.is_valid() || direct.status == PoiStatus::NoContrast {
                return direct;
            }
        }
        self.solve_searching(k, predicted, scratch)
    }
}

/// Grey-level standard deviation of every grid point's subset, from column sums per grid row.
fn subset_stds(image: &Image, grid: &PoiGrid, half: usize) -> Vec<f64> {
    let side = 2 * half + 1;
    let n = (side * side) as f64;
    // Only the columns some subset covers.
    let (Some(&x_first), Some(&x_last)) = (grid.xs.first(), grid.xs.last()) else {
        return Vec::new();
    };
    let (c0, c1) = (x_first - half, x_last + half + 1);
    // Per grid row: column sums of v and v² over the subset's rows, then their running sums
    // along x, differenced at each point (f64 throughout; grid rows in parallel).
    grid.ys
        .par_iter()
        .flat_map_iter(|&y| {
            let mut col = vec![[0.0f64; 2]; c1 - c0];
            for r in y - half..=y + half {
                for (acc, &v) in col.iter_mut().zip(&image.row(r)[c0..c1]) {
                    let v = v as f64;
                    acc[0] += v;
                    acc[1] += v * v;
                }
            }
            let mut running = Vec::with_capacity(col.len() + 1);
            running.push([0.0f64; 2]);
            let mut total = [0.0f64; 2];
            for c in &col {
                total = [total[0] + c[0], total[1] + c[1]];
                running.push(total);
            }
            grid.xs
                .iter()
                .map(|&x| {
                    let (a, b) = (running[x - half - c0], running[x + half + 1 - c0]);
                    let mean = (b[0] - a[0]) / n;
                    ((b[1] - a[1]) / n - mean * mean).max(0.0).sqrt()
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Prepares the reference and correlates one deformed image: the whole analysis of one pair.
pub fn analyze<'r, 'd>(
    reference: impl Into<ImageView<'r>>,
    deformed: impl Into<ImageView<'d>>,
    settings: &DicSettings,
    progress: Option<Progress<'_>>,
) -> Result<DicResult, DicError> {
    PreparedReference::new(reference, settings)?.correlate(deformed, progress)
}
