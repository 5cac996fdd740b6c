//! Dot centres that keep a minimum distance: random sequential adsorption (Widom 1966; Feder,
//! J. Theor. Biol. 87 (1980)). Centres are drawn uniformly and kept when no kept centre lies
//! within the distance, until the count is reached. Its jamming limit covers 54.7 % of the plane
//! with disks of that diameter; a print at or near it would take unbounded draws, so a centre
//! that finds no room in [`ATTEMPTS`] draws is placed at its last draw regardless (the count and
//! so the print's density are kept; the layout only loses its hard core locally).

use super::remembered::Remembered;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

/// Draws per centre before it is placed regardless.
const ATTEMPTS: usize = 64;

/// A layout's inputs: the generator's state, the field's and the distance's bits, the count.
type LayoutKey = (ChaCha8Rng, [u64; 5], usize);
/// A layout, and the generator's state after it.
type Layout = (Arc<Vec<(f64, f64)>>, ChaCha8Rng);

/// The last eight layouts.
static LAYOUTS: Remembered<LayoutKey, Layout> = Remembered::new(8);

/// [`hard_core_centres`], remembering the last few layouts: a print's calibration renders its
/// reference crop some fifty times with the same centres (its contrast and edge are searched, not
/// its spacing), and drawing them again was 6 % of a diagnosis round. `rng` is left as the
/// layout left it, remembered or not.
pub(super) fn hard_core_centres_remembered(
    rng: &mut ChaCha8Rng,
    field: (f64, f64, f64, f64),
    n: usize,
    min_distance_mm: f64,
) -> Arc<Vec<(f64, f64)>> {
    let (x0, y0, x1, y1) = field;
    let key = (
        rng.clone(),
        [x0, y0, x1, y1, min_distance_mm].map(f64::to_bits),
        n,
    );
    let (centres, after) = LAYOUTS.get_or(key, || {
        let centres = Arc::new(hard_core_centres(rng, field, n, min_distance_mm));
        (centres, rng.clone())
    });
    *rng = after;
    centres
}

/// The centres kept so far, by cell of side d: a centre's neighbours within d lie in the 3x3
/// cells about its own. Each cell holds its centres' coordinates in place (up to
/// [`CELL_SLOTS`]; only a centre placed regardless can crowd one beyond, into `crowded`), and
/// the grid has a border of empty cells, so a check reads nine runs of memory with no bounds
/// test: the check of a draw was a tenth of a paper-size diagnosis round when each cell held
/// indices into the list of centres.
struct Cells {
    /// Cells per row, the border included: cell (c, r) of the grid is at (r + 1)·stride + c + 1.
    stride: usize,
    counts: Vec<u8>,
    slots: Vec<[(f64, f64); CELL_SLOTS]>,
    /// The centres beyond a cell's slots, by cell.
    crowded: Vec<(usize, (f64, f64))>,
}

/// Centres at least d apart fit at most four in a square of side d (its corners).
const CELL_SLOTS: usize = 4;

impl Cells {
    fn new(cols: usize, rows: usize) -> Self {
        let n = (cols + 2) * (rows + 2);
        Cells {
            stride: cols + 2,
            counts: vec![0; n],
            slots: vec![[(0.0, 0.0); CELL_SLOTS]; n],
            crowded: Vec::new(),
        }
    }

    fn push(&mut self, cell: usize, at: (f64, f64)) {
        let k = usize::from(self.counts[cell]);
        if k < CELL_SLOTS {
            self.slots[cell][k] = at;
        } else {
            self.crowded.push((cell, at));
        }
        self.counts[cell] = self.counts[cell].saturating_add(1);
    }

