//! Analyses this process has already made, keyed by what they read: the two frames' content, how
//! the run was read out, the scheme and the DIC settings.
//!
//! Why: one process often correlates the same pairs twice. `ffdic reproduce` runs the study on
//! the frames it captured and then the diagnosis's measured side on the same frames, schemes and
//! settings; a daemon diagnoses a dataset it compared or studied a moment before. The second
//! analysis is the first one's result: remembered, it skips the pair's correlation and, when
//! every scheme of a reference is remembered, the reference's preparation (issue 37: reuse what
//! does not change, the measured side among it).
//!
//! The key is content, not a file's name or time: a frame written again with other pixels is a
//! new key, whatever its path. The memory is bounded ([`BUDGET_BYTES`]) and forgets the oldest
//! analyses first.

use crate::dic::{DicResult, DicSettings};
use crate::image::Image;
use crate::reduce::Scheme;
use sha2::{Digest, Sha256};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, OnceLock};

/// What the remembered analyses may hold in all: some twenty paper-size analyses at the paper's
/// step (≈ 30,000 points of ≈ 130 bytes each, 4 MB an analysis), ten times what `reproduce`
/// makes twice (nine), while a daemon's frames and jobs take hundreds of megabytes.
pub const BUDGET_BYTES: usize = 64 << 20;

/// A frame's content: SHA-256 of its size and pixels (the pixels as the analysis reads them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameDigest([u8; 32]);

impl FrameDigest {
    pub fn of(image: &Image) -> Self {
        let mut hash = Sha256::new();
        hash.update((image.width() as u64).to_le_bytes());
        hash.update((image.height() as u64).to_le_bytes());
        // The pixels' own bytes, in order: f32 to little-endian bytes, a chunk at a time.
        let mut bytes = Vec::with_capacity(4 * 4096);
        for chunk in image.data().chunks(4096) {
            bytes.clear();
            bytes.extend(chunk.iter().flat_map(|v| v.to_le_bytes()));
            hash.update(&bytes);
        }
        Self(hash.finalize().into())
    }
}

/// One analysis's inputs, digested.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AnalysisKey([u8; 32]);

impl AnalysisKey {
    /// The analysis of `deformed` against `reference` (both as read) under `scheme` and `dic`;
    /// `as_read` says the run was read out in the camera's own mode (analysed without reduction).
    pub fn new(
        reference: FrameDigest,
        deformed: FrameDigest,
        as_read: bool,
        scheme: &Scheme,
        dic: &DicSettings,
    ) -> Self {
        let mut hash = Sha256::new();
        hash.update(reference.0);
        hash.update(deformed.0);
        hash.update([as_read as u8]);
        // JSON of plain data: every field, the same bytes for the same values.
        hash.update(serde_json::to_vec(scheme).expect("a scheme serialises"));
        hash.update(serde_json::to_vec(dic).expect("DIC settings serialise"));
        Self(hash.finalize().into())
    }
}

/// Remembered analyses, oldest first, within a byte budget.
pub struct AnalysisMemo {
    budget_bytes: usize,
    entries: Mutex<VecDeque<(AnalysisKey, Arc<DicResult>, usize)>>,
}

impl AnalysisMemo {
    pub fn new(budget_bytes: usize) -> Self {
        Self {
            budget_bytes,
            entries: Mutex::new(VecDeque::new()),
        }
    }

