//! Reliability-guided propagation over the grid (Pan, "Reliability-guided digital image
//! correlation for image deformation measurement", Appl. Opt. 48 (2009); Blaber, Adair &
//! Antoniou, "Ncorr: open-source 2D digital image correlation Matlab software", Exp. Mech. 55
//! (2015)): a point is started from the full first-order shape of its best-correlated valid
//! neighbour, moved to its own centre, so the guess follows rotation, strain and gradients
//! instead of one global offset.
//!
//! Pan's scheme is sequential (a priority queue on ZNCC). Here it runs in waves: every pending
//! point next to a valid one is solved in the same wave, in parallel, from the neighbour with
//! the highest ZNCC it has not yet been started from. The waves depend only on the state at
//! their start, so the result is the same for any number of threads. A point that fails from
//! one neighbour is tried from another (at most [`MAX_ATTEMPTS`] times).

use super::{PoiResult, PoiStatus, Warp};

/// Starts per point from different neighbours before propagation gives up on it.
pub const MAX_ATTEMPTS: u8 = 3;

/// The 8-neighbourhood as (di, dj) grid steps.
const NEIGHBOURS: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// The state of every grid point during one correlation.
pub struct Field {
    pub nx: usize,
    pub ny: usize,
    /// The latest outcome of each point (None: not attempted yet, or masked).
    results: Vec<Option<PoiResult>>,
    valid: Vec<bool>,
    masked: Vec<bool>,
    /// Which neighbours (bit per direction of [`NEIGHBOURS`]) a point was started from.
    tried: Vec<u8>,
    attempts: Vec<u8>,
}

/// A point to solve and the start its neighbour gives it.
#[derive(Clone, Copy, Debug)]
pub struct Task {
    pub index: usize,
    pub start: Warp,
    /// Direction bit of the neighbour the start came from.
    direction: u8,
}

impl Field {
    pub fn new(nx: usize, ny: usize, analysed: &[bool]) -> Self {
        let n = nx * ny;
        Self {
            nx,
            ny,
            results: vec![None; n],
            valid: vec![false; n],
            masked: analysed.iter().map(|a| !a).collect(),
            tried: vec![0; n],
            attempts: vec![0; n],
        }
    }

    pub fn is_masked(&self, k: usize) -> bool {
        self.masked[k]
    }

    /// Records an outcome; `valid` says whether it may guide its neighbours.
    pub fn record(&mut self, k: usize, result: PoiResult, valid: bool) {
        self.results[k] = Some(result);
        self.valid[k] = valid;
        self.attempts[k] = self.attempts[k].saturating_add(1);
    }

    /// Records the outcome of a propagation task.
    pub fn record_task(&mut self, task: &Task, result: PoiResult, valid: bool) {
        self.tried[task.index] |= 1 << task.direction;
        self.record(task.index, result, valid);
    }

    /// The next wave: every pending point with a valid neighbour it was not yet started from,
    /// each with the start of its best such neighbour (highest ZNCC).
    pub fn frontier(&self, xs: &[usize], ys: &[usize]) -> Vec<Task> {
        let mut tasks = Vec::new();
        for j in 0..self.ny {
            for i in 0..self.nx {
                let k = j * self.nx + i;
                if self.valid[k] || self.masked[k] || self.attempts[k] >= MAX_ATTEMPTS {
                    continue;
                }
                let mut best: Option<(f64, usize, u8)> = None;
                for (d, (di, dj)) in NEIGHBOURS.iter().enumerate() {
                    if self.tried[k] & (1 << d) != 0 {
                        continue;
                    }
                    let (ii, jj) = (i as isize + di, j as isize + dj);
                    if ii < 0 || jj < 0 || ii >= self.nx as isize || jj >= self.ny as isize {
                        continue;
                    }
                    let n = jj as usize * self.nx + ii as usize;
                    if !self.valid[n] {
                        continue;
                    }
                    let zncc = self.results[n].map_or(f64::NEG_INFINITY, |r| r.zncc);
                    if best.is_none_or(|(z, _, _)| zncc > z) {
                        best = Some((zncc, n, d as u8));
                    }
                }
                if let Some((_, n, direction)) = best {
                    let from = self.results[n].expect("a valid point has a result");
                    let (dx, dy) = (
                        xs[i] as f64 - xs[n % self.nx] as f64,
                        ys[j] as f64 - ys[n / self.nx] as f64,
                    );
                    tasks.push(Task {
                        index: k,
                        start: warp_of(&from).moved_by(dx, dy),
                        direction,
                    });
                }
            }
        }
        tasks
    }

