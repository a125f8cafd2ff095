//! Named, labelled runs (issue 25, item 3): `name`, `labels` and `notes` in a job document — not
//! part of the fingerprint, so runs of other names still merge — the job list filtered by label,
//! state and sweep, and a sweep's runs named after their swept values.

use crate::common::{TestServer, assert_problem, small_job};
use serde_json::{Value, json};

fn with(mut spec: Value, extra: Value) -> Value {
    for (k, v) in extra.as_object().unwrap() {
        spec[k] = v.clone();
    }
    spec
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn jobs_are_named_labelled_and_found_by_label() {
    let server = TestServer::start().await;
    let a = server
        .submit_and_wait(&with(
            small_job(20, 1),
            json!({ "name": "radius study, seed 1", "labels": { "study": "radius", "owner": "ana" }, "notes": "first try" }),
        ))
        .await;
    let b = server.submit_and_wait(&with(small_job(20, 2), json!({ "labels": { "study": "radius" } }))).await;
    let c = server.submit_and_wait(&with(small_job(20, 3), json!({ "labels": { "study": "l3" } }))).await;
    let job = server.job(a).await;
    assert_eq!(job["spec"]["name"], "radius study, seed 1");
    assert_eq!(job["spec"]["labels"], json!({ "owner": "ana", "study": "radius" }));
    assert_eq!(job["spec"]["notes"], "first try");
    // Not part of the configuration: the three share a fingerprint and merge.
    assert_eq!(job["fingerprint"], server.job(c).await["fingerprint"]);
    let merged = server.merge(b, &server.moments(a).await).await;
    assert_eq!(merged.status, 200, "{}", merged.text());
    assert_eq!(server.job(b).await["spec"]["labels"], json!({ "study": "radius" }), "the target keeps its labels");
    // …and records where its statistics come from, with every seed it holds (its spec keeps one).
    let provenance = &server.job(b).await["provenance"];
    assert_eq!(
        *provenance,
        json!({ "sources": [
                    { "from": format!("job {b}"), "seeds": [2], "iterations": 20, "computed_here": true },
                    { "from": "document", "seeds": [1], "iterations": 20, "computed_here": false } ],
                "seeds": [1, 2] })
    );
    assert!(server.job(c).await.get("provenance").is_none(), "a job that merged nothing has none");
    let study = server.study(&json!({ "sources": [server.moments(c).await, server.moments(a).await] })).await;
    assert_eq!(study.status, 201, "{}", study.text());
    assert_eq!(study.json()["provenance"]["seeds"], json!([1, 3]));
    assert_eq!(study.json()["provenance"]["sources"][1]["from"], "document sources[1]");

    let ids = |jobs: Vec<Value>| jobs.iter().map(|j| j["id"].as_i64().unwrap()).collect::<Vec<_>>();
    assert_eq!(ids(server.list("?label=study%3Dradius").await), [b, a]);
    assert_eq!(ids(server.list("?label=owner%3Dana&state=succeeded").await), [a]);
    assert_eq!(ids(server.list("?label=study%3Dnone").await), Vec::<i64>::new());
    for bad in ["?label=study", "?label=bad%20key%3D1", "?sweep=0"] {
        let problem = assert_problem(server.get(&format!("/v1/jobs{bad}")).await, 422);
        assert!(problem["field"] == "label" || problem["field"] == "sweep", "{bad}: {problem}");
    }
    // Bounded and printable; the field named.
    for (extra, field) in [
        (json!({ "labels": { "bad key": "x" } }), "labels.bad key"),
        (json!({ "name": "a\nb" }), "name"),
        (json!({ "notes": "x".repeat(4001) }), "notes"),
    ] {
        let problem = assert_problem(server.post("/v1/jobs", &with(small_job(1, 9), extra)).await, 422);
        assert_eq!(problem["field"], field, "{problem}");
    }

    // A sweep's runs carry the base's labels, are named after their swept values, and are listed
    // by sweep.
    let created = server
        .post(
            "/v1/sweeps",
            &json!({ "base": { "iterations": 20, "light_paths": 1_000_000, "seed": 3, "name": "R", "labels": { "study": "sweep" } },
                     "axes": [{ "field": "merge_radius", "values": [0.003, 0.01] }] }),
        )
        .await;
    assert_eq!(created.status, 201, "{}", created.text());
    let sweep = created.json()["id"].as_i64().unwrap();
    server.get_json(&format!("/v1/sweeps/{sweep}?wait=60")).await;
    let runs = server.list(&format!("?sweep={sweep}")).await;
    let names: Vec<&str> = runs.iter().map(|j| j["spec"]["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["R: merge_radius=0.01", "R: merge_radius=0.003"]);
    assert_eq!(ids(server.list("?label=study%3Dsweep").await), ids(runs));
    server.stop().await;
}
