//! A dataset's frame pairs, read once and correlated under each scheme: the one loop of the
//! fill-factor study (`experiment::study`) and of the model comparison (`diagnose::compare`,
//! its full-resolution runs and its capture-mode runs).
//!
//! Runs that share a reference frame (every run of a pattern) reuse it: the reference is read,
//! reduced and prepared (`dic::PreparedReference`: interpolation coefficients, gradients, subset
//! sums) once per scheme and kept for the next runs — one reference per read-out mode, since an
//! experiment with hardware schemes alternates between the full-resolution reference and each
//! scheme's. A run the camera read out in its own binning or decimation (`capture`) is
//! correlated as it is, once, under its hardware scheme ([`hardware_geometry`]); every other run
//! under each scheme given.
//!
//! An analysis this process already made of the same frames' content, scheme and settings is
//! taken from [`memo::AnalysisMemo`] instead of made again, and a reference is prepared for a
//! scheme only when one of its runs is not remembered.

pub mod memo;

use crate::dataset::{check_pair, PairCheck, Run};
use crate::dic::{DicError, DicResult, DicSettings, PreparedReference, Watch};
use crate::image::{read_image, Image, ImageError};
use crate::reduce::{reduce, AxisScheme, ReduceError, Scheme};
use memo::{AnalysisKey, AnalysisMemo, FrameDigest};
use std::borrow::Cow;
use std::path::Path;

/// One run's frames, read and checked for equal size.
pub struct RunPair<'a> {
    /// The run's position in the runs handed to [`correlate_pairs`].
    pub index: usize,
    pub run: &'a Run,
    pub reference: &'a Image,
    pub deformed: &'a Image,
    /// The reference file's bit depth.
    pub bit_depth: u8,
}

#[derive(Debug, thiserror::Error)]
pub enum PairError {
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("run {run}: {source}")]
    Frames { run: String, source: PairCheck },
    #[error("run {run}, scheme {scheme}: {source}")]
    Reduce {
        run: String,
        scheme: String,
        source: ReduceError,
    },
    /// The visitor said stop ([`PairVisitor::cancelled`]) while a pair was correlated.
    #[error("cancelled")]
    Cancelled,
    #[error("run {run}, scheme {scheme}: {source}")]
    Dic {
        run: String,
        scheme: String,
        source: DicError,
    },
}

/// What [`correlate_pairs`] hands each run's frames and results to. An error stops the loop
/// (a caller's cancellation, a check of its own) and is returned as it is.
pub trait PairVisitor {
    /// Send: a run's correlation hands it back across [`rayon::join`] (the next run's frames
    /// are read beside it).
    type Error: From<PairError> + Send;

    /// A run's frames, before its schemes are correlated.
    fn frames(&mut self, _pair: &RunPair<'_>) -> Result<(), Self::Error> {
        Ok(())
    }

    /// Whether the caller has given the loop up. Asked from the correlation's threads before
    /// every point, so a long correlation stops within a point's IC-GN
    /// ([`PairError::Cancelled`]); the default never stops.
    fn cancelled(&self) -> bool {
        false
    }

    /// One scheme's result, in the order of the schemes (the hardware scheme's alone for a
    /// capture-mode run).
    fn result(
        &mut self,
        pair: &RunPair<'_>,
        scheme: &Scheme,
        result: DicResult,
    ) -> Result<(), Self::Error>;
}

/// A reference frame as read, with its schemes and, once a scheme's first run is not
/// remembered, its prepared reference.
struct PreparedFrame {
    file: String,
    /// The hardware scheme the frame was read out in; None at full resolution.
    mode: Option<String>,
    image: Image,
    digest: FrameDigest,
    bit_depth: u8,
    schemes: Vec<Scheme>,
    prepared: Vec<Option<PreparedReference>>,
}

impl PreparedFrame {
    /// Whether this is `run`'s reference frame, read out in the run's mode.
    fn is_reference_of(&self, run: &Run) -> bool {
        self.file == run.reference && self.mode == run.capture.as_ref().map(|c| c.name.clone())
    }
}