    /// Whether no centre within the 3x3 cells about `cell` lies closer to `at` than √`d2`. The
    /// draw's own cell first, then its sides, then its corners: near the jamming limit most
    /// draws are refused, and a refusal is most likely found nearest.
    fn free(&self, cell: usize, at: (f64, f64), d2: f64) -> bool {
        let s = self.stride as isize;
        [0, -1, 1, -s, s, -s - 1, -s + 1, s - 1, s + 1]
            .iter()
            .all(|&offset| {
                let k = cell.wrapping_add_signed(offset);
                let n = usize::from(self.counts[k]);
                // Squared: hypot's care for overflow cost a tenth of a render.
                let clear = |&(x, y): &(f64, f64)| (x - at.0).powi(2) + (y - at.1).powi(2) >= d2;
                self.slots[k][..n.min(CELL_SLOTS)].iter().all(clear)
                    && (n <= CELL_SLOTS
                        || self
                            .crowded
                            .iter()
                            .filter(|(c, _)| *c == k)
                            .all(|(_, p)| clear(p)))
            })
    }
}

/// `n` centres in the rectangle [x0, x1] x [y0, y1] (mm), none closer than `min_distance_mm`
/// to an earlier one where room was found.
fn hard_core_centres(
    rng: &mut ChaCha8Rng,
    (x0, y0, x1, y1): (f64, f64, f64, f64),
    n: usize,
    min_distance_mm: f64,
) -> Vec<(f64, f64)> {
    let d = min_distance_mm.max(1e-9);
    let d2 = d * d;
    let cols = (((x1 - x0) / d).ceil() as usize).max(1);
    let rows = (((y1 - y0) / d).ceil() as usize).max(1);
    let mut cells = Cells::new(cols, rows);
    let cell_of = |x: f64, y: f64| {
        let c = (((x - x0) / d) as usize).min(cols - 1);
        let r = (((y - y0) / d) as usize).min(rows - 1);
        (r + 1) * (cols + 2) + c + 1
    };
    let mut centres: Vec<(f64, f64)> = Vec::with_capacity(n);
    for _ in 0..n {
        let mut at = (x0, y0);
        for _ in 0..ATTEMPTS {
            at = (
                x0 + rng.gen::<f64>() * (x1 - x0),
                y0 + rng.gen::<f64>() * (y1 - y0),
            );
            if cells.free(cell_of(at.0, at.1), at, d2) {
                break;
            }
        }
        let cell = cell_of(at.0, at.1);
        cells.push(cell, at);
        centres.push(at);
    }
    centres
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// A remembered layout is the layout drawn again, and leaves the generator where drawing it
    /// would: the same centres and the same draws after, whether remembered or not.
    #[test]
    fn a_remembered_layout_is_the_one_drawn() {
        let field = (0.0, 0.0, 6.0, 5.0);
        let fresh = |seed| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let c = hard_core_centres(&mut rng, field, 200, 0.2);
            (c, rng.gen::<u64>())
        };
        let remembered = |seed| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let c = hard_core_centres_remembered(&mut rng, field, 200, 0.2);
            (c.to_vec(), rng.gen::<u64>())
        };
        for seed in [11, 12, 11, 12, 11] {
            assert_eq!(remembered(seed), fresh(seed), "seed {seed}");
        }
        assert_ne!(fresh(11), fresh(12));
    }

    /// At a third of the plane covered (print b of the paper: 0.24 mm dots at 0.36 mm), every
    /// centre finds room: no two closer than the distance, all inside, the count kept.
    #[test]
    fn no_two_centres_are_closer_than_the_distance() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let field = (0.0, 0.0, 12.0, 9.0);
        let n = ((12.0 / 0.36f64).ceil() * (9.0 / 0.36f64).ceil()) as usize;
        let c = hard_core_centres(&mut rng, field, n, 0.24);
        assert_eq!(c.len(), n);
        for (i, a) in c.iter().enumerate() {
            assert!(a.0 >= 0.0 && a.0 <= 12.0 && a.1 >= 0.0 && a.1 <= 9.0);
            for b in &c[..i] {
                assert!((a.0 - b.0).hypot(a.1 - b.1) >= 0.24, "{a:?} {b:?}");
            }
        }
    }
}
