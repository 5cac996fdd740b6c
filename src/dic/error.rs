use crate::image::Roi;

/// Why an analysis could not run at all. Problems of single points are a [`super::PoiStatus`].
#[derive(Debug, thiserror::Error)]
pub enum DicError {
    #[error("invalid {field}: {reason}")]
    Setting { field: &'static str, reason: String },
    #[error("reference is {ref_w}x{ref_h} but deformed is {def_w}x{def_h}: images must be the same size")]
    SizeMismatch {
        ref_w: usize,
        ref_h: usize,
        def_w: usize,
        def_h: usize,
    },
    #[error("ROI {roi} lies outside the {width}x{height} image")]
    RoiOutside {
        roi: Roi,
        width: usize,
        height: usize,
    },
    #[error("subset of {subset_px} px is larger than the ROI {roi}")]
    SubsetLargerThanRoi { subset_px: usize, roi: Roi },
    #[error(
        "no subset of {subset_px} px centred in ROI {roi} fits inside the {width}x{height} image"
    )]
    NoPointFits {
        subset_px: usize,
        roi: Roi,
        width: usize,
        height: usize,
    },
    /// The caller's [`super::Watch::cancelled`] said stop; nothing of the field is returned.
    #[error("cancelled")]
    Cancelled,
    #[error("the mask is {mask_w}x{mask_h} but the images are {width}x{height}")]
    MaskSize {
        mask_w: usize,
        mask_h: usize,
        width: usize,
        height: usize,
    },
}
