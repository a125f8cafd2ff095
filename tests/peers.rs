//! Pulls from peers (issue 11, item 6): only allowed peers are ever contacted; their answers are
//! bounded in size, never echoed, and redirects are not followed; and two servers with tokens
//! exchange a study over https, bit-identical to a single run.
//!
//! The hostile peers are raw TCP servers of the test's own on loopback ports.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use crate::common::process::{Process, free_port};
use crate::common::{Client, TestServer, assert_problem};
use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

/// A fake peer on loopback that answers every connection with `head` followed by `body_chunk`
/// repeated `repeats` times (or until the client goes away). Counts the bytes it could send and
/// whether anyone connected.
struct FakePeer {
    base: String,
    sent: Arc<AtomicUsize>,
    contacted: Arc<AtomicBool>,
}

async fn fake_peer(head: String, body_chunk: Vec<u8>, repeats: usize) -> FakePeer {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let sent = Arc::new(AtomicUsize::new(0));
    let contacted = Arc::new(AtomicBool::new(false));
    let (s, c) = (sent.clone(), contacted.clone());
    tokio::spawn(async move {
        while let Ok((mut stream, _)) = listener.accept().await {
            c.store(true, Ordering::SeqCst);
            let (head, chunk, s) = (head.clone(), body_chunk.clone(), s.clone());
            tokio::spawn(async move {
                let mut request = [0u8; 4096];
                let _ = stream.read(&mut request).await;
                if stream.write_all(head.as_bytes()).await.is_err() {
                    return;
                }
                for _ in 0..repeats {
                    match stream.write_all(&chunk).await {
                        Ok(()) => s.fetch_add(chunk.len(), Ordering::SeqCst),
                        Err(_) => return,
                    };
                }
            });
        }
    });
    FakePeer { base, sent, contacted }
}

/// A loopback listener that records whether anyone connected.
async fn bystander() -> (u16, Arc<AtomicBool>) {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let contacted = Arc::new(AtomicBool::new(false));
    let c = contacted.clone();
    tokio::spawn(async move {
        while listener.accept().await.is_ok() {
            c.store(true, Ordering::SeqCst);
        }
    });
    (port, contacted)
}

fn allow(peers: &[&str]) -> Vec<optimis::jobs::merges::peers::Peer> {
    peers.iter().map(|p| optimis::jobs::merges::peers::Peer::parse(p).unwrap()).collect()
}

/// A peer answering 500 with an endless body (a 3 GiB one once took the server to 6.3 GB): at most
/// a few KB of it are read, none of it is echoed. A redirect is not followed anywhere.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn peer_errors_are_read_a_little_never_echoed_and_redirects_not_followed() {
    let secret = b"SECRET-TOKEN-OF-AN-INTERNAL-SERVICE ".repeat(1000);
    let error = fake_peer(
        "HTTP/1.1 500 Internal Server Error\r\nContent-Type: text/plain\r\nContent-Length: 3221225472\r\n\r\n".into(),
        secret,
        100_000,
    )
    .await;
    let (hidden_port, hidden_contacted) = bystander().await;
    let redirect = fake_peer(
        format!("HTTP/1.1 302 Found\r\nLocation: http://127.0.0.1:{hidden_port}/admin\r\nContent-Length: 0\r\n\r\n"),
        Vec::new(),
        0,
    )
    .await;
    let (error_base, redirect_base) = (error.base.clone(), redirect.base.clone());
    let server = TestServer::start_with(move |c| c.peers = allow(&[&error_base, &redirect_base])).await;
    let target = server.submit_and_wait(&json!({ "iterations": 4, "light_paths": 100_000 })).await;
    let merge = |from: String| {
        let server = &server;
        async move { server.merge(target, &json!({ "from": from })).await }
    };

    let problem = assert_problem(merge(format!("{}/v1/jobs/1", error.base)).await, 422);
    assert!(error.contacted.load(Ordering::SeqCst), "the allowed peer was asked");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("500") && !detail.contains("SECRET"), "{detail}");
    tokio::time::sleep(Duration::from_millis(200)).await;
    let sent = error.sent.load(Ordering::SeqCst);
    assert!(sent < 32 << 20, "the error body was read on: {sent} bytes went out");

    let problem = assert_problem(merge(format!("{}/v1/jobs/1", redirect.base)).await, 422);
    assert!(problem["detail"].as_str().unwrap().contains("redirects are not followed"), "{problem}");
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(!hidden_contacted.load(Ordering::SeqCst), "the redirect target was contacted");
    server.stop().await;
}

