//! The README as a test (issue 15): every command block runs as written against a fresh server, in
//! order, or — where it needs a cluster, another machine or minutes of CPU — is marked
//! `<!-- readme-test: syntax-only (why) -->` on the line before it and checked for syntax
//! (`bash -n`; YAML parsed). The JSON blocks parse, and the job specification block is
//! `examples/specs/paper-table1.json`, which resolves to exactly the `paper-table1` preset.
//!
//! Substitutions, the only ones: `localhost:8080` is the test server's address and
//! `cargo run --release --` the binary under test. Blocks run with `bash -euo pipefail` in a
//! temporary directory that sees the repository's `examples/`, one after the other as in one
//! terminal: the (lowercase) shell variables a block sets, such as `$job` from a `Location`
//! header, are there in the next. After each block the test waits until no job is queued or
//! running, so that the next block reads finished jobs as a reader would; a block that needs a
//! job to have ended waits for it itself (`optimis wait`), or the sweep's table below would be
//! short of rows.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::TestServer;
use serde_json::Value;

/// One fenced block of the README.
struct Block {
    line: usize,
    lang: String,
    text: String,
    /// The reason given by a `syntax-only` marker.
    syntax_only: Option<String>,
}

fn blocks(readme: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut previous = "";
    let mut open: Option<Block> = None;
    for (i, line) in readme.lines().enumerate() {
        if let Some(block) = open.as_mut() {
            if line == "```" {
                out.push(open.take().unwrap());
            } else {
                block.text.push_str(line);
                block.text.push('\n');
            }
            continue;
        }
        if let Some(lang) = line.strip_prefix("```") {
            let syntax_only = previous
                .strip_prefix("<!-- readme-test: syntax-only")
                .map(|rest| rest.trim_end_matches("-->").trim().to_string());
            open = Some(Block { line: i + 1, lang: lang.to_string(), text: String::new(), syntax_only });
        }
        if !line.trim().is_empty() {
            previous = line;
        }
    }
    assert!(open.is_none(), "an unclosed code block");
    out
}

/// Runs before each block: the variables the previous blocks set.
const CARRY_IN: &str = "if [ -f .readme-vars ]; then . ./.readme-vars; fi\n";

/// Runs after each block: keeps its lowercase variables (bash's own are upper case) for the next.
const CARRY_OUT: &str = "\nREADME_VARS=$(compgen -v | grep -E '^[a-z][a-z0-9_]*$' || true)\n\
     if [ -n \"$README_VARS\" ]; then declare -p $README_VARS > .readme-vars; fi\n";

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

async fn quiet(server: &TestServer) {
    for _ in 0..1200 {
        let busy = ["queued", "running"].iter().map(|s| format!("?state={s}")).collect::<Vec<_>>();
        let mut any = false;
        for q in &busy {
            any |= !server.list(q).await.is_empty();
        }
        if !any {
            return;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("jobs still running after 120 s");
}

fn bash(dir: &Path, script: &str, check_only: bool) -> std::process::Output {
    let mut command = Command::new("bash");
    if check_only {
        command.arg("-n");
    }
    command.args(["-euo", "pipefail", "-c", script]).current_dir(dir);
    command.env_remove("SLURM_ARRAY_TASK_ID").env_remove("JOB_COMPLETION_INDEX").env_remove("OPTIMIS_TOKEN");
    command.output().expect("bash runs")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_readme_block_runs_as_written_or_is_marked_and_checked() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let blocks = blocks(&readme);
    let server = TestServer::start_with(|c| c.policy.checkpoint_iterations = 1000).await;
    let address = server.base.trim_start_matches("http://").to_string();
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(repo().join("examples"), dir.path().join("examples")).unwrap();
    let binary = env!("CARGO_BIN_EXE_optimis");
    let (mut ran, mut checked) = (0, 0);
    for b in &blocks {
        let at = format!("README.md:{} ({})", b.line, b.lang);
        match (b.lang.as_str(), &b.syntax_only) {
            ("sh", None) => {
                let script = b.text.replace("localhost:8080", &address).replace("cargo run --release --", binary);
                let script = format!("{CARRY_IN}{script}{CARRY_OUT}");
                let output = bash(dir.path(), &script, false);
                assert!(
                    output.status.success(),
                    "{at} failed:\n{}\nstdout: {}\nstderr: {}",
                    b.text,
                    String::from_utf8_lossy(&output.stdout),
                    String::from_utf8_lossy(&output.stderr)
                );
                // A curl that met an error answers a problem document: none of the README's do.
                let stdout = String::from_utf8_lossy(&output.stdout);
                assert!(!stdout.contains("\"type\":\"urn:problem-type"), "{at} got a problem: {stdout}");
                quiet(&server).await;
                ran += 1;
            }
            ("sh", Some(why)) => {
                assert!(!why.is_empty(), "{at}: a syntax-only marker says why");
                let output = bash(dir.path(), &b.text, true);
                assert!(output.status.success(), "{at}: {}", String::from_utf8_lossy(&output.stderr));
                checked += 1;
            }
            ("json", _) => {
                let value: Value = serde_json::from_str(&b.text).unwrap_or_else(|e| panic!("{at}: {e}"));
                let file: Value = serde_json::from_str(
                    &std::fs::read_to_string(repo().join("examples/specs/paper-table1.json")).unwrap(),
                )
                .unwrap();
                assert_eq!(value, file, "{at} is examples/specs/paper-table1.json");
                let spec = optimis::sim::spec::parse_job_spec(&value).unwrap();
                let preset = optimis::sim::spec::parse_job_spec(&serde_json::json!({})).unwrap();
                assert_eq!(spec, preset, "{at} resolves to exactly the paper-table1 preset");
                checked += 1;
            }
            ("yaml", Some(_)) => {
                let _: yaml_serde::Value = yaml_serde::from_str(&b.text).unwrap_or_else(|e| panic!("{at}: {e}"));
                checked += 1;
            }
            (lang, marker) => panic!("{at}: a {lang:?} block the test does not know how to check ({marker:?})"),
        }
    }
    assert!(ran >= 8 && checked >= 10, "ran {ran}, checked {checked}");
    // What the blocks left behind is what they promise.
    for file in ["sweep.csv", "study-merged.json", "noise.csv", "comp.json", "moments.json"] {
        assert!(dir.path().join(file).exists(), "{file} was not written");
    }
    let sweep = std::fs::read_to_string(dir.path().join("sweep.csv")).unwrap();
    // 9 points, each with every honest row (the in-sample `optimal` is not among them).
    let column = sweep.lines().next().unwrap().split(',').position(|c| c == "strategy").expect("a strategy column");
    let mut per_strategy = std::collections::BTreeMap::<&str, usize>::new();
    for line in sweep.lines().skip(1) {
        *per_strategy.entry(line.split(',').nth(column).unwrap()).or_default() += 1;
    }
    assert!(per_strategy.values().all(|&n| n == 9), "9 points × each strategy: {per_strategy:?}");
    for honest in ["switch", "optimal_cv", "optimal_stacked", "correlation_aware_planes23"] {
        assert!(per_strategy.contains_key(honest), "{per_strategy:?}");
    }
    assert!(!per_strategy.contains_key("optimal"), "in-sample rows are not in a sweep's table");
    server.stop().await;
}
