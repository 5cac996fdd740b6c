//! The last few values a pure function gave, by their inputs: a print's calibration renders its
//! reference crop some fifty times with the same layout of dots, and drawing it again each time
//! was 6–8 % of a diagnosis round. Used by the hard core's layouts (`hard_core.rs`), the
//! lattice's (`lattice.rs`) and the diagnosis's reference crops (`diagnose::scene`); a value
//! found is the one computed, by construction.

use std::sync::Mutex;

/// At most `capacity` (key, value) pairs, the oldest dropped first.
pub(crate) struct Remembered<K, V> {
    entries: Mutex<Vec<(K, V)>>,
    capacity: usize,
}

impl<K: PartialEq, V: Clone> Remembered<K, V> {
    pub(crate) const fn new(capacity: usize) -> Self {
        Self {
            entries: Mutex::new(Vec::new()),
            capacity,
        }
    }

    /// The value remembered for `key`, else `make`'s (computed without the lock held, then
    /// remembered).
    pub(crate) fn get_or(&self, key: K, make: impl FnOnce() -> V) -> V {
        let found = self
            .entries
            .lock()
            .expect("no panic while held")
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v.clone());
        if let Some(v) = found {
            return v;
        }
        let v = make();
        let mut entries = self.entries.lock().expect("no panic while held");
        if entries.len() == self.capacity {
            entries.remove(0);
        }
        entries.push((key, v.clone()));
        v
    }
}
