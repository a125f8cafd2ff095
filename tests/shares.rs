//! Issue 39, items 2, 4 and 5: no submission and no client can hold what every other request
//! needs. A submission computes no quadrature (its job's run does); a client past its share of
//! the document bytes is refused at once while another client's merge goes through; a client
//! whose studies pull from a slow peer delays only itself. The other client is 127.0.0.2 —
//! loopback too — beside 127.0.0.1.

use std::time::Duration;

use crate::common::{Client, TestServer, small_job};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpSocket, TcpStream};

/// A client of `server` from 127.0.0.2.
fn other_client(server: &TestServer) -> Client {
    let http = reqwest::Client::builder().local_address(std::net::IpAddr::from([127, 0, 0, 2])).build().unwrap();
    Client::new(&server.base).with_http(http)
}

/// A connection to `server` from 127.0.0.2.
async fn connect_from_other(server: &TestServer) -> TcpStream {
    let addr = server.base.trim_start_matches("http://").parse().unwrap();
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind("127.0.0.2:0".parse().unwrap()).unwrap();
    socket.connect(addr).await.unwrap()
}

/// Item 2: a submission computes no reference quadrature (a hard scene's took seconds on the
/// request pool, and sixteen abandoned ones held it); the job's own run computes it and the job
/// then shows it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_submission_computes_no_quadrature_its_run_does() {
    let server = TestServer::start().await;
    // The one worker is busy, so the next job stays queued.
    let busy = server.submit(&small_job(1_000_000, 1)).await;
    server.wait_for_state(busy, "running").await;
    // A scene no other test uses: its reference cannot be in the cache.
    let mut spec = small_job(3, 2);
    spec["scene"] = json!({ "l3": 3.0625 });
    let queued = server.submit_job(&spec).await;
    assert_eq!(queued["state"], "queued");
    assert!(queued["reference_luminance"].is_null(), "computed at submission: {queued}");
    assert_eq!(server.cancel(busy).await.status, 202);
    let id = queued["id"].as_i64().unwrap();
    let done = server.wait_finished(id).await;
    assert_eq!(done["state"], "succeeded", "{done}");
    let reference = done["reference_luminance"].as_f64().expect("the run computed the reference");
    assert!((2.0e-4..3.5e-4).contains(&reference), "{reference}");
    // The result carries it too.
    assert_eq!(server.result(id).await["reference_luminance"].as_f64(), Some(reference));
    server.stop().await;
}

/// A finished job and a moments document of another seed of the same configuration.
async fn job_and_document(server: &TestServer) -> (i64, Value) {
    let target = server.submit_and_wait(&small_job(4, 21)).await;
    let other = server.submit_and_wait(&small_job(4, 22)).await;
    (target, server.moments(other).await)
}

/// Item 4: five stalled uploads of one client held every byte of the document budget and kept a
/// valid merge of another client waiting (37.8 s; with longer stalls it got 408, blaming it).
/// Now a client holds at most one document's worth: its second upload is refused at once, and the
/// other client's merge goes through.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_past_its_document_share_is_refused_and_others_merge() {
    let limit = 2 << 20;
    let server = TestServer::start_with(|c| {
        c.http.document_bytes = limit;
        c.http.body_timeout = Duration::from_secs(120);
    })
    .await;
    let (target, document) = job_and_document(&server).await;
    let head = format!(
        "POST /v1/jobs/{target}/merge HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n\
         Content-Length: {limit}\r\n\r\n"
    );
    let mut stalled = Vec::new();
    let mut refused = 0;
    for _ in 0..5 {
        let mut s = connect_from_other(&server).await;
        s.write_all(head.as_bytes()).await.unwrap();
        // Nearly the whole body, then nothing more.
        if s.write_all(&vec![b' '; limit - 1024]).await.is_err() {
            refused += 1;
            continue;
        }
        let mut answer = vec![0u8; 4096];
        match tokio::time::timeout(Duration::from_millis(500), s.read(&mut answer)).await {
            Ok(Ok(n)) if n > 0 => {
                let text = String::from_utf8_lossy(&answer[..n]).into_owned();
                assert!(text.starts_with("HTTP/1.1 429") && text.contains("127.0.0.2"), "{text}");
                refused += 1;
            }
            _ => stalled.push(s),
        }
    }
    assert_eq!((stalled.len(), refused), (1, 4), "one upload within the share, the others refused");
    let merged = server.merge(target, &document).await;
    assert_eq!(merged.status, 200, "{}", merged.text());
    drop(stalled);
    server.stop().await;
}

/// A peer that answers every request with a document that never ends (a byte every 100 ms).
async fn slow_peer() -> String {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    tokio::spawn(async move {
        while let Ok((mut stream, _)) = listener.accept().await {
            tokio::spawn(async move {
                let mut request = [0u8; 4096];
                let _ = stream.read(&mut request).await;
                let head = "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 100000\r\n\r\n{";
                if stream.write_all(head.as_bytes()).await.is_err() {
                    return;
                }
                while stream.write_all(b" ").await.is_ok() {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            });
        }
    });
    base
}

/// Item 5: two studies of one client pulling eight sources each from a slow peer held both
/// processing slots and every server-wide pull, so a fast one-source study of another client got
/// 429 after 10 s. Now a pull waiting on its peer holds no processing slot and only its client's
/// share of the pulls: the other client's studies — from a fast peer, and from a document — are
/// created. A shutdown answers the slow studies 503 (they got no answer after 10 s before).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_peer_delays_only_the_client_whose_studies_pull_from_it() {
    let fast = TestServer::start().await;
    let fast_job = fast.submit_and_wait(&small_job(4, 31)).await;
    let slow = slow_peer().await;
    let allowed: Vec<_> = [slow.as_str(), fast.base.as_str()]
        .iter()
        .map(|p| optimis::jobs::merges::peers::Peer::parse(p).unwrap())
        .collect();
    let server = TestServer::start_with(move |c| {
        c.peers = allowed;
        c.http.max_document_requests = 2;
    })
    .await;
    let other = other_client(&server);
    let mut slow_studies = Vec::new();
    for study in 0..2 {
        let sources: Vec<_> = (1..=8).map(|i| json!({ "from": format!("{slow}/v1/jobs/{}", study * 8 + i) })).collect();
        let client = other.clone();
        slow_studies.push(tokio::spawn(async move { client.study(&json!({ "sources": sources })).await }));
    }
    // Let them start pulling (an ordering, not a speed limit).
    tokio::time::sleep(Duration::from_millis(500)).await;
    let from_peer =
        server.study(&json!({ "sources": [{ "from": format!("{}/v1/jobs/{fast_job}", fast.base) }] })).await;
    assert_eq!(from_peer.status, 201, "{}", from_peer.text());
    let document = fast.moments(fast_job).await;
    let inline = server.study(&json!({ "sources": [document] })).await;
    assert_eq!(inline.status, 201, "{}", inline.text());
    // A stopping server answers the studies still waiting on the slow peer (503) instead of
    // holding them, and itself, until its grace runs out.
    server.stop().await;
    for study in slow_studies {
        let reply = study.await.unwrap();
        assert_eq!(reply.status, 503, "{}", reply.text());
    }
    fast.stop().await;
}
