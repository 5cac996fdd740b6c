//! What a dataset's frames must satisfy before anything is stored: every frame the manifest names
//! is there, decodes, is at least [`MIN_FRAME_SIDE_PX`] square and at most
//! [`FrameLimits::max_pixels`] (read from the header, before any pixel is decoded), each run's
//! frames share one size, and no run's stated move contradicts its frames
//! ([`check_stated_move`]).
//!
//! The work is bounded by the limits, not by the manifest: the runs are capped, each distinct
//! frame is decoded once however many runs name it (two are held at a time), and each distinct
//! (reference, deformed, stated move) is checked once. Errors name frames by their file name
//! only, never by a server path.

use super::{check_stated_move, Manifest, MoveContradiction};
use crate::dic::MIN_FRAME_SIDE_PX;
use crate::image::{decode_image_within, FrameInfo, Image, ImageError};
use std::collections::HashSet;
use std::path::Path;
use std::rc::Rc;

/// Why two frames of one run cannot be analysed together.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PairCheck {
    #[error("reference is {}x{}, deformed {}x{}", reference.0, reference.1, other.0, other.1)]
    SizeMismatch {
        reference: (usize, usize),
        other: (usize, usize),
    },
    #[error("frames of {width}x{height} px are too small to compare")]
    TooSmall { width: usize, height: usize },
}

/// The one check of a run's pair of frames (its reference and its deformed frame or a repeat),
/// wherever frames are read: an upload's [`check_frames`], the pair loop every analysis,
/// comparison and diagnosis runs on, and a diagnosis' static repeats. Both frames of the same
/// size, and at least [`MIN_FRAME_SIDE_PX`] on each side.
pub fn check_pair(reference: &Image, other: &Image) -> Result<(), PairCheck> {
    let size = |i: &Image| (i.width(), i.height());
    if size(reference) != size(other) {
        return Err(PairCheck::SizeMismatch {
            reference: size(reference),
            other: size(other),
        });
    }
    let (width, height) = size(reference);
    if width < MIN_FRAME_SIDE_PX || height < MIN_FRAME_SIDE_PX {
        return Err(PairCheck::TooSmall { width, height });
    }
    Ok(())
}

/// How much a dataset's check may take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameLimits {
    /// Most pixels a frame may have (width × height).
    pub max_pixels: usize,
    /// Most runs a manifest may list.
    pub max_runs: usize,
}

/// What the check of frames that passed cost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CheckedFrames {
    /// Distinct frames decoded.
    pub decoded: usize,
}

/// Why a dataset's frames were refused.
#[derive(Debug, thiserror::Error)]
pub enum FrameCheckError {
    #[error("the manifest lists {runs} runs; at most {max_runs} are accepted")]
    TooManyRuns { runs: usize, max_runs: usize },
    #[error("run {run}: '{name}' was not uploaded")]
    Missing { run: String, name: String },
    #[error("run {run}: {source}")]
    Unreadable {
        run: String,
        #[source]
        source: ImageError,
    },
    #[error("'{name}' is {width}x{height} px; at least {MIN_FRAME_SIDE_PX}x{MIN_FRAME_SIDE_PX}")]
    TooSmall {
        name: String,
        width: usize,
        height: usize,
    },
    #[error("run {run}: '{name}' differs in size from the reference")]
    SizeMismatch { run: String, name: String },
    #[error("{source}")]
    StatedMove {
        run: String,
        #[source]
        source: MoveContradiction,
    },
    #[error("the check was abandoned: the client left")]
    Abandoned,
}

impl FrameCheckError {
    /// The manifest field or part a refusal is about (a problem document's `field`).
    pub fn field(&self) -> String {
        match self {
            FrameCheckError::TooManyRuns { .. } => "runs".into(),
            FrameCheckError::StatedMove { run, .. } => format!("runs[{run}].stage"),
            FrameCheckError::Missing { .. }
            | FrameCheckError::Unreadable { .. }
            | FrameCheckError::TooSmall { .. }
            | FrameCheckError::SizeMismatch { .. }
            | FrameCheckError::Abandoned => "file".into(),
        }
    }
}

