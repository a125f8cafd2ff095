//! The dashboard in a real browser: runs `tests/browser/dashboard.mjs` (headless Chromium driven by
//! playwright-core) against a server started here, and checks the screenshots it leaves.
//!
//! Needs `node`, Chromium (`$CHROMIUM` or /usr/bin/chromium) and `npm ci --prefix tests/browser`.
//! Without them the test is skipped, unless `OPTIMIS_REQUIRE_BROWSER=1` (as in CI), where a missing
//! prerequisite fails it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::common::{TestServer, assert_problem};
use tokio::process::Command;

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
const SCREENSHOTS: [&str; 8] = [
    "list.png",
    "job-running.png",
    "job-finished.png",
    "paper-job.png",
    "compare.png",
    "sweep.png",
    "runs-table.png",
    "sweep-compare.png",
];
/// The README's screenshots, written to `$OPTIMIS_SCREENSHOT_DIR` (e.g. `docs`) when it is set.
const DOC_SCREENSHOTS: [&str; 2] = ["dashboard-job.png", "dashboard-compare.png"];
/// Their size limit, to keep the repository small.
const DOC_SCREENSHOT_LIMIT: usize = 400_000;
/// A hang guard: the script has its own limit of 240 s.
const SCRIPT_TIMEOUT: Duration = Duration::from_secs(300);

fn browser_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join("browser")
}

fn chromium() -> PathBuf {
    std::env::var_os("CHROMIUM").map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from)
}

/// What is missing to run the browser test, each with how to install it.
async fn missing_prerequisites() -> Vec<String> {
    let mut missing = Vec::new();
    let node = Command::new("node").arg("--version").output().await;
    if !node.is_ok_and(|out| out.status.success()) {
        missing.push("`node` is not on PATH (install Node.js 20 or later, e.g. `apt-get install nodejs npm`)".into());
    }
    let chromium = chromium();
    if !chromium.is_file() {
        missing.push(format!(
            "no Chromium at {} (`apt-get install chromium`, or set CHROMIUM to its path)",
            chromium.display()
        ));
    }
    if !browser_dir().join("node_modules").join("playwright-core").is_dir() {
        missing.push(
            "tests/browser/node_modules/playwright-core is not installed (`npm ci --prefix tests/browser`)".into(),
        );
    }
    missing
}

fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("screenshot {}: {e}", path.display()));
    assert!(bytes.starts_with(PNG_SIGNATURE), "{} is not a PNG file", path.display());
    assert!(bytes.len() > 10_000, "{} is only {} bytes: an empty page?", path.display(), bytes.len());
}

/// Skips (or, in CI, fails) when the browser cannot run; true when it can.
async fn browser_available() -> bool {
    let missing = missing_prerequisites().await;
    if missing.is_empty() {
        return true;
    }
    let list = missing.join("\n  - ");
    if std::env::var("OPTIMIS_REQUIRE_BROWSER").is_ok_and(|v| v == "1") {
        panic!("OPTIMIS_REQUIRE_BROWSER=1 but the browser test cannot run:\n  - {list}");
    }
    // Straight to stderr: libtest captures `eprintln!`, and a skip must show in every log.
    let note = format!(
        "skipped: the dashboard browser test needs:\n  - {list}\n(set OPTIMIS_REQUIRE_BROWSER=1 to fail instead)\n"
    );
    std::io::stderr().write_all(note.as_bytes()).unwrap();
    false
}

/// Runs the browser scenario against `server` (signing in with `token` first, if given). Without a
/// token, the README's screenshots go to `$OPTIMIS_SCREENSHOT_DIR` when it is set (relative to the
/// crate: `OPTIMIS_SCREENSHOT_DIR=docs` replaces docs/dashboard-job.png and docs/dashboard-compare.png).
async fn run_scenario(server: &TestServer, token: Option<&str>) {
    let screenshots = tempfile::tempdir().unwrap();
    let mut command = Command::new("node");
    command
        .arg(browser_dir().join("dashboard.mjs"))
        .arg(&server.base)
        .arg(screenshots.path())
        .env("CHROMIUM", chromium())
        .env_remove("OPTIMIS_TOKEN")
        .kill_on_drop(true);
    if let Some(token) = token {
        command.env("OPTIMIS_TOKEN", token);
    }
    let doc_dir = std::env::var_os("OPTIMIS_SCREENSHOT_DIR")
        .filter(|_| token.is_none())
        .map(|dir| Path::new(env!("CARGO_MANIFEST_DIR")).join(dir));
    match &doc_dir {
        Some(dir) => command.env("OPTIMIS_SCREENSHOT_DIR", dir),
        None => command.env_remove("OPTIMIS_SCREENSHOT_DIR"),
    };
    let output = tokio::time::timeout(SCRIPT_TIMEOUT, command.output())
        .await
        .expect("the browser test did not finish within 5 minutes")
        .expect("node starts");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "the browser test failed ({}):\n{stdout}\n{stderr}", output.status);
    println!("{stdout}");
    for name in SCREENSHOTS {
        assert_png(&screenshots.path().join(name));
    }
    for name in DOC_SCREENSHOTS.iter().filter(|_| doc_dir.is_some()) {
        let path = doc_dir.as_ref().unwrap().join(name);
        assert_png(&path);
        let size = std::fs::metadata(&path).unwrap().len();
        assert!(size < DOC_SCREENSHOT_LIMIT as u64, "{} is {size} bytes, over {DOC_SCREENSHOT_LIMIT}", path.display());
    }
}

