//! The error responses many routes share, declared once for the OpenAPI document: each is an RFC
//! 9457 problem document (`error::Problem`) with the status and the description every route that
//! answers it uses. A route lists them beside its own responses:
//! `responses((status = 200, …), NoSuchJob, ServerFailure)`. Route-specific failures (a 409 that
//! means something particular to the route) stay written out where they are answered.

use utoipa::IntoResponses;

use super::error::Problem;

/// 500: the server failed; the problem's text never leaks internals (they are logged).
#[derive(IntoResponses)]
#[response(status = 500, description = "Server failure", content_type = "application/problem+json")]
pub struct ServerFailure(#[allow(dead_code)] Problem);

/// 404 for a job id that names no job.
#[derive(IntoResponses)]
#[response(status = 404, description = "No such job", content_type = "application/problem+json")]
pub struct NoSuchJob(#[allow(dead_code)] Problem);

/// 404 for a sweep id that names no sweep.
#[derive(IntoResponses)]
#[response(status = 404, description = "No such sweep", content_type = "application/problem+json")]
pub struct NoSuchSweep(#[allow(dead_code)] Problem);

/// 400 for a request body that is not JSON.
#[derive(IntoResponses)]
#[response(status = 400, description = "The body is not JSON", content_type = "application/problem+json")]
pub struct NotJson(#[allow(dead_code)] Problem);

/// 413 for a request body beyond the route's limit.
#[derive(IntoResponses)]
#[response(status = 413, description = "The body is too large", content_type = "application/problem+json")]
pub struct TooLarge(#[allow(dead_code)] Problem);

/// 422 for a query parameter that is invalid or unknown.
#[derive(IntoResponses)]
#[response(
    status = 422,
    description = "A query parameter is invalid or unknown; `field` names it",
    content_type = "application/problem+json"
)]
pub struct BadQuery(#[allow(dead_code)] Problem);
