//! The camera: its state, its settings (`PATCH` applies and answers with what the camera really
//! set), and a snapshot as a 16-bit TIFF or, for a quick look, an 8-bit PNG — with, on request,
//! the speckle-quality figures of that very frame in a header (no second acquisition).

use super::blocking;
use crate::api::json::ApiJson;
use crate::api::problem::{ApiError, ApiResult, Problem};
use crate::bench::Owner;
use crate::service::Service;
use axum::extract::{Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;
use ffdic_hw::{CameraSettings, Frame, PixelFormat, SensorRoi};
use serde::Deserialize;
use serde_json::Value;
use std::time::Duration;

#[utoipa::path(get, path = "/camera", tag = "bench",
    responses((status = 200, description = "Camera info, settings and counters", body = Object),
              (status = 503, body = Problem), (status = 504, body = Problem)))]
pub async fn get_camera(State(svc): State<Service>) -> ApiResult<Json<Value>> {
    let bench = svc.bench.clone();
    let status = blocking(move || bench.status()).await??;
    Ok(Json(
        serde_json::to_value(status.camera).expect("camera status serialises"),
    ))
}

/// The largest binning (or decimation) factor a request may ask for: beyond what GenICam cameras offer (2–8),
/// so the camera, not this check, names its own limit.
pub const MAX_BINNING: u32 = 64;

/// The settings to change; absent fields keep their value.
#[derive(Debug, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraPatch {
    pub exposure_us: Option<f64>,
    pub gain_db: Option<f64>,
    #[schema(value_type = Option<String>)]
    pub pixel_format: Option<PixelFormat>,
    /// A sensor region `{x, y, width, height}`; `null` is the whole sensor.
    #[serde(default, deserialize_with = "present")]
    #[schema(value_type = Option<Object>)]
    pub roi: Option<Option<SensorRoi>>,
    /// Hardware binning `[horizontal, vertical]`.
    pub binning: Option<(u32, u32)>,
    /// Hardware decimation `[horizontal, vertical]` (one pixel of every block kept).
    pub decimation: Option<(u32, u32)>,
}

/// Tells `"roi": null` (clear it) from no `roi` at all (keep it).
fn present<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Option<SensorRoi>>, D::Error> {
    Ok(Some(Option::deserialize(d)?))
}

#[utoipa::path(patch, path = "/camera", tag = "bench", request_body = CameraPatch,
    responses((status = 200, description = "What the camera really set", body = Object),
              (status = 409, description = "An experiment holds the bench", body = Problem),
              (status = 422, body = Problem), (status = 503, body = Problem)))]
pub async fn patch_camera(
    State(svc): State<Service>,
    ApiJson(patch): ApiJson<CameraPatch>,
) -> ApiResult<Json<CameraSettings>> {
    for (field, v) in [
        ("exposure_us", patch.exposure_us),
        ("gain_db", patch.gain_db),
    ] {
        if v.is_some_and(|v| !v.is_finite()) {
            return Err(ApiError::invalid(field, "must be a finite number"));
        }
    }
    if let Some(Some(roi)) = patch.roi {
        if roi.width == 0 || roi.height == 0 {
            return Err(ApiError::invalid(
                "roi",
                "width and height must be at least 1",
            ));
        }
    }
    for (field, factors) in [("binning", patch.binning), ("decimation", patch.decimation)] {
        if let Some((h, v)) = factors {
            if !(1..=MAX_BINNING).contains(&h) || !(1..=MAX_BINNING).contains(&v) {
                return Err(ApiError::invalid(
                    field,
                    format!("each factor 1 to {MAX_BINNING}"),
                ));
            }
        }
    }
    let bench = svc.bench.clone();
    let applied = blocking(move || {
        let current = bench.status()?.camera.settings;
        let next = CameraSettings {
            exposure_us: patch.exposure_us.unwrap_or(current.exposure_us),
            gain_db: patch.gain_db.unwrap_or(current.gain_db),
            pixel_format: patch.pixel_format.unwrap_or(current.pixel_format),
            roi: patch.roi.unwrap_or(current.roi),
            binning: patch.binning.unwrap_or(current.binning),
            decimation: patch.decimation.unwrap_or(current.decimation),
            ..current
        };
        bench.apply_camera(Owner::Direct, next)
    })
    .await??;
    Ok(Json(applied))
}

