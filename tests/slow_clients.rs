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