    /// This process's memo, shared by every correlation loop.
    pub fn global() -> &'static AnalysisMemo {
        static MEMO: OnceLock<AnalysisMemo> = OnceLock::new();
        MEMO.get_or_init(|| AnalysisMemo::new(BUDGET_BYTES))
    }

    /// The analysis remembered under `key`, if any.
    pub fn recall(&self, key: &AnalysisKey) -> Option<Arc<DicResult>> {
        let entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        entries
            .iter()
            .find(|(k, _, _)| k == key)
            .map(|(_, r, _)| Arc::clone(r))
    }

    /// Remembers `result` under `key`, forgetting the oldest analyses beyond the budget; an
    /// analysis larger than the whole budget is not kept.
    pub fn remember(&self, key: AnalysisKey, result: &DicResult) {
        let size = bytes_of(result);
        if size > self.budget_bytes {
            return;
        }
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if entries.iter().any(|(k, _, _)| *k == key) {
            return;
        }
        let mut held: usize = entries.iter().map(|(_, _, s)| s).sum();
        while held + size > self.budget_bytes {
            let Some((_, _, s)) = entries.pop_front() else {
                break;
            };
            held -= s;
        }
        entries.push_back((key, Arc::new(result.clone()), size));
    }

    /// How many analyses are remembered.
    pub fn len(&self) -> usize {
        self.entries.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What an analysis holds in memory, nearly all of it its points.
fn bytes_of(result: &DicResult) -> usize {
    std::mem::size_of::<DicResult>()
        + result.points.capacity() * std::mem::size_of::<crate::dic::PoiResult>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dic::{PoiGrid, PoiResult, PoiStatus, Summary};

    /// An analysis of `points` points on a row (their values do not matter here).
    fn result(points: usize) -> DicResult {
        let settings = DicSettings::default();
        let grid = PoiGrid::new(&settings, 256, 256).expect("a frame larger than a subset");
        let points: Vec<PoiResult> = (0..points)
            .map(|i| PoiResult::invalid(i as f64, 0.0, PoiStatus::Converged, 1.0, 1))
            .collect();
        DicResult {
            summary: Summary::of(&points),
            strain_gauge_px: settings.strain_gauge_px(),
            settings,
            grid,
            points,
            global_offset_px: (0, 0),
        }
    }

    #[test]
    fn a_key_changes_with_every_input() {
        let a = FrameDigest::of(&Image::filled(8, 8, 1.0));
        let b = FrameDigest::of(&Image::filled(8, 8, 2.0));
        // The same pixels in another shape are another frame.
        assert_ne!(
            FrameDigest::of(&Image::filled(4, 16, 1.0)),
            a,
            "the size is part of the content"
        );
        let native = Scheme::preset("native").unwrap();
        let dic = DicSettings::default();
        let key = AnalysisKey::new(a, b, false, &native, &dic);
        assert_eq!(key, AnalysisKey::new(a, b, false, &native, &dic));
        assert_ne!(key, AnalysisKey::new(b, a, false, &native, &dic));
        assert_ne!(key, AnalysisKey::new(a, b, true, &native, &dic));
        let binned = Scheme::preset("ff100").unwrap();
        assert_ne!(key, AnalysisKey::new(a, b, false, &binned, &dic));
        let other = DicSettings {
            step_px: dic.step_px + 1,
            ..dic.clone()
        };
        assert_ne!(key, AnalysisKey::new(a, b, false, &native, &other));
    }

    #[test]
    fn the_memo_recalls_what_it_holds_and_forgets_the_oldest_beyond_its_budget() {
        let one = bytes_of(&result(100));
        let memo = AnalysisMemo::new(2 * one + one / 2);
        let native = Scheme::preset("native").unwrap();
        let digest = |v: f32| FrameDigest::of(&Image::filled(4, 4, v));
        let key = |v: f32| {
            AnalysisKey::new(
                digest(0.0),
                digest(v),
                false,
                &native,
                &DicSettings::default(),
            )
        };
        memo.remember(key(1.0), &result(100));
        memo.remember(key(2.0), &result(100));
        assert_eq!(memo.len(), 2);
        assert_eq!(memo.recall(&key(1.0)).unwrap().points.len(), 100);
        assert!(memo.recall(&key(3.0)).is_none());
        // A third does not fit beside two: the oldest goes.
        memo.remember(key(3.0), &result(100));
        assert_eq!(memo.len(), 2);
        assert!(memo.recall(&key(1.0)).is_none());
        assert!(memo.recall(&key(2.0)).is_some() && memo.recall(&key(3.0)).is_some());
        // One larger than the whole budget is not kept, and forgets nothing.
        memo.remember(key(4.0), &result(1000));
        assert!(memo.recall(&key(4.0)).is_none());
        assert_eq!(memo.len(), 2);
    }
}
