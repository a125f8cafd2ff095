//! Post-processing of the generated OpenAPI document: the bearer security scheme, the responses
//! every route shares (401, 403 from the cross-site guard, 408 and 415 for bodies, 429, 503 for
//! writes), added to every operation they apply to so that no route can forget them, and links
//! from the responses that create a job to the operations on it (so that clients and API fuzzers
//! know where a job's `id` comes from).

use utoipa::Modify;
use utoipa::openapi::content::ContentBuilder;
use utoipa::openapi::link::LinkBuilder;
use utoipa::openapi::path::Operation;
use utoipa::openapi::response::ResponseBuilder;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme};
use utoipa::openapi::{OpenApi, Ref, RefOr, Response};

use super::auth::is_public;
use super::error::PROBLEM_JSON;

/// Operations that can answer 429 (queue full, too many event streams).
const LIMITED: &[(&str, &str)] =
    &[("/v1/jobs", "post"), ("/v1/jobs/{id}/extend", "post"), ("/v1/jobs/{id}/events", "get")];

pub struct Security;

fn problem(description: &str) -> RefOr<Response> {
    ResponseBuilder::new()
        .description(description)
        .content(PROBLEM_JSON, ContentBuilder::new().schema(Some(Ref::from_schema_name("Problem"))).build())
        .build()
        .into()
}

fn operations(item: &mut utoipa::openapi::path::PathItem) -> Vec<(&'static str, &mut Operation)> {
    [
        ("get", item.get.as_mut()),
        ("post", item.post.as_mut()),
        ("put", item.put.as_mut()),
        ("delete", item.delete.as_mut()),
        ("patch", item.patch.as_mut()),
    ]
    .into_iter()
    .filter_map(|(method, op)| op.map(|op| (method, op)))
    .collect()
}

impl Modify for Security {
    fn modify(&self, openapi: &mut OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some("Required on every route but /healthz, /readyz and the dashboard's static files when the server is started with a token (OPTIMIS_TOKEN or --token-file)."))
                    .build(),
            ),
        );
        for (path, item) in openapi.paths.paths.iter_mut() {
            let public = is_public(path) || path == "/assets/{name}";
            for (method, operation) in operations(item) {
                if public {
                    operation.security = None;
                } else {
                    operation.security = Some(vec![SecurityRequirement::new("bearer", Vec::<String>::new())]);
                    operation
                        .responses
                        .responses
                        .insert("401".into(), problem("Missing or wrong bearer token (when the server requires one)"));
                }
                if LIMITED.contains(&(path.as_str(), method)) {
                    operation
                        .responses
                        .responses
                        .insert("429".into(), problem("A limit is reached; retry after Retry-After seconds"));
                }
                let responses = &mut operation.responses.responses;
                responses.entry("403".into()).or_insert_with(|| {
                    problem(
                        "A cross-origin request (an Origin other than this server's), or a Host this server does not \
                         answer to",
                    )
                });
                if operation.request_body.is_some() {
                    responses
                        .insert("415".into(), problem("The body is not JSON: send Content-Type: application/json"));
                    responses.insert(
                        "408".into(),
                        problem("The body did not arrive within the server's body timeout (--body-timeout)"),
                    );
                }
                if matches!(method, "post" | "delete") {
                    responses.entry("503".into()).or_insert_with(|| {
                        problem(
                            "The database cannot store anything right now (disk full or an I/O error); nothing was \
                             changed; retry after Retry-After seconds",
                        )
                    });
                }
            }
        }
    }
}

/// Links from the responses that create a job to every operation on `/v1/jobs/{id}…`.
pub struct Links;

impl Modify for Links {
    fn modify(&self, openapi: &mut OpenApi) {
        let mut targets: Vec<String> = Vec::new();
        for (path, item) in openapi.paths.paths.iter_mut() {
            if path.starts_with("/v1/jobs/{id}") {
                targets.extend(operations(item).into_iter().filter_map(|(_, op)| op.operation_id.clone()));
            }
        }
        targets.sort();
        for (path, method, status) in [("/v1/jobs", "post", "202"), ("/v1/studies", "post", "201")] {
            let Some(item) = openapi.paths.paths.get_mut(path) else { continue };
            let Some((_, operation)) = operations(item).into_iter().find(|(m, _)| *m == method) else { continue };
            let Some(RefOr::T(response)) = operation.responses.responses.get_mut(status) else { continue };
            for target in &targets {
                let link = LinkBuilder::new()
                    .operation_id(target.clone())
                    .parameter("id", "$response.body#/id")
                    .description(format!("`{target}` on the created job"))
                    .build();
                response.links.insert(target.clone(), RefOr::T(link));
            }
        }
    }
}
