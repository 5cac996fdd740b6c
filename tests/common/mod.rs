//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod daemon;
pub mod folder_sink;
pub mod independent;

use ffdic::image::Image;
use ffdic::model::{render_dots, SpeckleLayout};
use std::path::PathBuf;

/// The `ffdic` binary run with `args`, as a user runs it.
pub fn ffdic(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .args(args)
        .output()
        .expect("run ffdic")
}

/// [`ffdic`], which must succeed (its stderr shown when it does not).
pub fn ffdic_ok(args: &[&str]) -> std::process::Output {
    let out = ffdic(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The shared benchmark data beside the repository (`../shared/data`).
pub fn shared_data() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// A speckle layout covering a `w x h` image with margin for large motions.
pub fn layout(w: usize, h: usize, seed: u64) -> SpeckleLayout {
    SpeckleLayout::jittered(
        (-120.0, -120.0, w as f64 + 120.0, h as f64 + 120.0),
        5.0,
        1.3,
        90.0,
        0.3,
        seed,
    )
}

/// Renders the layout at full fill factor on a 200-grey background.
pub fn render(layout: &SpeckleLayout, w: usize, h: usize) -> Image {
    render_dots(w, h, &layout.dots, 200.0, (1.0, 1.0))
}
