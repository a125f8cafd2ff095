//! Published figures served (issue 25, item 2): the paper's Table 1 is data in `references/`,
//! listed by `GET /v1/references`, attached to `/result` (and the noise CSV) of a job whose
//! configuration is the paper's, and printed by `optimis run --paper`; and the CLI's errors name
//! what is wrong (item 8): a flag, a moments document, the fields in which two merged runs
//! differ.

use std::process::Command;

use crate::common::{TestServer, assert_problem};
use serde_json::{Value, json};

fn optimis(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir)
        .args(args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .expect("optimis runs")
}

fn file_table() -> Value {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/references/ershov2020-table1.json"));
    serde_json::from_str(&text.unwrap()).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_papers_table_is_served_where_it_applies() {
    let server = TestServer::start().await;
    // The list is the repository's file, as it is.
    let listed = server.get_json("/v1/references").await;
    assert_eq!(listed["references"], json!([file_table()]));

    let paper = server.submit_and_wait(&json!({ "preset": "paper-table1", "iterations": 300, "seed": 4 })).await;
    let result = server.result(paper).await;
    let references = result["references"].as_array().unwrap();
    assert_eq!(references.len(), 1, "{result}");
    assert_eq!(references[0]["id"], "ershov2020-table1");
    let rows: Vec<&str> =
        references[0]["rows"].as_array().unwrap().iter().map(|r| r["strategy"].as_str().unwrap()).collect();
    assert_eq!(rows, ["plane1", "plane2", "plane3", "switch", "optimal"]);
    // The CSV carries the published figures on the rows that have them, and nothing on others.
    let csv = server.get(&format!("/v1/jobs/{paper}/result?format=csv")).await.text();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let (l, r) = (
        header.iter().position(|c| *c == "paper_luminance").unwrap(),
        header.iter().position(|c| *c == "paper_rms_percent").unwrap(),
    );
    let cells = |strategy: &str| -> (String, String) {
        let line = csv.lines().find(|line| line.starts_with(&format!("{strategy},"))).unwrap();
        let cells: Vec<&str> = line.split(',').collect();
        (cells[l].to_string(), cells[r].to_string())
    };
    assert_eq!(cells("switch"), ("0.00026352".to_string(), "61".to_string()));
    assert_eq!(cells("optimal_cv"), (String::new(), String::new()));
    // With w0 freed the optimum's published row no longer applies; the fixed cases still do.
    let solved = server.solve(paper, &json!({ "fixed": { "w0": null } })).await.json();
    assert_eq!(solved["references"][0]["rows"].as_array().unwrap().len(), 4, "{solved}");

    // The noise table for a paper: Markdown, and LaTeX that compiles (pdflatex in CI, where
    // OPTIMIS_REQUIRE_LATEX=1 makes its absence a failure).
    let md = server.get(&format!("/v1/jobs/{paper}/result?format=markdown")).await;
    assert_eq!(md.header("content-type"), Some("text/markdown; charset=utf-8"));
    assert!(md.text().contains("| `switch` |") && md.text().contains("| 26.352 |"), "{}", md.text());
    // Issue 42, item 8: every row (18 and the in-sample one) fits an article's text width — no
    // overfull box —, under a caption, the recommended row marked, the paper's figures with z.
    let tex = server.get(&format!("/v1/jobs/{paper}/result?format=latex")).await.text();
    assert!(
        tex.contains("optimal\\_\\allowbreak cv") && tex.contains("\\end{tabular}") && tex.contains("\\caption{"),
        "{tex}"
    );
    let recommended =
        server.result(paper).await["recommended"]["strategy"].as_str().unwrap().replace('_', "\\_\\allowbreak ");
    assert!(tex.contains(&format!("\\textbf{{{recommended}}}*")), "the recommended row is marked: {tex}");
    assert!(tex.contains("& $z$ &") && tex.contains("Paper RMS"), "{tex}");
    compiles(&tex);
    // Chosen rows, in the order given, under one's own caption (escaped); the bare tabular too.
    let chosen = server
        .get(&format!(
            "/v1/jobs/{paper}/result?format=latex&rows=optimal_cv,switch&caption=Paper%20scene%2C%2050%25%20%26%20more"
        ))
        .await
        .text();
    let names: Vec<&str> = chosen
        .lines()
        .filter(|l| l.contains(" & ") && !l.starts_with("Strategy"))
        .map(|l| l.split(" & ").next().unwrap())
        .collect();
    assert_eq!(names.len(), 2, "{chosen}");
    assert!(names[0].contains("optimal\\_\\allowbreak cv") && names[1].contains("switch"), "{chosen}");
    assert!(chosen.contains("\\caption{Paper scene, 50\\% \\& more}"), "{chosen}");
    compiles(&chosen);
    let bare = server.get(&format!("/v1/jobs/{paper}/result?format=latex&bare=true")).await.text();
    assert!(!bare.contains("\\begin{table}") && bare.ends_with("\\end{tabular}\n}\n"), "{bare}");
    compiles(&bare);
    for (query, field) in [
        ("format=latex&rows=nonsense", "rows"),
        ("format=latex&rows=plane1,plane1x", "rows"),
        ("rows=switch", "rows"),
        ("format=csv&caption=x", "caption"),
    ] {
        let problem = assert_problem(server.get(&format!("/v1/jobs/{paper}/result?{query}")).await, 422);
        assert_eq!(problem["field"], field, "{query}: {problem}");
    }
    assert_problem(server.get(&format!("/v1/jobs/{paper}/result?format=latex&table=weights")).await, 422);

    // Another illumination: not the paper's figures.
    let uniform =
        server.submit_and_wait(&json!({ "preset": "uniform-illumination", "iterations": 300, "seed": 4 })).await;
    assert_eq!(server.result(uniform).await["references"], json!([]));
    server.stop().await;
}

#[test]
fn the_cli_prints_the_paper_column_and_names_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let out = optimis(dir.path(), &["run", "--preset", "paper-table1", "--iterations", "1e3", "--paper"]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("paper L·10⁵") && text.contains("paper RMS"), "{text}");
    let switch = text.lines().find(|l| l.starts_with("switch ")).unwrap();
    assert!(switch.contains("26.352") && switch.contains(" 61 "), "{switch}");
    // Another configuration: the table says why the paper's figures are not shown.
    let out =
        optimis(dir.path(), &["run", "--iterations", "200", "--set", "scene.l3=9", "--paper", "--out", "l3.json"]);
    assert!(out.status.success(), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stdout)
            .contains("does not apply: this configuration differs in scene.l3: 9.0 vs 3.0")
    );

    // A flag is named as a flag, not as a job specification.
    let out = optimis(dir.path(), &["budget", "l3.json", "--target-rms", "-1"]);
    assert_eq!(out.status.code(), Some(3), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("invalid argument --target-rms") && !err.contains("job specification"), "{err}");
    // A document that cannot serve the command is named, with why.
    let out = optimis(dir.path(), &["predict", "l3.json", "--light-paths", "1e8"]);
    assert_eq!(out.status.code(), Some(3), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("optimis: l3.json: ") && !err.contains("job specification"), "{err}");

    // A merge of two configurations names the fields that differ.
    let out = optimis(dir.path(), &["run", "--iterations", "200", "--seed", "2", "--out", "l3-paper.json"]);
    assert!(out.status.success(), "{out:?}");
    // The paper's Fig. 2 without a browser: the recommendation's effective weights beside the
    // in-sample table at λ = 0, the spot's edge marked in both (tests/figures.rs checks the data).
    let out = optimis(dir.path(), &["figure", "fig2", "l3-paper.json", "--out", "fig2.svg"]);
    assert!(out.status.success(), "{out:?}");
    let svg = std::fs::read_to_string(dir.path().join("fig2.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("w1 against r3"), "{svg:.300}");
    assert_eq!(svg.matches("r3 = a = 0.02").count(), 2, "the spot's edge in both panels");
    assert!(svg.contains("effective weights") && svg.contains("fitted in-sample at λ = 0"), "{svg:.600}");
    assert!(svg.matches(r#"r="4""#).count() > 52, "w1 and w2 of every bin with light, and the table's cells");

    let out = optimis(dir.path(), &["merge", "l3-paper.json", "l3.json", "--out", "merged.json"]);
    assert_eq!(out.status.code(), Some(4), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("scene.l3: 9.0 vs 3.0"), "{err}");
}

/// Compiles `table` inside a minimal document with pdflatex, if it is installed (required when
/// OPTIMIS_REQUIRE_LATEX=1, as in CI).
fn compiles(table: &str) {
    let dir = tempfile::tempdir().unwrap();
    let document = format!("\\documentclass{{article}}\n\\begin{{document}}\n{table}\\end{{document}}\n");
    std::fs::write(dir.path().join("table.tex"), document).unwrap();
    let run = Command::new("pdflatex")
        .current_dir(dir.path())
        .args(["-interaction=nonstopmode", "-halt-on-error", "table.tex"])
        .output();
    match run {
        Ok(out) => {
            let log = String::from_utf8_lossy(&out.stdout);
            assert!(out.status.success(), "pdflatex refused the table:\n{log}");
            assert!(dir.path().join("table.pdf").exists());
            assert!(!log.contains("Overfull"), "the table overflows the text width:\n{log}");
        }
        Err(e) => {
            assert!(std::env::var("OPTIMIS_REQUIRE_LATEX").is_err(), "pdflatex is required here: {e}");
            eprintln!("pdflatex not installed ({e}): the LaTeX table's compilation is checked in CI");
        }
    }
}

/// Issue 42: one citation of the paper, from the reference file that `--paper`, the dashboard
/// (GET /v1/references) and the Python example's figures come from, word for word in the README,
/// docs/model.md and the Python example, and printed by the CLI; the wrong author list and title
/// that stood in the reference file are nowhere.
#[test]
fn one_citation_of_the_paper_everywhere() {
    let source = file_table()["source"].as_str().unwrap().to_string();
    let citation = source.strip_suffix(", section 5, Table 1").expect("the source cites the table");
    assert!(
        citation.starts_with(
            "S. V. Ershov, A. G. Voloboy, D. D. Zhdanov, A. D. Zhdanov, V. A. Frolov, \"Direct calculation of the \
             optimal weight for MIS\", GraphiCon 2020"
        ),
        "{citation}"
    );
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    // Line breaks inside a paragraph are spaces.
    let text =
        |path: &str| std::fs::read_to_string(root.join(path)).unwrap().split_whitespace().collect::<Vec<_>>().join(" ");
    for path in ["README.md", "docs/model.md", "examples/python/paper_table1.py"] {
        assert!(text(path).contains(citation), "{path} does not cite the paper as {citation}");
    }
    let mut elsewhere =
        vec!["references/ershov2020-table1.json".to_string(), "README.md".into(), "docs/model.md".into()];
    elsewhere.extend(["examples/python/paper_table1.py", "src/lib.rs", "src/api/mod.rs"].map(String::from));
    for entry in std::fs::read_dir(root.join("src/api/dashboard")).unwrap() {
        elsewhere.push(format!("src/api/dashboard/{}", entry.unwrap().file_name().to_string_lossy()));
    }
    for path in elsewhere.iter().filter(|p| !p.ends_with("vendor")) {
        let t = text(path);
        assert!(!t.contains("Galaktionov") && !t.contains("Direct optimal MIS weights"), "{path} cites another paper");
    }
    let dir = tempfile::tempdir().unwrap();
    let out = optimis(dir.path(), &["run", "--preset", "paper-table1", "--iterations", "20", "--paper", "--quiet"]);
    assert!(out.status.success(), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stdout).contains(&source), "the CLI prints the citation");
}