/// Correlates every run of `runs` (frames in `dir`) under each of `schemes`, or under its own
/// hardware scheme when the camera read it out in one, with this process's memo of analyses;
/// see the module doc.
pub fn correlate_pairs<V: PairVisitor + Send + Sync>(
    dir: &Path,
    runs: &[Run],
    schemes: &[Scheme],
    dic: &DicSettings,
    visitor: &mut V,
) -> Result<(), V::Error> {
    correlate_pairs_in(AnalysisMemo::global(), dir, runs, schemes, dic, visitor)
}

/// [`correlate_pairs`] with the analyses recalled from and remembered in `memo`. The next run's
/// frames are read while a run is correlated: reading and digesting a paper-size pair is
/// serial, and one at a time it left a core idle for a third of a diagnosis's measured side.
pub fn correlate_pairs_in<V: PairVisitor + Send + Sync>(
    memo: &AnalysisMemo,
    dir: &Path,
    runs: &[Run],
    schemes: &[Scheme],
    dic: &DicSettings,
    visitor: &mut V,
) -> Result<(), V::Error> {
    let mut kept: Vec<PreparedFrame> = Vec::new();
    let mut next = runs.first().map(|run| read_frames(dir, run, schemes, true));
    for (index, run) in runs.iter().enumerate() {
        let ReadFrames {
            reference,
            deformed,
        } = next.take().expect("read before its turn")?;
        let mut frame = match kept.iter().position(|f| f.is_reference_of(run)) {
            Some(k) => kept.remove(k),
            None => reference.expect("read where none was kept"),
        };
        // One reference per read-out mode: a mode's runs come one pattern after another, and an
        // experiment with hardware schemes alternates between the modes.
        kept.retain(|f| f.mode != frame.mode);
        // Whether the next run's reference must be read: the frames kept after this run.
        let following = runs.get(index + 1).map(|following| {
            let kept_after = frame.is_reference_of(following)
                || kept.iter().any(|f| f.is_reference_of(following));
            (following, !kept_after)
        });
        let (following, correlated) = rayon::join(
            || {
                following
                    .map(|(run, with_reference)| read_frames(dir, run, schemes, with_reference))
            },
            || correlate_run(memo, (index, run), (&mut frame, &deformed), dic, visitor),
        );
        correlated?;
        next = following;
        kept.push(frame);
    }
    Ok(())
}

/// A run's frames as [`read_frames`] reads them: its reference when no kept frame is it.
struct ReadFrames {
    reference: Option<PreparedFrame>,
    deformed: Image,
}

/// Reads `run`'s deformed frame and, when `with_reference`, its reference, side by side.
fn read_frames(
    dir: &Path,
    run: &Run,
    schemes: &[Scheme],
    with_reference: bool,
) -> Result<ReadFrames, PairError> {
    let (reference, deformed) = rayon::join(
        || {
            with_reference
                .then(|| read_reference(dir, run, schemes))
                .transpose()
        },
        || read_image(&dir.join(&run.deformed)),
    );
    Ok(ReadFrames {
        reference: reference?,
        deformed: deformed?.0,
    })
}

