//! `optimis figure`: Fig. 2, Table 1 and convergence drawn without a browser, as SVG, PNG and PDF.
//! PNG and PDF need a system font; without one the command says so, and these checks are skipped
//! unless OPTIMIS_REQUIRE_FONTS=1 (CI installs fonts-dejavu-core and sets it).

use std::path::Path;
use std::process::{Command, Output};

use serde_json::{Value, json};

fn optimis(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_optimis")).current_dir(dir).args(args).output().expect("optimis runs")
}

fn succeeded(out: &Output) {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Whether PNG/PDF output can be checked here: a missing font skips the checks (it fails them
/// when OPTIMIS_REQUIRE_FONTS=1).
fn fonts(out: &Output) -> bool {
    let err = String::from_utf8_lossy(&out.stderr);
    if err.contains("no fonts found") && std::env::var("OPTIMIS_REQUIRE_FONTS").is_err() {
        eprintln!("skipping the PNG/PDF checks: {err}");
        return false;
    }
    succeeded(out);
    true
}

/// A PNG's (width, height) from its IHDR chunk, after checking the signature.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "a PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |k: usize| u32::from_be_bytes(bytes[k..k + 4].try_into().unwrap());
    (be(16), be(20))
}

#[test]
fn table1_and_fig2_as_svg_png_and_pdf() {
    let dir = tempfile::tempdir().unwrap();
    succeeded(&optimis(dir.path(), &["run", "--iterations", "2000", "--quiet", "--out", "paper.json"]));
    let report: Value = {
        let out = optimis(dir.path(), &["report", "paper.json", "--json"]);
        succeeded(&out);
        serde_json::from_slice(&out.stdout).unwrap()
    };

    // Table 1: one bar per row with an RMS, the recommended one named, the paper's five values.
    succeeded(&optimis(dir.path(), &["figure", "table1", "paper.json", "--out", "table1.svg"]));
    let svg = std::fs::read_to_string(dir.path().join("table1.svg")).unwrap();
    assert!(svg.contains("Table 1 beside it") && svg.contains("2000 iterations"), "{svg:.400}");
    let recommended = report["recommended"]["strategy"].as_str().unwrap();
    assert_eq!(svg.matches("← recommended").count(), 1);
    assert!(svg.contains(&format!("{recommended} ← recommended")));
    let rows = report["noise_table"].as_array().unwrap().iter().filter(|r| r["rms_percent"].is_number()).count();
    for row in report["noise_table"].as_array().unwrap().iter().filter(|r| r["rms_percent"].is_number()) {
        assert!(svg.contains(row["strategy"].as_str().unwrap()), "{row}");
    }
    assert!(svg.contains("optimal (in-sample)"), "the in-sample row says so");
    // Bars are the only filled rectangles with opacity 0.75 apart from the three legend swatches.
    assert_eq!(svg.matches(r#"opacity="0.75""#).count(), rows + 3, "one bar per row with an RMS");
    // The paper's markers: its five cases (the optimum's needs w0 = 0, the default) and the legend's.
    assert_eq!(svg.matches("<polygon").count(), 5 + 1);

    // Another configuration: the figure says the paper's table does not apply and draws no marker.
    let out =
        optimis(dir.path(), &["run", "--iterations", "500", "--set", "scene.l3=9", "--quiet", "--out", "l3.json"]);
    succeeded(&out);
    succeeded(&optimis(dir.path(), &["figure", "table1", "l3.json", "--out", "l3.svg"]));
    let svg = std::fs::read_to_string(dir.path().join("l3.svg")).unwrap();
    assert!(svg.contains("does not apply") && !svg.contains("<polygon"), "{svg:.400}");

    // Fig. 2: the recommended row's effective weights (left), whatever its kind, and the paper's
    // in-sample table at λ = 0 (right) with every off-scale cell marked and its value written
    // (seed 3 of 10⁴ iterations fits 11 cells off the scale).
    let run = ["run", "--iterations", "10000", "--seed", "3", "--quiet", "--out", "seed3.json"];
    succeeded(&optimis(dir.path(), &run));
    succeeded(&optimis(dir.path(), &["figure", "fig2", "seed3.json", "--out", "fig2.svg"]));
    let svg = std::fs::read_to_string(dir.path().join("fig2.svg")).unwrap();
    assert!(
        svg.contains("correlation_aware_planes23: heuristic"),
        "the left panel names the recommendation: {svg:.600}"
    );
    assert!(svg.contains("effective weights") && svg.contains("not an honest estimate"), "{svg:.600}");
    let paper: Value = {
        let out = optimis(dir.path(), &["report", "seed3.json", "--weights-lambda", "0", "--json"]);
        succeeded(&out);
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let off: Vec<&Value> = paper["weights"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["status"] != "empty" && w["status"] != "uninformative")
        .filter(|w| !(-0.5..=1.5).contains(&w["w1"].as_f64().unwrap()))
        .collect();
    assert!(!off.is_empty(), "seed 3 fits some cells far off the scale at λ = 0");
    assert_eq!(svg.matches("<polygon").count(), off.len(), "one triangle per off-scale cell");
    assert!(svg.contains(&format!("{} cells off the scale", off.len())));
    for w in &off {
        assert!(svg.contains(&format!("{:.2}", w["w1"].as_f64().unwrap())), "its value is written: {w}");
    }
    // Every kind draws data: a stack and a table by name, each with its error bars.
    for (strategy, kind) in [("optimal_stacked", "stack"), ("optimal_cv", "table")] {
        let out = format!("{strategy}.svg");
        succeeded(&optimis(dir.path(), &["figure", "fig2", "paper.json", "--strategy", strategy, "--out", &out]));
        let svg = std::fs::read_to_string(dir.path().join(&out)).unwrap();
        assert!(svg.contains(&format!("{strategy}: {kind} (effective weights")), "{svg:.600}");
        assert!(svg.matches("<circle").count() > 2 * 25, "w1 and w2 of 25 bins at least: {strategy}");
    }

    // PNG at 2× by default, or --width; PDF as vector.
    let out = optimis(dir.path(), &["figure", "fig2", "paper.json", "--out", "fig2.png"]);
    if fonts(&out) {
        let png = std::fs::read(dir.path().join("fig2.png")).unwrap();
        assert_eq!(png_size(&png), (3200, 1400));
        succeeded(&optimis(dir.path(), &["figure", "table1", "paper.json", "--out", "t.png", "--width", "800"]));
        assert_eq!(png_size(&std::fs::read(dir.path().join("t.png")).unwrap()), (800, 534));
        succeeded(&optimis(dir.path(), &["figure", "fig2", "paper.json", "--out", "fig2.pdf"]));
        let pdf = std::fs::read(dir.path().join("fig2.pdf")).unwrap();
        assert!(pdf.starts_with(b"%PDF-") && pdf.len() > 1000, "a PDF");
        // Text is vector, not pixels: outlines by default, the font embedded with `pdf-text`.
        let embedded = pdf.windows(8).any(|w| w == b"FontFile");
        assert_eq!(embedded, cfg!(feature = "pdf-text"), "the font is embedded only with the pdf-text feature");
        assert!(!pdf.windows(15).any(|w| w == b"/Subtype /Image"), "no raster image in the PDF");
        if !embedded {
            // The labels' glyphs are paths: the outlined PDF is far larger than the drawing's lines alone.
            assert!(pdf.len() > 20_000, "outlined text in the PDF ({} bytes)", pdf.len());
        }
    }

    // Flags are checked and named.
    for (args, what) in [
        (vec!["--out", "x.svg", "--width", "800"], "--width"),
        (vec!["--out", "x.png", "--width", "20000"], "--width"),
        (vec!["--out", "x.gif"], "FILE.svg, FILE.png or FILE.pdf"),
        (vec!["--out", "x.svg", "--strategies", "switch"], "--strategies"),
        (vec!["--out", "x.svg", "--weights-lambda", "-1"], "--weights-lambda"),
        // The old name is an alias of the one `report` has.
        (vec!["--out", "x.svg", "--lambda", "-1"], "--weights-lambda"),
        // Table 1's fitted rows each have their own λ: a λ would change nothing, so it is refused.
        (vec!["--out", "x.svg", "--lambda", "0.1"], "applies to fig2 only"),
    ] {
        let out = optimis(dir.path(), &[&["figure", "table1", "paper.json"], &args[..]].concat());
        assert_eq!(out.status.code(), Some(3), "{args:?}: {out:?}");
        assert!(String::from_utf8_lossy(&out.stderr).contains(what), "{args:?}: {out:?}");
        assert!(!dir.path().join("x.svg").exists() && !dir.path().join("x.png").exists());
    }
}

#[test]
fn convergence_from_a_history() {
    let dir = tempfile::tempdir().unwrap();
    // A history as the server keeps it: the figures of the first 250, 500, 1000, 2000 iterations
    // of one run (the same seed: each is a prefix of the next, as checkpoints are).
    let points: Vec<Value> = [250, 500, 1000, 2000]
        .iter()
        .map(|m| {
            let n = m.to_string();
            let out = optimis(dir.path(), &["run", "--iterations", &n, "--json", "--quiet"]);
            succeeded(&out);
            let report: Value = serde_json::from_slice(&out.stdout).unwrap();
            let strategies: Vec<Value> = report["noise_table"]
                .as_array()
                .unwrap()
                .iter()
                .map(|r| json!({"strategy": r["strategy"], "luminance": r["luminance"], "rms_percent": r["rms_percent"]}))
                .collect();
            json!({"iterations": m, "strategies": strategies})
        })
        .collect();
    let history = json!({"job_id": 7, "points": points});
    std::fs::write(dir.path().join("history.json"), history.to_string()).unwrap();

    succeeded(&optimis(dir.path(), &["figure", "convergence", "history.json", "--out", "c.svg"]));
    let svg = std::fs::read_to_string(dir.path().join("c.svg")).unwrap();
    assert!(svg.contains("job 7: L ± 1 SE and RMS against iterations (4 checkpoints)"), "{svg:.300}");
    for name in ["plane1", "plane2", "plane3", "switch", "optimal_cv", "optimal_stacked", "correlation_aware_planes23"]
    {
        // Each default curve is named once, in the legend beside both panels.
        assert_eq!(svg.matches(&format!("\n{name}\n</text>")).count(), 1, "{name}");
    }
    // One SE band per curve in the L panel.
    assert_eq!(svg.matches("<polygon").count(), 7);

    succeeded(&optimis(
        dir.path(),
        &["figure", "convergence", "history.json", "--out", "two.svg", "--strategies", "switch,balance"],
    ));
    let svg = std::fs::read_to_string(dir.path().join("two.svg")).unwrap();
    assert!(svg.contains("\nbalance\n</text>") && !svg.contains("\nplane1\n</text>"));
    let out = optimis(dir.path(), &["figure", "convergence", "history.json", "--out", "c.pdf"]);
    if fonts(&out) {
        assert!(std::fs::read(dir.path().join("c.pdf")).unwrap().starts_with(b"%PDF-"));
    }

    // What cannot be drawn is named.
    let out = optimis(dir.path(), &["figure", "convergence", "history.json", "--out", "x.svg", "--strategies", "nope"]);
    assert_eq!(out.status.code(), Some(3), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains(r#"the history has no "nope""#), "{out:?}");
    let out = optimis(dir.path(), &["figure", "convergence", "history.json", "--out", "x.svg", "--lambda", "0.1"]);
    assert_eq!(out.status.code(), Some(3), "{out:?}");
    std::fs::write(dir.path().join("bad.json"), r#"{"points": 3}"#).unwrap();
    let out = optimis(dir.path(), &["figure", "convergence", "bad.json", "--out", "x.svg"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("not a job history"), "{out:?}");
    // A moments document is not a history (and a history is not a moments document).
    let out = optimis(dir.path(), &["figure", "fig2", "history.json", "--out", "x.svg"]);
    assert!(!out.status.success(), "{out:?}");
}