/// The names of the dashboard files `text` refers to: `/assets/…` in the page, `from './….js'` in a
/// module (every import of the dashboard is a sibling file).
fn referenced_assets(text: &str) -> Vec<String> {
    let mut names = Vec::new();
    for marker in ["\"/assets/", "from './"] {
        for (start, _) in text.match_indices(marker) {
            let rest = &text[start + marker.len()..];
            let end = rest.find(['"', '\'']).expect("a closing quote");
            names.push(rest[..end].to_owned());
        }
    }
    names
}

/// Without a browser: the page and every file it loads, the script's modules followed import by
/// import from app.js, are served with their media type; an unknown name is a 404 problem.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_dashboard_file_is_served() {
    let server = TestServer::start().await;
    let page = server.get("/").await;
    assert_eq!(page.status, 200);
    let mut pending = referenced_assets(&page.text());
    assert!(pending.contains(&"app.js".to_owned()), "the page loads app.js: {pending:?}");
    let mut served = Vec::new();
    while let Some(name) = pending.pop() {
        if served.contains(&name) {
            continue;
        }
        let response = server.get(&format!("/assets/{name}")).await;
        assert_eq!(response.status, 200, "/assets/{name}");
        let media_type = response.header("content-type").unwrap().to_owned();
        let body = response.text();
        if name.ends_with(".js") {
            assert_eq!(media_type, "text/javascript; charset=utf-8", "/assets/{name}");
            pending.extend(referenced_assets(&body));
        } else {
            assert_eq!(media_type, "text/css; charset=utf-8", "/assets/{name}");
        }
        served.push(name);
    }
    served.sort();
    let expected = [
        "api.js",
        "app.css",
        "app.js",
        "axes.js",
        "budget.js",
        "budgetplan.js",
        "chartfiles.js",
        "chartkit.js",
        "chartsvg.js",
        "compare.js",
        "csv.js",
        "csvtables.js",
        "errorplan.js",
        "fig2.js",
        "form.js",
        "format.js",
        "job.js",
        "list.js",
        "noisetable.js",
        "paper.js",
        "plots.js",
        "radiitable.js",
        "results.js",
        "solves.js",
        "specfields.js",
        "sweep.js",
        "sweepdata.js",
        "sweepplots.js",
        "sweeps.js",
        "sweepw1.js",
        "uPlot.iife.min.js",
        "uPlot.min.css",
    ];
    assert_eq!(served, expected, "the files the page loads");
    for name in ["nope.js", "app.JS", "..%2Fapp.js"] {
        let problem = assert_problem(server.get(&format!("/assets/{name}")).await, 404);
        assert!(problem["detail"].as_str().unwrap().contains("no dashboard file"), "{name}: {problem}");
    }
    // No folders under /assets/.
    assert_problem(server.get("/assets/js/app.js").await, 404);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_works_in_a_browser() {
    if !browser_available().await {
        return;
    }
    let server = TestServer::start().await;
    run_scenario(&server, None).await;
    server.stop().await;
}

/// The same scenario on a server that requires a token: the page asks for it once, then every
/// call and the live event stream carry it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_works_with_a_token() {
    if !browser_available().await {
        return;
    }
    const TOKEN: &str = "dashboard-token-0123456789";
    let server = TestServer::start_with(|c| c.token = Some(optimis::api::BearerToken(TOKEN.into()))).await;
    run_scenario(&server, Some(TOKEN)).await;
    server.stop().await;
}