/// Run `index`'s frames checked and handed to `visitor`, then correlated under each of the
/// reference `frame`'s schemes (or recalled from `memo`).
fn correlate_run<V: PairVisitor + Sync>(
    memo: &AnalysisMemo,
    (index, run): (usize, &Run),
    (frame, deformed): (&mut PreparedFrame, &Image),
    dic: &DicSettings,
    visitor: &mut V,
) -> Result<(), V::Error> {
    check_pair(&frame.image, deformed).map_err(|source| PairError::Frames {
        run: run.id.clone(),
        source,
    })?;
    let pair = RunPair {
        index,
        run,
        reference: &frame.image,
        deformed,
        bit_depth: frame.bit_depth,
    };
    if visitor.cancelled() {
        return Err(PairError::Cancelled.into());
    }
    visitor.frames(&pair)?;
    let deformed_digest = FrameDigest::of(deformed);
    for (scheme, prepared) in frame.schemes.iter().zip(frame.prepared.iter_mut()) {
        let key = AnalysisKey::new(
            frame.digest,
            deformed_digest,
            run.capture.is_some(),
            scheme,
            dic,
        );
        if let Some(known) = memo.recall(&key) {
            visitor.result(&pair, scheme, DicResult::clone(&known))?;
            continue;
        }
        let prepared = match prepared {
            Some(p) => p,
            None => prepared.insert(prepare_scheme(&frame.image, run, scheme, dic, &|| {
                visitor.cancelled()
            })?),
        };
        let moved = as_analysed(deformed, run, scheme)?;
        let watching: &V = visitor;
        let watch = Watch {
            progress: None,
            cancelled: Some(&|| watching.cancelled()),
        };
        let result = prepared
            .correlate_watched(moved.as_ref(), watch)
            .map_err(|source| match source {
                DicError::Cancelled => PairError::Cancelled,
                source => PairError::Dic {
                    run: run.id.clone(),
                    scheme: scheme.name.clone(),
                    source,
                },
            })?;
        memo.remember(key, &result);
        visitor.result(&pair, scheme, result)?;
    }
    Ok(())
}

/// Reads `run`'s reference and digests its content; its schemes are the hardware scheme's alone,
/// as read, for a capture-mode run.
fn read_reference(dir: &Path, run: &Run, schemes: &[Scheme]) -> Result<PreparedFrame, PairError> {
    let (image, info) = read_image(&dir.join(&run.reference))?;
    let schemes = match &run.capture {
        Some(capture) => vec![hardware_geometry(capture)],
        None => schemes.to_vec(),
    };
    Ok(PreparedFrame {
        file: run.reference.clone(),
        mode: run.capture.as_ref().map(|c| c.name.clone()),
        bit_depth: info.bit_depth.min(16),
        digest: FrameDigest::of(&image),
        prepared: schemes.iter().map(|_| None).collect(),
        image,
        schemes,
    })
}

/// The reference `image` of `run` prepared for `scheme`.
fn prepare_scheme(
    image: &Image,
    run: &Run,
    scheme: &Scheme,
    dic: &DicSettings,
    cancelled: &dyn Fn() -> bool,
) -> Result<PreparedReference, PairError> {
    // A dense grid's preparation takes seconds a scheme.
    if cancelled() {
        return Err(PairError::Cancelled);
    }
    PreparedReference::new(as_analysed(image, run, scheme)?.as_ref(), dic).map_err(|source| {
        PairError::Dic {
            run: run.id.clone(),
            scheme: scheme.name.clone(),
            source,
        }
    })
}

/// A frame of `run` as `scheme` analyses it: reduced, or as read when the camera read the run
/// out in its own mode.
fn as_analysed<'a>(
    frame: &'a Image,
    run: &Run,
    scheme: &Scheme,
) -> Result<Cow<'a, Image>, PairError> {
    if run.capture.is_some() {
        return Ok(Cow::Borrowed(frame));
    }
    reduce(frame, scheme)
        .map(Cow::Owned)
        .map_err(|source| PairError::Reduce {
            run: run.id.clone(),
            scheme: scheme.name.clone(),
            source,
        })
}

/// A hardware scheme as the study's reduction vocabulary: the same block per axis, the whole
/// block active when binned, its first pixel when decimated; the name keeps the `hw:` prefix.
pub fn hardware_geometry(scheme: &ffdic_hw::HardwareScheme) -> Scheme {
    let axis = |a: ffdic_hw::AxisReduction| AxisScheme {
        block: a.factor() as usize,
        first: 0,
        active: a.active_px() as usize,
    };
    Scheme {
        name: scheme.name.clone(),
        x: axis(scheme.x),
        y: axis(scheme.y),
    }
}