/// A 2xx body beyond the document limit is refused, declared (Content-Length) or not (chunked).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn peer_documents_are_capped_by_the_document_limit() {
    let declared = fake_peer(
        "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 104857600\r\n\r\n".into(),
        vec![b' '; 65536],
        1600,
    )
    .await;
    let chunked = fake_peer(
        "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n".into(),
        format!("10000\r\n{}\r\n", " ".repeat(65536)).into_bytes(),
        1600,
    )
    .await;
    let (a, b) = (declared.base.clone(), chunked.base.clone());
    let server = TestServer::start_with(move |c| {
        c.peers = allow(&[&a, &b]);
        c.http.document_bytes = 1 << 20;
    })
    .await;
    for peer in [&declared, &chunked] {
        let response = server.study(&json!({ "sources": [{ "from": format!("{}/v1/jobs/3", peer.base) }] })).await;
        let problem = assert_problem(response, 422);
        assert!(problem["detail"].as_str().unwrap().contains("document limit"), "{problem}");
        assert!(peer.sent.load(Ordering::SeqCst) < 32 << 20);
    }
    server.stop().await;
}

/// A URL that is not under an allowed peer is refused (403, saying how to allow it) before any
/// connection: the server cannot be used to probe other hosts, ports or paths.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_allowed_peers_are_contacted() {
    let (port, contacted) = bystander().await;
    let allowed = format!("http://127.0.0.1:{port}/optimis");
    let server = TestServer::start_with(move |c| c.peers = allow(&[&allowed])).await;
    for url in [
        format!("http://127.0.0.1:{port}/v1/jobs/1"), // outside the allowed prefix
        format!("http://localhost:{port}/optimis/v1/jobs/1"), // another host name
        format!("https://127.0.0.1:{port}/optimis/v1/jobs/1"), // another scheme
        format!("http://127.0.0.1:{}/v1/jobs/1", free_port()), // another port
    ] {
        let problem = assert_problem(server.study(&json!({ "sources": [{ "from": url }] })).await, 403);
        let detail = problem["detail"].as_str().unwrap();
        assert!(detail.contains("not an allowed peer") && detail.contains("--peer"), "{detail}");
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(!contacted.load(Ordering::SeqCst), "a refused URL was contacted");
    server.stop().await;
}

/// Writes `text` to `path`, readable by its owner only.
fn secret_file(path: &std::path::Path, text: &str) {
    std::fs::write(path, text).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).unwrap();
    }
}

