//! Strain by pointwise least squares: a plane u = a + b·x + c·y (and likewise v) is fitted to the
//! displacements of the N x N neighbouring POIs around each point, after Pan, Xie, Guo & Hua,
//! "Full-field strain measurement using a two-dimensional Savitzky-Golay digital differentiator
//! in digital image correlation", Opt. Eng. 46 (2007). Small strain: exx = ∂u/∂x, eyy = ∂v/∂y,
//! exy = ½(∂u/∂y + ∂v/∂x). Windows are truncated at the grid border and skip invalid points; a
//! point keeps NaN strains when fewer than 6 neighbours remain or they are collinear.

use super::{PoiGrid, PoiResult};

const MIN_POINTS: usize = 6;

/// Fills exx, eyy, exy of every valid point from its strain window.
pub fn compute_strains(grid: &PoiGrid, points: &mut [PoiResult], window: usize) {
    let (nx, ny) = (grid.nx(), grid.ny());
    let half = (window / 2) as isize;
    let mut strains = vec![(f64::NAN, f64::NAN, f64::NAN); points.len()];
    for j in 0..ny {
        for i in 0..nx {
            let centre = &points[j * nx + i];
            if !centre.status.is_valid() {
                continue;
            }
            let mut fit_u = PlaneFit::default();
            let mut fit_v = PlaneFit::default();
            for jj in (j as isize - half).max(0)..=(j as isize + half).min(ny as isize - 1) {
                for ii in (i as isize - half).max(0)..=(i as isize + half).min(nx as isize - 1) {
                    let p = &points[jj as usize * nx + ii as usize];
                    if !p.status.is_valid() {
                        continue;
                    }
                    let (dx, dy) = (p.x - centre.x, p.y - centre.y);
                    fit_u.add(dx, dy, p.u);
                    fit_v.add(dx, dy, p.v);
                }
            }
            if let (Some((dudx, dudy)), Some((dvdx, dvdy))) = (fit_u.slopes(), fit_v.slopes()) {
                strains[j * nx + i] = (dudx, dvdy, 0.5 * (dudy + dvdx));
            }
        }
    }
    for (p, (exx, eyy, exy)) in points.iter_mut().zip(strains) {
        p.exx = exx;
        p.eyy = eyy;
        p.exy = exy;
    }
}

/// Normal equations of the least-squares plane z = a + b·x + c·y.
#[derive(Default)]
struct PlaneFit {
    n: usize,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    sz: f64,
    sxz: f64,
    syz: f64,
}

impl PlaneFit {
    fn add(&mut self, x: f64, y: f64, z: f64) {
        self.n += 1;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.sxy += x * y;
        self.syy += y * y;
        self.sz += z;
        self.sxz += x * z;
        self.syz += y * z;
    }

    /// (b, c), or None when the points do not determine a plane.
    fn slopes(&self) -> Option<(f64, f64)> {
        if self.n < MIN_POINTS {
            return None;
        }
        let n = self.n as f64;
        // Centre the sums so the 2x2 system is well conditioned.
        let cxx = self.sxx - self.sx * self.sx / n;
        let cxy = self.sxy - self.sx * self.sy / n;
        let cyy = self.syy - self.sy * self.sy / n;
        let cxz = self.sxz - self.sx * self.sz / n;
        let cyz = self.syz - self.sy * self.sz / n;
        let det = cxx * cyy - cxy * cxy;
        if det <= 1e-9 * (cxx * cyy).max(f64::MIN_POSITIVE) {
            return None;
        }
        Some(((cyy * cxz - cxy * cyz) / det, (cxx * cyz - cxy * cxz) / det))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dic::{DicSettings, PoiStatus};

    #[test]
    fn linear_field_gives_exact_strain_everywhere_including_borders() {
        let s = DicSettings::default();
        let grid = PoiGrid::new(&s, 512, 512).unwrap();
        let mut pts = Vec::new();
        for &y in &grid.ys {
            for &x in &grid.xs {
                let (x, y) = (x as f64, y as f64);
                let mut p = PoiResult::invalid(x, y, PoiStatus::Converged, 1.0, 1);
                p.u = 1.0 + 0.002 * x + 0.001 * y;
                p.v = -2.0 + 0.003 * x - 0.004 * y;
                pts.push(p);
            }
        }
        pts[5].status = PoiStatus::NotConverged;
        compute_strains(&grid, &mut pts, 7);
        for (k, p) in pts.iter().enumerate() {
            if k == 5 {
                assert!(p.exx.is_nan());
                continue;
            }
            assert!((p.exx - 0.002).abs() < 1e-10);
            assert!((p.eyy + 0.004).abs() < 1e-10);
            assert!((p.exy - 0.002).abs() < 1e-10);
        }
    }
}