    /// Points neither valid nor masked.
    pub fn unresolved(&self) -> Vec<usize> {
        (0..self.results.len())
            .filter(|&k| !self.valid[k] && !self.masked[k])
            .collect()
    }

    /// For every point, the nearest valid point (8-connected grid distance, ties to the lower
    /// index), or None when no point is valid.
    pub fn nearest_valid(&self) -> Vec<Option<usize>> {
        let n = self.results.len();
        let mut nearest: Vec<Option<usize>> = (0..n)
            .map(|k| if self.valid[k] { Some(k) } else { None })
            .collect();
        let mut queue: std::collections::VecDeque<usize> =
            (0..n).filter(|&k| self.valid[k]).collect();
        while let Some(k) = queue.pop_front() {
            let (i, j) = ((k % self.nx) as isize, (k / self.nx) as isize);
            for (di, dj) in NEIGHBOURS {
                let (ii, jj) = (i + di, j + dj);
                if ii < 0 || jj < 0 || ii >= self.nx as isize || jj >= self.ny as isize {
                    continue;
                }
                let m = jj as usize * self.nx + ii as usize;
                if nearest[m].is_none() {
                    nearest[m] = nearest[k];
                    queue.push_back(m);
                }
            }
        }
        nearest
    }

    pub fn result(&self, k: usize) -> Option<&PoiResult> {
        self.results[k].as_ref()
    }

    /// The points, row-major; masked points get the `masked` status.
    pub fn into_points(self, xs: &[usize], ys: &[usize]) -> Vec<PoiResult> {
        let nx = self.nx;
        self.results
            .into_iter()
            .enumerate()
            .map(|(k, r)| {
                let (x, y) = (xs[k % nx] as f64, ys[k / nx] as f64);
                match r {
                    Some(r) if !self.masked[k] => r,
                    _ => {
                        let status = if self.masked[k] {
                            PoiStatus::Masked
                        } else {
                            PoiStatus::NotConverged
                        };
                        PoiResult::invalid(x, y, status, f64::NAN, 0)
                    }
                }
            })
            .collect()
    }
}

/// The first-order shape a point converged to.
pub fn warp_of(p: &PoiResult) -> Warp {
    Warp {
        u: p.u,
        ux: p.du_dx,
        uy: p.du_dy,
        v: p.v,
        vx: p.dv_dx,
        vy: p.dv_dy,
    }
}

/// Seed points: a lattice every `spacing` grid points, centred, at least one per axis.
pub fn seed_indices(nx: usize, ny: usize, spacing: usize) -> Vec<usize> {
    let axis = |n: usize| -> Vec<usize> {
        let count = n.div_ceil(spacing).max(1);
        let first = (n - 1 - (count - 1) * spacing.min(n - 1)) / 2;
        (0..count)
            .map(|c| (first + c * spacing).min(n - 1))
            .collect()
    };
    let (cols, rows) = (axis(nx), axis(ny));
    let mut out = Vec::with_capacity(cols.len() * rows.len());
    for &j in &rows {
        for &i in &cols {
            out.push(j * nx + i);
        }
    }
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_spread_and_inside() {
        let s = seed_indices(161, 161, 16);
        assert_eq!(s.len(), 11 * 11);
        assert!(s.iter().all(|&k| k < 161 * 161));
        assert_eq!(seed_indices(1, 1, 16), vec![0]);
        let small = seed_indices(5, 3, 16);
        assert_eq!(small, vec![5 + 2]);
    }

    #[test]
    fn frontier_starts_from_the_best_neighbour_and_moves_its_shape() {
        let (xs, ys) = (vec![0, 10, 20], vec![0, 10, 20]);
        let mut f = Field::new(3, 3, &[true; 9]);
        let mut a = PoiResult::invalid(10.0, 10.0, PoiStatus::Converged, 0.9, 2);
        (a.u, a.du_dx, a.du_dy, a.v, a.dv_dx, a.dv_dy) = (1.0, 0.1, 0.0, 0.0, 0.0, 0.0);
        f.record(4, a, true);
        let tasks = f.frontier(&xs, &ys);
        assert_eq!(tasks.len(), 8);
        let right = tasks.iter().find(|t| t.index == 5).unwrap();
        assert!((right.start.u - 2.0).abs() < 1e-12);
        let nearest = f.nearest_valid();
        assert!(nearest.iter().all(|n| *n == Some(4)));
    }
}