/// Checks the frames of the dataset in `dir` against `manifest`; `abandoned` is asked between
/// frames, and a `true` stops the check.
pub fn check_frames(
    dir: &Path,
    manifest: &Manifest,
    limits: FrameLimits,
    abandoned: &dyn Fn() -> bool,
) -> Result<CheckedFrames, FrameCheckError> {
    if manifest.runs.len() > limits.max_runs {
        return Err(FrameCheckError::TooManyRuns {
            runs: manifest.runs.len(),
            max_runs: limits.max_runs,
        });
    }
    let mut frames = Frames::new(dir, limits.max_pixels);
    let mut moves_checked = HashSet::new();
    let mut repeats_checked = HashSet::new();
    for run in &manifest.runs {
        if abandoned() {
            return Err(FrameCheckError::Abandoned);
        }
        let (reference, _) = frames.get(&run.id, &run.reference)?;
        let (deformed, _) = frames.get(&run.id, &run.deformed)?;
        check_pair(&reference, &deformed).map_err(|e| pair_refused(e, run, &run.deformed))?;
        let scale = run.frame_px_per_mm(manifest.scale_px_per_mm);
        let key = (
            run.reference.clone(),
            run.deformed.clone(),
            run.stage.dx_mm.to_bits(),
            run.stage.dy_mm.to_bits(),
            scale.to_bits(),
        );
        if moves_checked.insert(key) {
            check_stated_move(
                &reference,
                &deformed,
                (run.stage.dx_mm, run.stage.dy_mm),
                scale,
            )
            .map_err(|source| FrameCheckError::StatedMove {
                run: run.id.clone(),
                source,
            })?;
        }
        for name in &run.repeat {
            if repeats_checked.insert((run.reference.clone(), name.clone())) {
                if abandoned() {
                    return Err(FrameCheckError::Abandoned);
                }
                let (repeat, _) = frames.get(&run.id, name)?;
                check_pair(&reference, &repeat).map_err(|e| pair_refused(e, run, name))?;
            }
        }
    }
    Ok(CheckedFrames {
        decoded: frames.decoded,
    })
}

/// [`check_pair`]'s refusal of `run`'s frame `name` beside its reference, naming the file.
fn pair_refused(e: PairCheck, run: &super::Run, name: &str) -> FrameCheckError {
    match e {
        PairCheck::SizeMismatch { .. } => FrameCheckError::SizeMismatch {
            run: run.id.clone(),
            name: name.into(),
        },
        PairCheck::TooSmall { width, height } => FrameCheckError::TooSmall {
            name: name.into(),
            width,
            height,
        },
    }
}

/// Frames decoded on demand: the last two are held (a run's reference and deformed frame), so
/// runs that share frames decode them once.
struct Frames<'a> {
    dir: &'a Path,
    max_pixels: usize,
    held: Vec<(String, Rc<Image>, FrameInfo)>,
    decoded: usize,
}

impl<'a> Frames<'a> {
    const HELD: usize = 2;

    fn new(dir: &'a Path, max_pixels: usize) -> Self {
        Self {
            dir,
            max_pixels,
            held: Vec::with_capacity(Self::HELD),
            decoded: 0,
        }
    }