#[derive(Debug, Deserialize, utoipa::IntoParams)]
pub struct SnapshotQuery {
    /// `tiff` (16-bit, the default) or `png` (8-bit, stretched for a quick look).
    #[param(pattern = "^(tiff|png)$")]
    pub format: Option<String>,
    /// With `true`, the `X-Speckle-Quality` header carries the frame's speckle-quality figures
    /// (JSON: mean intensity gradient, speckle size, SSSIG over `subset_px` subsets, and the
    /// temporal noise from a second frame taken for it, with the displacement error it predicts;
    /// and the whole frame's focus region by region, its gradient energy on a 4x3 grid).
    pub quality: Option<bool>,
    /// Subset side for the SSSIG, px (default: the DIC default subset); at most the frame's
    /// smaller side less 2 (422 otherwise: the frame size is the camera's).
    #[param(minimum = 3, maximum = 4096)]
    pub subset_px: Option<u32>,
}

/// The header that carries the speckle-quality figures of a snapshot.
pub const SPECKLE_QUALITY_HEADER: &str = "x-speckle-quality";

/// Side of the centred crop the quality figures are computed on: enough subsets for a median,
/// and a bounded cost on a large sensor (the autocorrelation is O(pixels × lags)).
const QUALITY_CROP_PX: usize = 1024;

/// The speckle-quality figures of a 16-bit frame, over its centred crop, as header JSON.
/// `second` is another frame of the same scene: the temporal noise comes from the pair (a
/// single frame's estimate takes speckle for noise: 2.3x the temporal σ on the mock bench).
fn quality_json(first: &Frame, second: &Frame, subset_px: usize) -> ApiResult<String> {
    let (width, height) = (first.width, first.height);
    let (cw, ch) = (width.min(QUALITY_CROP_PX), height.min(QUALITY_CROP_PX));
    let (x0, y0) = ((width - cw) / 2, (height - ch) / 2);
    let crop = |f: &Frame| {
        crate::image::Image::from_fn(cw, ch, |c, r| f.data[(y0 + r) * width + x0 + c] as f32)
    };
    let crop_first = crop(first);
    let figures = crate::image::speckle_quality(&crop_first, subset_px)
        .map_err(|e| ApiError::invalid("subset_px", e.to_string()))?;
    let noise_dn = if (second.width, second.height) == (width, height) {
        crate::diagnose::noise_variance(
            &crop_first,
            Some(&crop(second)),
            crate::model::effects::Quantization {
                bits: first.bit_depth.into(),
            }
            .max_dn(),
        )
        .sqrt()
    } else {
        f64::NAN
    };
    let whole =
        crate::image::Image::from_fn(width, height, |c, r| first.data[r * width + c] as f32);
    let q = SnapshotQuality {
        std_u_px: figures.std_u_px_per_noise_dn * noise_dn,
        std_v_px: figures.std_v_px_per_noise_dn * noise_dn,
        figures,
        noise_dn,
        focus: crate::image::focus_map(&whole, FOCUS_COLUMNS, FOCUS_ROWS),
    };
    Ok(serde_json::to_string(&q).expect("speckle quality serialises"))
}

/// The speckle-quality figures with the frame's own noise: what they predict for DIC here.
#[derive(serde::Serialize)]
struct SnapshotQuality {
    #[serde(flatten)]
    figures: crate::image::SpeckleQuality,
    /// Temporal image noise σ from the frame and a second one of the same scene, DN (NaN, JSON
    /// null, when the two differ in size).
    noise_dn: f64,
    /// σ_u and σ_v a median subset would show at that noise: √2·σ/√SSSIG (Pan et al. 2008), px.
    std_u_px: f64,
    std_v_px: f64,
    /// The gradient energy of each region of the whole frame (its focus, region by region).
    focus: crate::image::FocusMap,
}

