//! Fill-factor synthesis (Hijazi, Rawashdeh & Kähler, "Fill Factor Modification"): a full-
//! resolution frame becomes a lower-resolution one whose pixels see only part of their area.
//!
//! Per axis, a block of `block` sensor pixels of which `active` consecutive ones starting at
//! `first` are light sensitive: they are averaged, the others dropped. The paper's presets:
//!
//! | preset | x (block/first/active) | y | linear fill x × y | reduced pixel 0 centre (full-res px) |
//! |---|---|---|---|---|
//! | `ff100` | 2/0/2 | 2/0/2 | 100 % × 100 % | (0.5, 0.5) |
//! | `ff50`  | 2/0/1 | 2/0/2 | 50 % × 100 %  | (0.0, 0.5) |
//! | `ff25`  | 2/0/1 | 2/0/1 | 50 % × 50 %   | (0.0, 0.0) |
//!
//! The paper's MATLAB code "deletes even columns" in 1-based terms, i.e. keeps 0-based columns
//! 0, 2, 4, …: `first = 0`. Reduced pixel i covers full-resolution pixels
//! `i·block + first .. i·block + first + active`, so its centre lies at
//! `X_full = block·X_red + first + (active − 1)/2` (origin at the centre of the top-left pixel):
//! binning and subsampling differ by half a full-resolution pixel, which matters wherever
//! positions are compared, never for a displacement (`u_red = u_full / block`).

mod apply;
mod scheme;

pub use apply::{reduce, reduce_u16};
pub use scheme::{AxisScheme, ReduceError, Scheme, MAX_BLOCK_PX};
