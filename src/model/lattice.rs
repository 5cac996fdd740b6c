//! Dots on a lattice — one per cell of the spacing grid, placed anywhere in it (the jittered
//! grid) or in a cell drawn too (Poisson) — with the uniform draw each dot's depth is made from,
//! remembered: a print's calibration renders its reference crop some fifty times with the same
//! seed, field and spacing (its contrast and size are searched, not where its dots sit), and
//! drawing the layout again for every crop was 6–8 % of a diagnosis round (`perf`, 2026-11-29).
//! The hard core's layouts are remembered the same way (`remembered.rs`).

use super::pattern::Placement;
use super::remembered::Remembered;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

/// One dot: its centre (x, y), mm, and the uniform draw in [0, 1) its depth is made from.
pub(super) type LatticeDot = (f64, f64, f64);

/// A layout's inputs (the placement, the field's and the spacing's bits, the seed) and the
/// layout: the last eight (a diagnosis calibrates up to three prints side by side, each under
/// up to three placements).
static LAYOUTS: Remembered<(Placement, [u64; 5], u64), Arc<Vec<LatticeDot>>> = Remembered::new(8);

/// [`lattice`], remembering the last few layouts.
pub(super) fn lattice_remembered(
    placement: Placement,
    field: (f64, f64, f64, f64),
    spacing_mm: f64,
    seed: u64,
) -> Arc<Vec<LatticeDot>> {
    let (x0, y0, x1, y1) = field;
    let key = (
        placement,
        [x0, y0, x1, y1, spacing_mm].map(f64::to_bits),
        seed,
    );
    LAYOUTS.get_or(key, || {
        Arc::new(lattice(placement, field, spacing_mm, seed))
    })
}

/// The lattice's dots, reproducible from `seed`: per cell in row order, a Poisson dot's cell
/// (two draws), then its place in the cell (two) and its depth's draw (one).
fn lattice(
    placement: Placement,
    (x0, y0, x1, y1): (f64, f64, f64, f64),
    s: f64,
    seed: u64,
) -> Vec<LatticeDot> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let nx = ((x1 - x0) / s).ceil() as usize;
    let ny = ((y1 - y0) / s).ceil() as usize;
    let mut dots = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            // The jittered grid keeps the cell; Poisson draws the cell too (the same count and
            // the same stream of draws, so the two layouts differ only in placement).
            let (ci, cj) = match placement {
                Placement::JitteredGrid => (i as f64, j as f64),
                Placement::Poisson => (
                    (rng.gen::<f64>() * nx as f64).floor(),
                    (rng.gen::<f64>() * ny as f64).floor(),
                ),
                Placement::HardCore => unreachable!("a hard core is laid out by hard_core.rs"),
            };
            let x = x0 + (ci + rng.gen::<f64>()) * s;
            let y = y0 + (cj + rng.gen::<f64>()) * s;
            dots.push((x, y, rng.gen::<f64>()));
        }
    }
    dots
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A remembered layout is the one drawn, whichever was asked for in between.
    #[test]
    fn a_remembered_layout_is_the_one_drawn() {
        let field = (-3.0, -2.0, 4.0, 5.0);
        for (placement, seed) in [
            (Placement::JitteredGrid, 5),
            (Placement::Poisson, 5),
            (Placement::JitteredGrid, 6),
            (Placement::JitteredGrid, 5),
            (Placement::Poisson, 5),
        ] {
            let fresh = lattice(placement, field, 0.3, seed);
            assert_eq!(*lattice_remembered(placement, field, 0.3, seed), fresh);
            assert_eq!(fresh.len(), 24 * 24);
        }
        assert_ne!(
            lattice(Placement::Poisson, field, 0.3, 5),
            lattice(Placement::JitteredGrid, field, 0.3, 5)
        );
    }
}
