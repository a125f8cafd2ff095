//! Slow and idle clients (issue 11, item 9): connections that send nothing, half a request head or
//! half a body are closed after the documented timeouts, and a flood of idle connections cannot
//! take more than `--max-connections` slots — the server answers again as soon as they time out.
//! (A client that stops *reading* is cut off by the send timeout; the kernel's send buffers hold
//! megabytes on loopback, so that is tested on a pipe, in `server::listener`.)
//! Timeouts are shortened for the test; hang guards of half a minute catch a connection that is
//! never closed.

use std::time::Duration;

use crate::common::TestServer;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

async fn server() -> TestServer {
    TestServer::start_with(|c| {
        c.connections.header_timeout = Duration::from_millis(500);
        c.http.body_timeout = Duration::from_millis(500);
        c.connections.send_timeout = Duration::from_secs(2);
        c.connections.max_connections = 20;
    })
    .await
}

/// Reads until the server closes the connection; what it sent.
async fn until_closed(stream: &mut TcpStream) -> String {
    let mut out = Vec::new();
    let read = tokio::time::timeout(Duration::from_secs(30), stream.read_to_end(&mut out)).await;
    assert!(read.is_ok(), "the server never closed the connection");
    String::from_utf8_lossy(&out).into_owned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn half_open_connections_are_closed_after_the_timeouts() {
    let server = server().await;
    let addr = server.base.trim_start_matches("http://").to_string();
    // Nothing at all.
    let mut silent = TcpStream::connect(&addr).await.unwrap();
    until_closed(&mut silent).await;
    // Half a request head.
    let mut half = TcpStream::connect(&addr).await.unwrap();
    half.write_all(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ").await.unwrap();
    until_closed(&mut half).await;
    // A head announcing 100 bytes of body, and only 10 of them: 408.
    let mut slow_body = TcpStream::connect(&addr).await.unwrap();
    slow_body
        .write_all(b"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{\"seed\": 1")
        .await
        .unwrap();
    let answer = until_closed(&mut slow_body).await;
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    // A keep-alive connection left idle after a request.
    let mut idle = TcpStream::connect(&addr).await.unwrap();
    idle.write_all(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").await.unwrap();
    let answer = until_closed(&mut idle).await;
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    assert!(server.list("").await.is_empty(), "no half request was served");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_connections_cannot_exhaust_the_server() {
    let server = server().await;
    let addr = server.base.trim_start_matches("http://").to_string();
    // Three times the connection limit, all silent.
    let mut idle = Vec::new();
    for _ in 0..60 {
        idle.push(TcpStream::connect(&addr).await.unwrap());
    }
    // The server answers again once the timeouts free slots (the idle ones wait in the backlog).
    let health = tokio::time::timeout(Duration::from_secs(30), server.get("/healthz")).await;
    assert_eq!(health.expect("the server answers again").status, 200);
    for stream in &mut idle {
        until_closed(stream).await;
    }
    server.stop().await;
}

/// Issue 22, item 3: a document request takes a processing slot only once its body is whole, so
/// clients trickling study bodies (more of them than `--max-document-requests`) hold none: a third
/// study is answered on its merits (422, its source list is empty), not told to retry (429).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn trickling_document_bodies_hold_no_processing_slot() {
    let server = TestServer::start_with(|c| c.http.max_document_requests = 2).await;
    let addr = server.base.trim_start_matches("http://").to_string();
    let mut tricklers = Vec::new();
    for _ in 0..3 {
        let mut s = TcpStream::connect(&addr).await.unwrap();
        let head = "POST /v1/studies HTTP/1.1\r\nHost: localhost\r\nContent-Type: application/json\r\n\
                    Content-Length: 100000\r\n\r\n{\"sources\": [";
        s.write_all(head.as_bytes()).await.unwrap();
        tricklers.push(s);
    }
    // Let the server read their heads and start waiting for their bodies (the old code took a
    // slot there; a study then waited 10 s for one and was answered 429).
    tokio::time::sleep(Duration::from_millis(500)).await;
    for s in &mut tricklers {
        s.write_all(b" ").await.unwrap();
    }
    let reply = server.post("/v1/studies", &serde_json::json!({ "sources": [] })).await;
    assert_eq!(reply.status, 422, "{}", reply.text());
    assert!(reply.text().contains("sources"), "{}", reply.text());
    drop(tricklers);
    server.stop().await;
}

/// Issue 22, item 5: one client address holds at most `--max-connections-per-client` connections;
/// a further one is answered 429 and closed at once (not held until the header timeout), and
/// another client — here 127.0.0.2, loopback too — is served while the first holds its share
/// half-open. (One client with 600 half-open connections once held the server at ~10 s latency.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_client_cannot_hold_every_connection() {
    let server = TestServer::start_with(|c| {
        c.connections.max_connections = 8;
        c.connections.max_per_client = 4;
        c.connections.header_timeout = Duration::from_secs(120);
    })
    .await;
    let addr = server.base.trim_start_matches("http://").to_string();
    let mut held = Vec::new();
    for _ in 0..4 {
        let mut s = TcpStream::connect(&addr).await.unwrap();
        s.write_all(b"GET /healthz HTTP/1.1\r\n").await.unwrap(); // half a head, never finished
        held.push(s);
    }
    // Give the accept loop time to admit the four (an ordering, not a speed limit).
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut over = TcpStream::connect(&addr).await.unwrap();
    let answer = until_closed(&mut over).await;
    assert!(answer.starts_with("HTTP/1.1 429") && answer.contains("--max-connections-per-client"), "{answer}");

    let other = reqwest::Client::builder().local_address(std::net::IpAddr::from([127, 0, 0, 2])).build().unwrap();
    let health = other.get(format!("{}/healthz", server.base)).send().await.unwrap();
    assert_eq!(health.status(), 200);
    drop(held);
    server.stop().await;
}