    fn get(&mut self, run: &str, name: &str) -> Result<(Rc<Image>, FrameInfo), FrameCheckError> {
        if let Some(pos) = self.held.iter().position(|(n, _, _)| n == name) {
            // Most recently used last.
            let entry = self.held.remove(pos);
            let out = (entry.1.clone(), entry.2);
            self.held.push(entry);
            return Ok(out);
        }
        let path = self.dir.join(name);
        if !path.is_file() {
            return Err(FrameCheckError::Missing {
                run: run.into(),
                name: name.into(),
            });
        }
        let unreadable = |source| FrameCheckError::Unreadable {
            run: run.into(),
            source,
        };
        // Errors name the file, not the folder it was staged in.
        let bytes = std::fs::read(&path).map_err(|e| {
            unreadable(ImageError::Open {
                path: name.into(),
                source: e,
            })
        })?;
        if self.held.len() == Self::HELD {
            // Let go of the least recently used frame before decoding the next one.
            self.held.remove(0);
        }
        let (image, info) =
            decode_image_within(&bytes, Path::new(name), self.max_pixels).map_err(unreadable)?;
        drop(bytes);
        self.decoded += 1;
        if image.width() < MIN_FRAME_SIDE_PX || image.height() < MIN_FRAME_SIDE_PX {
            return Err(FrameCheckError::TooSmall {
                name: name.into(),
                width: image.width(),
                height: image.height(),
            });
        }
        let image = Rc::new(image);
        self.held.push((name.into(), image.clone(), info));
        Ok((image, info))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::tiff_u16_bytes;

    /// A hashed texture (no renderer of ours), shifted by `dx` px.
    fn texture(w: usize, h: usize, dx: i64) -> Vec<u8> {
        let data: Vec<u16> = (0..w * h)
            .map(|k| {
                let (c, r) = ((k % w) as i64 - dx, (k / w) as u64);
                let mut s = (c as u64).wrapping_mul(73_856_093) ^ r.wrapping_mul(19_349_663);
                s ^= s >> 13;
                (s.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 52) as u16
            })
            .collect();
        tiff_u16_bytes(w, h, &data).unwrap()
    }

    fn dataset(runs: usize, dx_mm: f64) -> (tempfile::TempDir, Manifest) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("ref.tif"), texture(96, 80, 0)).unwrap();
        std::fs::write(dir.path().join("def.tif"), texture(96, 80, 13)).unwrap();
        let runs: Vec<serde_json::Value> = (0..runs)
            .map(|k| {
                serde_json::json!({"id": format!("r{k}"), "reference": "ref.tif",
                    "deformed": "def.tif", "stage": {"dx_mm": dx_mm, "dy_mm": 0.0}})
            })
            .collect();
        let m = serde_json::json!({"format": "ffdic-dataset/1", "name": "t",
            "scale_px_per_mm": 13.0, "runs": runs});
        std::fs::write(dir.path().join("dataset.json"), m.to_string()).unwrap();
        let manifest = Manifest::read(dir.path()).unwrap();
        (dir, manifest)
    }

    const LIMITS: FrameLimits = FrameLimits {
        max_pixels: 1 << 20,
        max_runs: 1000,
    };

    #[test]
    fn many_runs_over_one_pair_decode_two_frames() {
        let (dir, m) = dataset(500, 1.0);
        let checked = check_frames(dir.path(), &m, LIMITS, &|| false).unwrap();
        assert_eq!(checked.decoded, 2);
    }

    #[test]
    fn the_run_cap_and_the_pixel_cap_refuse_before_decoding() {
        let (dir, m) = dataset(3, 1.0);
        let tight = FrameLimits {
            max_runs: 2,
            ..LIMITS
        };
        let e = check_frames(dir.path(), &m, tight, &|| false).unwrap_err();
        assert_eq!(e.field(), "runs");
        let small = FrameLimits {
            max_pixels: 96 * 80 - 1,
            ..LIMITS
        };
        let e = check_frames(dir.path(), &m, small, &|| false).unwrap_err();
        assert!(
            matches!(
                e,
                FrameCheckError::Unreadable {
                    source: ImageError::TooLarge { .. },
                    ..
                }
            ),
            "{e}"
        );
        let text = e.to_string();
        assert!(
            text.contains("'ref.tif'") || text.contains("ref.tif"),
            "{text}"
        );
        assert!(
            !text.contains(&dir.path().display().to_string()),
            "no server path: {text}"
        );
    }

    #[test]
    fn a_contradicted_move_names_its_run_and_an_abandoned_check_stops() {
        let (dir, m) = dataset(2, 0.001);
        let e = check_frames(dir.path(), &m, LIMITS, &|| false).unwrap_err();
        assert_eq!(e.field(), "runs[r0].stage");
        let (dir, m) = dataset(2, 1.0);
        let e = check_frames(dir.path(), &m, LIMITS, &|| true).unwrap_err();
        assert!(matches!(e, FrameCheckError::Abandoned));
    }

    #[test]
    fn a_pair_is_checked_for_size_then_for_its_smallest_side() {
        let m = MIN_FRAME_SIDE_PX;
        let frame = |w, h| Image::filled(w, h, 0.0);
        assert_eq!(check_pair(&frame(m, m + 1), &frame(m, m + 1)), Ok(()));
        let e = check_pair(&frame(m + 2, m), &frame(m, m + 2)).unwrap_err();
        assert_eq!(
            e,
            PairCheck::SizeMismatch {
                reference: (m + 2, m),
                other: (m, m + 2)
            }
        );
        assert_eq!(
            e.to_string(),
            format!("reference is {}x{m}, deformed {m}x{}", m + 2, m + 2)
        );
        let e = check_pair(&frame(m - 1, m), &frame(m - 1, m)).unwrap_err();
        assert_eq!(
            e,
            PairCheck::TooSmall {
                width: m - 1,
                height: m
            }
        );
    }
}