/// The acceptance test of item 6: two servers that require tokens, both serving https with a
/// certificate made here, exchange a study. Server A pulls shard 0 from itself and shard 1 from B,
/// presenting each peer's token and trusting the certificate through --peer-ca; the merged
/// moments are bit-identical to one run of the whole study.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_servers_with_tokens_exchange_a_study_over_https() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    let certified = rcgen::generate_simple_self_signed(vec!["localhost".to_string()]).unwrap();
    std::fs::write(path("cert.pem"), certified.cert.pem()).unwrap();
    secret_file(&path("key.pem"), &certified.signing_key.serialize_pem());
    let (token_a, token_b) = ("token-of-server-a-0123456789", "token-of-server-b-0123456789");
    secret_file(&path("a.token"), token_a);
    secret_file(&path("b.token"), token_b);
    let (pa, pb) = (free_port(), free_port());
    let (base_a, base_b) = (format!("https://localhost:{pa}"), format!("https://localhost:{pb}"));
    let db = |name: &str| format!("sqlite://{}", path(name).display());
    let tls = |token: &str| {
        vec![
            "--tls-cert".to_string(),
            path("cert.pem").display().to_string(),
            "--tls-key".to_string(),
            path("key.pem").display().to_string(),
            "--token-file".to_string(),
            path(token).display().to_string(),
            "--checkpoint-seconds".to_string(),
            "0.5".to_string(),
        ]
    };
    let b_flags = tls("b.token");
    let mut a_flags = tls("a.token");
    a_flags.extend([
        "--peer".to_string(),
        format!("{base_a},token-file={}", path("a.token").display()),
        "--peer".to_string(),
        format!("{base_b},token-file={}", path("b.token").display()),
        "--peer-ca".to_string(),
        path("cert.pem").display().to_string(),
    ]);
    let b = Process::start_on(&db("b.db"), pb, &b_flags.iter().map(String::as_str).collect::<Vec<_>>());
    let a = Process::start_on(&db("a.db"), pa, &a_flags.iter().map(String::as_str).collect::<Vec<_>>());

    optimis::trust::pins::install_crypto_provider();
    let ca = reqwest::Certificate::from_pem(certified.cert.pem().as_bytes()).unwrap();
    let https = reqwest::Client::builder().tls_certs_only([ca]).build().unwrap();
    let (client_a, client_b) = (
        Client::new(&base_a).with_http(https.clone()).with_token(token_a),
        Client::new(&base_b).with_http(https.clone()).with_token(token_b),
    );
    // Without its token a server refuses; plain http is not served.
    assert_eq!(Client::new(&base_a).with_http(https).get("/v1/jobs").await.status, 401);
    let plain = Client::new(format!("http://localhost:{pa}"));
    assert!(plain.builder(reqwest::Method::GET, "/healthz").send().await.is_err());

    let study = |shard: Option<(u64, u64)>| {
        let mut spec =
            json!({ "light_paths": 100_000, "camera_paths": 300, "merge_radius": 0.02, "iterations": 30, "seed": 21 });
        if let Some((index, count)) = shard {
            spec["shard"] = json!({ "index": index, "count": count });
        }
        spec
    };
    let shard0 = client_a.submit(&study(Some((0, 2)))).await;
    let shard1 = client_b.submit(&study(Some((1, 2)))).await;
    let whole = client_a.submit(&study(None)).await;
    for (client, id) in [(&client_a, shard0), (&client_b, shard1), (&client_a, whole)] {
        client.wait_for_state(id, "succeeded").await;
    }
    let sources = json!({ "sources": [{ "from": format!("{base_a}/v1/jobs/{shard0}") }, { "from": format!("{base_b}/v1/jobs/{shard1}") }] });
    let response = client_a.study(&sources).await;
    assert_eq!(response.status, 201, "{}", response.text());
    let merged = response.json()["id"].as_i64().unwrap();
    let merged_moments = client_a.moments(merged).await;
    let whole_moments = client_a.moments(whole).await;
    assert_eq!(merged_moments["moments"], whole_moments["moments"], "bit-identical to the single run");
    a.kill();
    b.kill();
}

/// Issue 22, item 4: a study of slow but valid sources ends at its deadline (`--study-deadline`),
/// with a problem naming `sources` and the deadline, instead of holding its request for the sum of
/// its pulls' deadlines (eight sources that trickle their documents took 47.8 s; 256 could take
/// hours). Nothing is created.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_study_of_slow_sources_ends_at_its_deadline() {
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
                // A byte every 100 ms: never idle long enough for the read timeout.
                while stream.write_all(b" ").await.is_ok() {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            });
        }
    });
    let allowed = base.clone();
    let server = TestServer::start_with(move |c| {
        c.peers = allow(&[&allowed]);
        c.policy.study_deadline = Duration::from_secs(2);
    })
    .await;
    let sources: Vec<_> = (1..=8).map(|i| json!({ "from": format!("{base}/v1/jobs/{i}") })).collect();
    let problem = assert_problem(server.study(&json!({ "sources": sources })).await, 422);
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.starts_with("sources:") && detail.contains("study deadline of 2 s"), "{detail}");
    assert_eq!(server.get("/v1/jobs").await.json()["jobs"].as_array().unwrap().len(), 0, "nothing was created");
    server.stop().await;
}