/// The focus map's grid over the whole frame: columns and rows of regions.
const FOCUS_COLUMNS: usize = 4;
const FOCUS_ROWS: usize = 3;

#[utoipa::path(post, path = "/camera/snapshot", tag = "bench", params(SnapshotQuery),
    responses((status = 200, description = "One frame: 16-bit TIFF, or with format=png an 8-bit PNG", content(("image/tiff"), ("image/png")),
               headers(("X-Speckle-Quality" = String, description = "With quality=true: the frame's speckle-quality figures as JSON (mean_gradient_dn_per_px, speckle_size_x_px, speckle_size_y_px, speckle_size_px, subset_px, subsets, sssig_x_median_dn2, sssig_y_median_dn2, sssig_x_min_dn2, sssig_y_min_dn2, std_u_px_per_noise_dn, std_v_px_per_noise_dn, noise_dn: the temporal noise σ in DN from a second frame taken for it, std_u_px, std_v_px: the displacement error that noise predicts, focus: {columns, rows, energy_dn2_per_px2}: the whole frame's gradient energy per region, row-major)"))),
              (status = 422, description = "Unknown format, or a subset larger than the frame", body = Problem),
              (status = 409, body = Problem), (status = 503, body = Problem), (status = 504, body = Problem)))]
pub async fn snapshot(
    State(svc): State<Service>,
    Query(q): Query<SnapshotQuery>,
) -> ApiResult<Response> {
    let png = match q.format.as_deref() {
        None | Some("tiff") => false,
        Some("png") => true,
        Some(other) => {
            return Err(ApiError::invalid(
                "format",
                format!("'{other}': tiff or png"),
            ))
        }
    };
    let subset_px = q
        .subset_px
        .map_or(crate::dic::DicSettings::default().subset_px, |n| n as usize);
    if !(3..=4096).contains(&subset_px) {
        return Err(ApiError::invalid("subset_px", "3 to 4096 px"));
    }
    let bench = svc.bench.clone();
    let timeout = Duration::from_millis(svc.config.bench.frame_timeout_ms);
    // The quality figures need the noise: a second frame of the same scene measures it.
    let frames_wanted = if q.quality == Some(true) { 2 } else { 1 };
    let mut frames =
        blocking(move || bench.capture(Owner::Direct, frames_wanted, timeout)).await??;
    if frames.len() < frames_wanted {
        return Err(ApiError::unavailable("the camera delivered too few frames"));
    }
    let second = (frames_wanted == 2).then(|| frames.pop()).flatten();
    let frame = frames.remove(0);
    let quality = match second {
        Some(second) => {
            let f = frame.clone();
            Some(blocking(move || quality_json(&f, &second, subset_px)).await??)
        }
        None => None,
    };
    let (bytes, mime) = blocking(move || {
        if png {
            crate::report::png_quicklook(frame.width, frame.height, &frame.data)
                .map(|b| (b, "image/png"))
        } else {
            crate::image::tiff_u16_bytes(frame.width, frame.height, &frame.data)
                .map(|b| (b, "image/tiff"))
                .map_err(|e| e.to_string())
        }
    })
    .await?
    .map_err(|e| ApiError::internal("encoding the snapshot", e))?;
    let mut response = ([(header::CONTENT_TYPE, mime)], bytes).into_response();
    if let Some(json) = quality {
        let value = header::HeaderValue::from_str(&json)
            .map_err(|e| ApiError::internal("the speckle-quality header", e))?;
        response.headers_mut().insert(SPECKLE_QUALITY_HEADER, value);
    }
    Ok(response)
}
