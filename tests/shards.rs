//! A study split across two real `optimis serve` processes (separate SQLite files), merged on a
//! third job by pulling from the peers — bit-identical to one job running all iterations — and the
//! merges that must be refused (same shard twice, another configuration, a corrupted or truncated
//! document, an unreachable peer), each leaving the target's statistics unchanged.

use crate::common::assert_problem;
use crate::common::process::{Process, free_port};
use serde_json::{Value, json};

fn study(seed: u64, shard: Option<(u64, u64)>, radius: f64) -> Value {
    let mut spec =
        json!({ "light_paths": 100_000, "camera_paths": 300, "merge_radius": radius, "iterations": 30, "seed": seed });
    if let Some((index, count)) = shard {
        spec["shard"] = json!({ "index": index, "count": count });
    }
    spec
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shards_on_two_servers_merge_into_the_whole_study() {
    let dir = tempfile::tempdir().unwrap();
    let db = |name: &str| format!("sqlite://{}", dir.path().join(name).display());
    // A pulls from itself and from B (its allow-list names both, and port 9, where nothing
    // listens); B allows no peers.
    let (pa, pb) = (free_port(), free_port());
    let peer = |p: u16| format!("http://127.0.0.1:{p}");
    let (peer_a, peer_b, peer_9) = (peer(pa), peer(pb), peer(9));
    let flags = ["--checkpoint-iterations", "3", "--checkpoint-seconds", "0.5"];
    let b = Process::start_on(&db("b.db"), pb, &flags);
    let a = Process::start_on(
        &db("a.db"),
        pa,
        &[&flags[..], &["--peer", &peer_a, "--peer", &peer_b, "--peer", &peer_9]].concat(),
    );

    let shard0 = a.submit(&study(21, Some((0, 2)), 0.02)).await;
    let shard1 = b.submit(&study(21, Some((1, 2)), 0.02)).await;
    let whole = a.submit(&study(21, None, 0.02)).await;
    for (server, id) in [(&a, shard0), (&b, shard1), (&a, whole)] {
        server.wait_for_state(id, "succeeded").await;
    }
    let s0 = a.job(shard0).await;
    assert_eq!(s0["progress"]["iterations_total"], 15, "shard 0 of 2 runs half of the 30 iterations");

    // The study, on server A, pulls both shards from their servers.
    let from = |base: &str, id: i64| json!({ "from": format!("{base}/v1/jobs/{id}") });
    let response = a.study(&json!({ "sources": [from(&a.base, shard0), from(&b.base, shard1)] })).await;
    assert_eq!(response.status, 201);
    let merged_job = response.json();
    assert_eq!(merged_job["state"], "succeeded");
    assert_eq!(merged_job["merged"], true);
    let merged = merged_job["id"].as_i64().unwrap();
    assert_eq!(response.header("location"), Some(format!("/v1/jobs/{merged}").as_str()));

    let merged_moments = a.moments(merged).await;
    let whole_moments = a.moments(whole).await;
    assert_eq!(merged_moments["moments"], whole_moments["moments"], "merged shards are bit-identical to the whole run");
    let report = |mut r: Value| {
        r.as_object_mut().unwrap().remove("job_id");
        r
    };
    let merged_result = report(a.result(merged).await);
    let whole_result = report(a.result(whole).await);
    assert_eq!(merged_result, whole_result, "the results are equal");

    // Refusals, each leaving the target unchanged.
    let unchanged = || a.moments(merged);
    let before = unchanged().await;
    let merge_path = format!("/v1/jobs/{merged}/merge");

    // The same shard a second time: 409 naming the overlapping iterations.
    let problem = assert_problem(a.merge(merged, &from(&b.base, shard1)).await, 409);
    assert!(problem["detail"].as_str().unwrap().contains("seed 21 iterations [15, 30)"), "{problem}");
    assert_eq!(unchanged().await, before);

    // A shard of another configuration (another R): 409.
    let foreign = b.submit_and_wait(&study(22, Some((0, 2)), 0.021)).await;
    let problem = assert_problem(a.merge(merged, &from(&b.base, foreign)).await, 409);
    assert!(
        problem["detail"].as_str().unwrap().contains("merge_radius: 0.021 vs 0.02"),
        "the field that differs: {problem}"
    );
    assert_eq!(unchanged().await, before);

    // A document with one byte changed (a digit of its statistics): 422.
    let other_seed = b.submit_and_wait(&study(23, None, 0.02)).await;
    let text = b.get(&format!("/v1/jobs/{other_seed}/moments")).await.text();
    let at = text.find("\"sum_y\":[").unwrap() + 50;
    let pos = text[at..].find(|c: char| c.is_ascii_digit() && c != '0').unwrap() + at;
    let mut corrupted = text.clone().into_bytes();
    corrupted[pos] = if corrupted[pos] == b'9' { b'1' } else { corrupted[pos] + 1 };
    let problem = assert_problem(a.post_raw(&merge_path, corrupted).await, 422);
    assert!(problem["detail"].as_str().unwrap().contains("checksum"), "{problem}");
    assert_eq!(unchanged().await, before);

    // A truncated document: 400.
    assert_problem(a.post_raw(&merge_path, text[..text.len() / 2].to_string()).await, 400);
    assert_eq!(unchanged().await, before);

    // An allowed peer that is not there: 422 naming the source.
    let problem = assert_problem(a.merge(merged, &json!({ "from": "http://127.0.0.1:9/v1/jobs/1" })).await, 422);
    assert_eq!(problem["field"], "from");
    assert!(problem["detail"].as_str().unwrap().contains("could not be reached"), "{problem}");
    assert_eq!(unchanged().await, before);
    // A server that is not on the allow-list: 403, nothing pulled.
    let problem =
        assert_problem(a.merge(merged, &json!({ "from": format!("{}/v1/jobs/1", peer(free_port())) })).await, 403);
    assert!(problem["detail"].as_str().unwrap().contains("--peer"), "{problem}");
    // B allows no peers at all.
    assert_problem(b.study(&json!({ "sources": [from(&a.base, shard0)] })).await, 403);

    // The intact document of another seed merges: 30 more iterations, results recomputed.
    let response = a.merge(merged, &serde_json::from_str::<Value>(&text).unwrap()).await;
    let result = response.json();
    assert_eq!(response.status, 200, "{result}");
    assert_eq!(result["iterations"], 60);
    assert_eq!(result["coverage"].as_array().unwrap().len(), 2, "two seeds covered");
    let job = a.job(merged).await;
    assert_eq!(job["progress"]["iterations_done"], 60);

    // A merged job cannot run more iterations; a shard cannot be extended past its range.
    assert_problem(a.extend(merged, &json!({ "iterations": 5 })).await, 409);
    assert_problem(a.extend(shard0, &json!({ "iterations": 5 })).await, 409);
    a.kill();
    b.kill();
}