/// Writes a self-signed certificate for `localhost` (marked CA:TRUE when `ca`, as a plain
/// `openssl req -x509` makes it) and its key to `dir`; the paths.
fn self_signed(dir: &std::path::Path, name: &str, ca: bool) -> (std::path::PathBuf, std::path::PathBuf) {
    let mut params = rcgen::CertificateParams::new(vec!["localhost".to_string()]).unwrap();
    if ca {
        params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    }
    let key = rcgen::KeyPair::generate().unwrap();
    let cert = params.self_signed(&key).unwrap();
    let (cert_path, key_path) = (dir.join(format!("{name}.pem")), dir.join(format!("{name}.key")));
    std::fs::write(&cert_path, cert.pem()).unwrap();
    secret_file(&key_path, &key.serialize_pem());
    (cert_path, key_path)
}

/// Issue 22, item 7: a peer serving a self-signed certificate marked CA:TRUE (what `openssl req
/// -x509` makes; WebPKI refuses it as a server's own certificate, `CaUsedAsEndEntity`) is trusted
/// when that certificate is given to `--peer-ca`: it is pinned. A peer with another certificate is
/// refused, and the problem says why (the TLS error, and the flag that would trust it) instead of
/// only "handshake failed".
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_self_signed_certificate_given_to_peer_ca_is_pinned() {
    let dir = tempfile::tempdir().unwrap();
    let (cert, key) = self_signed(dir.path(), "peer", true);
    let (other, _) = self_signed(dir.path(), "other", true);
    let files = optimis::server::TlsFiles { cert: cert.clone(), key };
    let peer = TestServer::start_with(move |c| c.tls = Some(files)).await;
    let port = peer.base.rsplit(':').next().unwrap().to_string();
    let base = format!("https://localhost:{port}");
    let source = json!({ "sources": [{ "from": format!("{base}/v1/jobs/999") }] });

    let (b, ca) = (base.clone(), cert.clone());
    let trusting = TestServer::start_with(move |c| {
        c.peers = allow(&[&b]);
        c.peer_ca = Some(ca);
    })
    .await;
    let problem = assert_problem(trusting.study(&source).await, 422);
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("404"), "the handshake passed and the peer answered: {detail}");

    let b = base.clone();
    let other_ca = TestServer::start_with(move |c| {
        c.peers = allow(&[&b]);
        c.peer_ca = Some(other);
    })
    .await;
    let problem = assert_problem(other_ca.study(&source).await, 422);
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains("TLS handshake") && detail.contains("certificate") && detail.contains("--peer-ca"),
        "{detail}"
    );
    for server in [trusting, other_ca, peer] {
        server.stop().await;
    }
}

/// An Ed25519 key pair in the PEM files OpenSSL writes; (private, public) paths.
fn signing_keys(dir: &std::path::Path, name: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let pair = rcgen::KeyPair::generate_for(&rcgen::PKCS_ED25519).unwrap();
    let (private, public) = (dir.join(format!("{name}.pem")), dir.join(format!("{name}.pub.pem")));
    secret_file(&private, &pair.serialize_pem());
    std::fs::write(&public, pair.public_key_pem()).unwrap();
    (private, public)
}

