//! The routes and the OpenAPI document they make: every handler carries its `#[utoipa::path]`,
//! so the document cannot drift from the router (a test checks it against a snapshot).

use super::problem::Problem;
use super::routes::{camera, datasets, experiments, jobs, models, stage, system};
use crate::service::Service;
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "ffdic",
        description = "Translation experiments, fill-factor synthesis, 2D DIC and a physical imaging model. \
                       Errors are RFC 9457 problem documents. Mutating requests need `Authorization: Bearer` \
                       when the server has a token.",
    ),
    components(schemas(Problem)),
    tags(
        (name = "system", description = "Health and status"),
        (name = "bench", description = "Camera and stage, directly"),
        (name = "experiments", description = "Translation experiments on the bench"),
        (name = "datasets", description = "Measurements in format ffdic-dataset/1"),
        (name = "jobs", description = "Any run: experiments, analyses, comparisons, diagnoses"),
        (name = "models", description = "Analysis models: embedded and added by users"),
    )
)]
struct ApiDoc;

/// `max_upload_bytes` bounds dataset uploads; every other body has the app's JSON limit.
pub fn router(max_upload_bytes: usize) -> OpenApiRouter<Service> {
    // The route-level limit is the inner layer, so it wins over the app-wide JSON limit.
    let uploads = OpenApiRouter::new()
        .routes(routes!(datasets::upload))
        .layer(axum::extract::DefaultBodyLimit::max(max_upload_bytes));
    let v1 = OpenApiRouter::new()
        .merge(uploads)
        .routes(routes!(system::health))
        .routes(routes!(system::status))
        .routes(routes!(camera::get_camera, camera::patch_camera))
        .routes(routes!(camera::snapshot))
        .routes(routes!(stage::get_stage))
        .routes(routes!(stage::move_stage))
        .routes(routes!(experiments::create, experiments::list))
        .routes(routes!(experiments::get))
        .routes(routes!(experiments::cancel_experiment))
        .routes(routes!(experiments::events))
        .routes(routes!(experiments::results))
        .routes(routes!(experiments::results_csv))
        .routes(routes!(experiments::frame))
        .routes(routes!(experiments::plot))
        .routes(routes!(datasets::list))
        .routes(routes!(datasets::get))
        .routes(routes!(datasets::analyse))
        .routes(routes!(datasets::compare))
        .routes(routes!(datasets::diagnose))
        .routes(routes!(datasets::history))
        .routes(routes!(datasets::history_svg))
        .routes(routes!(datasets::jobs))
        .routes(routes!(datasets::details))
        .routes(routes!(models::list, models::add))
        .routes(routes!(models::get))
        .routes(routes!(jobs::get_job))
        .routes(routes!(jobs::cancel_job))
        .routes(routes!(jobs::job_events))
        .routes(routes!(jobs::job_file));
    OpenApiRouter::with_openapi(ApiDoc::openapi()).nest("/api/v1", v1)
}
