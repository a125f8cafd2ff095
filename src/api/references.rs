//! `GET /v1/references`: the published reference tables (the paper's Table 1), with the
//! configuration each was measured under — the same data `/result` attaches to a job that has
//! that configuration, and that clients (the Python example, the dashboard) show beside a run's.

use axum::Json;
use serde::Serialize;
use utoipa::ToSchema;

use crate::sim::checks::published::{ReferenceTable, tables};

/// The published tables.
#[derive(Debug, Serialize, ToSchema)]
pub struct References {
    /// Every table, each with its source, the configuration it applies to and its rows.
    pub references: Vec<ReferenceTable>,
}

/// The published reference tables.
#[utoipa::path(
    get, operation_id = "list_references", path = "/v1/references", tag = "jobs",
    responses((status = 200, description = "The published tables", body = References))
)]
pub async fn list() -> Json<References> {
    Json(References { references: tables().to_vec() })
}