/// Issue 22, item 12: provenance. Server B signs what it exports (`--signing-key`); server A
/// trusts B's key (`--trust`) and signs its own exports. A study of B's job verifies; a document
/// of B's edited and re-sealed (its checksum recomputed, as anyone can) is refused with 422 naming
/// the signature; an unsigned one is refused while `--trust` is set.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_servers_with_signing_keys_exchange_a_verified_study_and_refuse_forgeries() {
    let dir = tempfile::tempdir().unwrap();
    let (key_a, _) = signing_keys(dir.path(), "a");
    let (key_b, public_b) = signing_keys(dir.path(), "b");
    let b = TestServer::start_with(move |c| c.signing_key = Some(key_b)).await;
    let allowed = b.base.clone();
    let a = TestServer::start_with(move |c| {
        c.peers = allow(&[&allowed]);
        c.trust = vec![public_b];
        c.signing_key = Some(key_a);
    })
    .await;
    let spec = json!({ "iterations": 6, "light_paths": 100_000, "camera_paths": 30, "seed": 5 });
    let job = b.submit_and_wait(&spec).await;
    let exported = b.moments(job).await;
    let b_key = exported["signature"]["key_id"].as_str().expect("B signs its exports").to_string();
    assert_eq!(exported["signature"]["algorithm"], "ed25519");

    let study = a.study(&json!({ "sources": [{ "from": format!("{}/v1/jobs/{job}", b.base) }] })).await;
    assert_eq!(study.status, 201, "{}", study.text());
    let merged = study.json()["id"].as_i64().unwrap();
    let a_export = a.moments(merged).await;
    let a_key = a_export["signature"]["key_id"].as_str().expect("A signs what it exports");
    assert_ne!(a_key, b_key);
    assert_eq!(a_export["moments"], exported["moments"], "the study holds B's statistics");

    // Edited (another solver λ claimed) and re-sealed: a valid checksum, a broken signature.
    let mut doc: optimis::sim::document::MomentsDocument = serde_json::from_value(exported.clone()).unwrap();
    doc.spec.solver.lambda = 0.5;
    let forged = serde_json::to_value(doc.sealed()).unwrap();
    let problem = assert_problem(a.study(&json!({ "sources": [forged] })).await, 422);
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.starts_with("sources[0].signature:") && detail.contains("edited"), "{detail}");
    // Unsigned: refused, saying how to trust a key.
    let mut unsigned = exported.clone();
    unsigned.as_object_mut().unwrap().remove("signature");
    let problem = assert_problem(a.study(&json!({ "sources": [unsigned.clone()] })).await, 422);
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("unsigned") && detail.contains("--trust"), "{detail}");
    // B trusts nobody: it takes the unsigned document as before.
    let target =
        b.submit_and_wait(&json!({ "iterations": 6, "light_paths": 100_000, "camera_paths": 30, "seed": 6 })).await;
    let plain = b.merge(target, &unsigned).await;
    assert_eq!(plain.status, 200, "{}", plain.text());
    // Issue 39, item 6: B signed whatever was merged into it, so an unsigned document sent to B
    // came back signed and A took it. Now a job holding statistics no trusted key vouches for is
    // exported unsigned, and A refuses it.
    let laundered = b.moments(target).await;
    assert!(laundered.get("signature").is_none(), "signed what it cannot vouch for: {}", laundered["signature"]);
    let provenance = &b.job(target).await["provenance"]["sources"];
    assert_eq!(provenance[1]["computed_here"], false);
    assert!(provenance[1].get("signed_by").is_none(), "{provenance}");
    let problem = assert_problem(a.study(&json!({ "sources": [laundered] })).await, 422);
    assert!(problem["detail"].as_str().unwrap().contains("unsigned"), "{problem}");
    // What B computed itself is signed as such; what A merged from B's signed export is signed as
    // merged, naming B's key.
    assert_eq!(exported["signature"]["attests"], json!({ "basis": "computed", "keys": [] }));
    assert_eq!(a_export["signature"]["attests"], json!({ "basis": "merged", "keys": [b_key] }));
    assert_eq!(a.job(merged).await["provenance"]["sources"][0]["signed_by"], b_key);
    // B's own signed export merged back into B: B vouches for it (its own key).
    let own =
        b.submit_and_wait(&json!({ "iterations": 6, "light_paths": 100_000, "camera_paths": 30, "seed": 7 })).await;
    let back = b.merge(own, &exported).await;
    assert_eq!(back.status, 200, "{}", back.text());
    let resigned = b.moments(own).await;
    assert_eq!(resigned["signature"]["attests"], json!({ "basis": "merged", "keys": [b_key] }));
    for server in [a, b] {
        server.stop().await;
    }
}
