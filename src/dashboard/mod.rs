//! The dashboard: pages a person reads in a browser, served by the daemon at `/` next to the API.
//! Plain HTML, CSS and a little JavaScript that talks only to `/api/v1`; every asset is compiled
//! into the binary (no CDN: it works on an offline lab network). Pages:
//! - `/`: the bench (camera, stage, live snapshot with its histogram, exposure and gain), the
//!   experiments (list, a form to start one), the calibrations (list, a plan to start one), the
//!   design maps (list, a spec to start one) and the datasets (list, upload);
//! - `/experiments/{id}`: live progress, Figures 5 and 6, u/v/strain maps, downloads;
//! - `/datasets/{id}`: compare against a model, diagnose, add the winner, the history chart;
//! - `/sweeps/{id}`: a design map's progress, recommendations, heat maps, bias plots and cells;
//! - `/calibrations/{id}`: a calibration's progress, then its camera card (every number with its
//!   standard error and significance, the stage's map, the imaging chain, what is left
//!   unexplained, the stored model and how to use it).

mod assets;

use crate::service::Service;
use axum::extract::Path;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

/// Scripts, styles and data only from the daemon itself; nothing inline, nothing remote.
const CSP: &str = "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; \
                   script-src 'self'; connect-src 'self'; object-src 'none'; \
                   base-uri 'none'; frame-ancestors 'none'";

/// The dashboard's routes, to mount through [`crate::api::app`]'s `extra`.
pub fn router() -> Router<Service> {
    Router::new()
        .route("/", get(|| async { page(assets::HOME_HTML) }))
        .route(
            "/experiments/{id}",
            get(|_: Path<String>| async { page(assets::EXPERIMENT_HTML) }),
        )
        .route(
            "/datasets/{id}",
            get(|_: Path<String>| async { page(assets::DATASET_HTML) }),
        )
        .route(
            "/sweeps/{id}",
            get(|_: Path<String>| async { page(assets::SWEEP_HTML) }),
        )
        .route(
            "/calibrations/{id}",
            get(|_: Path<String>| async { page(assets::CALIBRATION_HTML) }),
        )
        .route("/assets/{name}", get(asset))
}

fn page(html: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
            (header::CONTENT_SECURITY_POLICY, CSP),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        html,
    )
        .into_response()
}

async fn asset(Path(name): Path<String>) -> Response {
    match assets::find(&name) {
        Some((bytes, mime)) => {
            let mut r = (StatusCode::OK, bytes).into_response();
            let h = r.headers_mut();
            h.insert(header::CONTENT_TYPE, HeaderValue::from_static(mime));
            h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
            h.insert(
                header::X_CONTENT_TYPE_OPTIONS,
                HeaderValue::from_static("nosniff"),
            );
            r
        }
        None => crate::api::ApiError::not_found(format!(
            "no asset '{}'",
            name.chars().take(64).collect::<String>()
        ))
        .into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_asset_a_page_names_is_shipped() {
        for html in [
            assets::HOME_HTML,
            assets::EXPERIMENT_HTML,
            assets::DATASET_HTML,
            assets::SWEEP_HTML,
            assets::CALIBRATION_HTML,
        ] {
            for part in html.split("/assets/").skip(1) {
                let name = &part[..part.find('"').unwrap()];
                assert!(assets::find(name).is_some(), "{name} is not shipped");
            }
            assert!(!html.contains("http://") && !html.contains("https://"));
        }
        for (name, _) in assets::ALL {
            let (bytes, _) = assets::find(name).unwrap();
            // The SVG namespace is a name, not a fetch; nothing else may point off the daemon.
            let text = std::str::from_utf8(bytes)
                .unwrap()
                .replace("http://www.w3.org/2000/svg", "");
            // Modules import each other by relative path only, never from the network.
            assert!(
                !text.contains("https://") && !text.contains("http://"),
                "{name}"
            );
        }
    }
}
