//! The headless path of a study on a batch cluster: shards run with `optimis run --shard`, merged
//! with `optimis merge`, reported with `optimis report` — equal to a single run.

use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;

fn optimis(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_optimis"));
    command.current_dir(dir).args(args).env_remove("SLURM_ARRAY_TASK_ID").env_remove("JOB_COMPLETION_INDEX");
    for (k, v) in env {
        command.env(k, v);
    }
    command.output().expect("optimis runs")
}

fn ok(output: Output) -> Vec<u8> {
    assert!(output.status.success(), "optimis failed: {}", String::from_utf8_lossy(&output.stderr));
    output.stdout
}

#[test]
fn four_shards_merged_equal_a_single_run() {
    let dir = tempfile::tempdir().unwrap();
    let spec = r#"{"light_paths": 40000, "camera_paths": 200, "merge_radius": 0.02, "iterations": 22, "seed": 8}"#;
    std::fs::write(dir.path().join("job.json"), spec).unwrap();
    for k in 0..4 {
        let shard = format!("{k}/4");
        let out = format!("shard-{k}.json");
        ok(optimis(dir.path(), &["run", "--spec", "job.json", "--shard", &shard, "--out", &out, "--json"], &[]));
    }
    // The scheduler's index: Slurm arrays (here numbered from 1) and Kubernetes indexed Jobs.
    ok(optimis(
        dir.path(),
        &["run", "--spec", "job.json", "--out", "slurm.json", "--json"],
        &[("SLURM_ARRAY_TASK_ID", "2"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "4")],
    ));
    ok(optimis(
        dir.path(),
        &["run", "--spec", "job.json", "--out", "k8s.json", "--shard-count", "4", "--json"],
        &[("JOB_COMPLETION_INDEX", "3")],
    ));
    let read = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    assert_eq!(read("slurm.json"), read("shard-1.json"));
    assert_eq!(read("k8s.json"), read("shard-3.json"));

    ok(optimis(
        dir.path(),
        &["merge", "shard-2.json", "shard-0.json", "shard-3.json", "shard-1.json", "--out", "study.json"],
        &[],
    ));
    let study_report: Value =
        serde_json::from_slice(&ok(optimis(dir.path(), &["report", "study.json", "--json"], &[]))).unwrap();
    let single_report: Value = serde_json::from_slice(&ok(optimis(
        dir.path(),
        &["run", "--spec", "job.json", "--out", "single.json", "--json"],
        &[],
    )))
    .unwrap();
    assert_eq!(study_report, single_report, "the merged report equals the single run's");
    let study: Value = serde_json::from_slice(&read("study.json")).unwrap();
    let single: Value = serde_json::from_slice(&read("single.json")).unwrap();
    assert_eq!(study["moments"], single["moments"], "merged moments are bit-identical to the single run's");
    assert_eq!(study_report["iterations"], 22);

    // Double counting, foreign configurations and corrupted files are refused.
    let refused = optimis(dir.path(), &["merge", "shard-0.json", "study.json", "--out", "bad.json"], &[]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("already counted"));
    let text = String::from_utf8(read("shard-0.json")).unwrap();
    let at = text.find("\"sum_yy\":[").unwrap();
    let pos = text[at..].find(|c: char| c.is_ascii_digit() && c != '0').unwrap() + at;
    let mut corrupted = text.into_bytes();
    corrupted[pos] = if corrupted[pos] == b'9' { b'1' } else { corrupted[pos] + 1 };
    std::fs::write(dir.path().join("corrupted.json"), corrupted).unwrap();
    let refused = optimis(dir.path(), &["report", "corrupted.json"], &[]);
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("checksum"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
    assert!(!dir.path().join("bad.json").exists());

    // A report with other solver options: they change the rows fitted at the spec's λ; the weights
    // table is the recommended one unless a λ is asked for.
    let tables =
        String::from_utf8(ok(optimis(dir.path(), &["report", "study.json", "--solver", r#"{"lambda": 0.5}"#], &[])))
            .unwrap();
    assert!(tables.contains("λ = 0.5, in-sample (optimistic)"), "{tables}");
    // The recommendation's table, or — a per-path strategy recommended — why it has none.
    assert!(tables.contains("recommended weights (") || tables.contains("it has no table"), "{tables}");
    let in_sample =
        String::from_utf8(ok(optimis(dir.path(), &["report", "study.json", "--weights-lambda", "0.5"], &[]))).unwrap();
    assert!(in_sample.contains("weights fitted on all iterations at λ = 0.5"), "{in_sample}");
}

/// `optimis bench` reports the restricted engine on one thread beside its rate on all of them (the
/// figures themselves are timings: only their consistency is checked, never a wall-clock bound).
#[test]
fn bench_reports_the_parallel_speed_up() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["bench", "--engine", "restricted", "--iterations", "1", "--light-paths", "100000", "--threads", "2"];
    let out: Value = serde_json::from_slice(&ok(optimis(dir.path(), &[&args[..], &["--json"]].concat(), &[]))).unwrap();
    let scaling = &out["restricted_scaling"];
    let (one, two) = (
        scaling["iterations_per_second_1_thread"].as_f64().unwrap(),
        scaling["iterations_per_second"].as_f64().unwrap(),
    );
    assert_eq!(scaling["threads"], 2);
    assert_eq!(two, out["engines"][0]["iterations_per_second"].as_f64().unwrap());
    assert!(one > 0.0 && (scaling["speed_up"].as_f64().unwrap() - two / one).abs() < 1e-9 * two / one);
    assert!((scaling["efficiency"].as_f64().unwrap() - two / one / 2.0).abs() < 1e-9);
    let text = String::from_utf8(ok(optimis(dir.path(), &args, &[]))).unwrap();
    assert!(text.contains("restricted on 1 thread:") && text.contains("parallel efficiency"), "{text}");
    // One thread: nothing to compare.
    let one: Value = serde_json::from_slice(&ok(optimis(
        dir.path(),
        &[
            "bench",
            "--engine",
            "restricted",
            "--iterations",
            "1",
            "--light-paths",
            "100000",
            "--threads",
            "1",
            "--json",
        ],
        &[],
    )))
    .unwrap();
    assert!(one["restricted_scaling"].is_null());
}

/// `optimis bench | head -1` and friends: the reader closing the pipe is not an error (exit 0, no
/// panic message). The pipe's read end is closed before the child starts, so every write fails.
#[test]
fn a_reader_that_leaves_early_is_not_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let commands: [&[&str]; 3] = [
        &["bench", "--engine", "brute", "--iterations", "1", "--light-paths", "1000"],
        &["bench", "--engine", "brute", "--iterations", "1", "--light-paths", "1000", "--json"],
        &["run", "--preset", "paper-table1", "--iterations", "2", "--json"],
    ];
    for args in commands {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let output = Command::new(env!("CARGO_BIN_EXE_optimis"))
            .current_dir(dir.path())
            .args(args)
            .stdout(writer)
            .stderr(std::process::Stdio::piped())
            .output()
            .expect("optimis runs");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "optimis {args:?} failed on a closed pipe: {stderr}");
        assert!(!stderr.contains("panicked"), "optimis {args:?} panicked: {stderr}");
    }
}

/// `--out` and the CSV flags write *to* a pipe or a device, and through a symbolic link, instead
/// of renaming a new file over them (which, run as root, replaced /dev/null by a regular file).
/// The pipe is a FIFO in a temporary directory, read by a thread; the link keeps being a link.
#[test]
fn outputs_write_through_pipes_and_links_without_replacing_them_and_failures_leave_no_litter() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("moments.fifo");
    assert!(Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs").success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap())
    };
    let run = ["run", "--preset", "paper-table1", "--iterations", "2", "--quiet"];
    ok(optimis(dir.path(), &[&run[..], &["--out", "moments.fifo"]].concat(), &[]));
    // Before joining: a FIFO replaced by a file would leave the reader waiting for a writer.
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo(), "the FIFO is still a FIFO");
    let piped: Value = serde_json::from_slice(&reader.join().unwrap()).expect("the document came through the pipe");
    assert!(piped["moments"].is_object(), "a moments document");

    std::fs::write(dir.path().join("real.csv"), "old").unwrap();
    std::os::unix::fs::symlink("real.csv", dir.path().join("link.csv")).unwrap();
    ok(optimis(dir.path(), &[&run[..], &["--csv", "link.csv"]].concat(), &[]));
    assert!(dir.path().join("link.csv").is_symlink(), "the link is still a link");
    let csv = std::fs::read_to_string(dir.path().join("real.csv")).unwrap();
    assert!(csv.starts_with("strategy,"), "the file behind the link has the table: {csv}");
    // `--out /dev/stdout` with the output redirected to a file: the document goes through the
    // stream, followed by the report (a rename would replace the file and lose the report).
    let redirected = dir.path().join("stdout.txt");
    let status = Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir.path())
        .args(run)
        .args(["--out", "/dev/stdout"])
        .stdout(std::fs::File::create(&redirected).unwrap())
        .status()
        .expect("optimis runs");
    assert!(status.success());
    let both = std::fs::read_to_string(&redirected).unwrap();
    let mut values = serde_json::Deserializer::from_str(&both).into_iter::<Value>();
    let document = values.next().expect("a document").expect("the document comes first, whole");
    let document_end = values.byte_offset();
    assert!(document["moments"].is_object());
    assert!(both[document_end..].contains("strategy"), "the report follows the document: {}", &both[document_end..]);
    // A write that fails (a directory cannot be replaced by a file) says so and leaves no
    // temporary file behind.
    std::fs::create_dir(dir.path().join("taken.csv")).unwrap();
    let failed = optimis(dir.path(), &[&run[..], &["--csv", "taken.csv"]].concat(), &[]);
    assert!(!failed.status.success(), "writing over a directory must fail");
    assert!(String::from_utf8_lossy(&failed.stderr).contains("taken.csv"), "the error names the file");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.contains("partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// Issue 11, item 1 on the command line: a poisoned document made `report` and `merge` loop
/// forever. Now they fail at once, naming the file and the sum. (The hang guard is the CI timeout
/// of the whole suite: a loop would never return.)
#[test]
fn poisoned_documents_fail_report_and_merge() {
    let dir = tempfile::tempdir().unwrap();
    let spec = r#"{"light_paths": 20000, "camera_paths": 100, "merge_radius": 0.02, "iterations": 4, "seed": 8,
        "cells": {"r2_edges": [0, 0.5], "r3_edges": [0, 0.01]}}"#;
    std::fs::write(dir.path().join("job.json"), spec).unwrap();
    ok(optimis(dir.path(), &["run", "--spec", "job.json", "--out", "good.json", "--json"], &[]));
    let mut doc: Value = serde_json::from_slice(&std::fs::read(dir.path().join("good.json")).unwrap()).unwrap();
    doc["moments"]["folds"][0]["sum_y"][0] = serde_json::json!([1.7976931348623157e308, 1.7976931348623157e308]);
    std::fs::write(dir.path().join("poisoned.json"), doc.to_string()).unwrap();
    for args in [&["report", "poisoned.json"][..], &["merge", "good.json", "poisoned.json", "--out", "m.json"][..]] {
        let output = optimis(dir.path(), args, &[]);
        assert!(!output.status.success(), "{args:?} must fail");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains("poisoned.json") && stderr.contains("2^1000"), "{args:?}: {stderr}");
    }
}

/// Issue 11, item 14: a short token was reported as an "invalid job specification"; a token file
/// readable by other users was accepted silently; and "listening" was logged before the database
/// opened (a server that could not open it had already announced itself).
#[test]
fn serve_refuses_bad_secrets_and_announces_itself_only_when_ready() {
    let dir = tempfile::tempdir().unwrap();
    let short = optimis(dir.path(), &["serve", "--bind", "127.0.0.1:0", "--token", "short"], &[]);
    assert!(!short.status.success());
    let stderr = String::from_utf8_lossy(&short.stderr);
    assert!(stderr.contains("invalid configuration") && stderr.contains("--token"), "{stderr}");
    assert!(!stderr.contains("job specification"), "{stderr}");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let file = dir.path().join("token");
        std::fs::write(&file, "a-long-enough-token-for-the-test").unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o644)).unwrap();
        let open = optimis(dir.path(), &["serve", "--bind", "127.0.0.1:0", "--token-file", "token"], &[]);
        assert!(!open.status.success());
        let stderr = String::from_utf8_lossy(&open.stderr);
        assert!(stderr.contains("chmod 600"), "{stderr}");
    }
    let database = format!("sqlite://{}/missing/dir/x.db", dir.path().display());
    let unopenable = optimis(dir.path(), &["serve", "--bind", "127.0.0.1:0", "--database", &database], &[]);
    assert!(!unopenable.status.success());
    let stderr = String::from_utf8_lossy(&unopenable.stderr);
    assert!(!stderr.contains("optimis listening"), "announced before the database opened: {stderr}");
    assert!(stderr.contains("database"), "{stderr}");
}

/// Issue 14: `optimis predict` and `optimis budget` on a run with noise components. The budget
/// plan with given costs: every strategy's best point is at least as fast as any other point of
/// the same strategy, and the paper's configuration is reported beside them.
#[test]
fn predict_and_budget_read_a_run_with_noise_components() {
    let dir = tempfile::tempdir().unwrap();
    let spec = r#"{"preset": "paper-table1", "light_paths": 1000000, "camera_paths": 20, "noise_components": true, "iterations": 3000, "seed": 2}"#;
    std::fs::write(dir.path().join("job.json"), spec).unwrap();
    ok(optimis(dir.path(), &["run", "--spec", "job.json", "--out", "comp.json", "--json"], &[]));
    let text = String::from_utf8(ok(optimis(
        dir.path(),
        &["predict", "comp.json", "--light-paths", "2000000", "--camera-paths", "10"],
        &[],
    )))
    .unwrap();
    assert!(text.contains("predicted for N_F = 2000000") && text.contains("cross-fitted"), "{text}");
    assert!(text.contains("recommended at this budget: "), "{text}");
    let plan: Value = serde_json::from_slice(&ok(optimis(
        dir.path(),
        &["budget", "comp.json", "--light-cost", "1e-8", "--camera-cost", "1e-6", "--iteration-cost", "0.01", "--json"],
        &[],
    )))
    .unwrap();
    assert_eq!(plan["paper"]["strategy"], "switch");
    assert_eq!(plan["paper"]["budget"]["light_paths"], 10_000_000);
    let points = plan["points"].as_array().unwrap();
    // The search starts a decade each way and widens by half decades: a grid of half-decade steps
    // over the range it reports, at least 5 × 5.
    let steps = |axis: &str| {
        let [lo, hi] = [0, 1].map(|i| plan["search"][axis][i].as_f64().unwrap());
        (2.0 * (hi / lo).log10()).round() as usize + 1
    };
    let (light_steps, camera_steps) = (steps("light_paths"), steps("camera_paths"));
    assert!(light_steps >= 5 && camera_steps >= 5, "{}", plan["search"]);
    assert_eq!(points.iter().filter(|p| p["strategy"] == "plane1").count(), light_steps * camera_steps);
    // The run's recommendation is headlined unless its weights depend on the budget (then the
    // stacked optimum, with a note that says why).
    let recommended = plan["recommended"].as_str().unwrap();
    if recommended.starts_with("correlation_aware") {
        assert_eq!(plan["headline"], "optimal_stacked");
        assert!(plan["headline_note"].as_str().unwrap().contains(recommended), "{}", plan["headline_note"]);
    } else {
        assert_eq!(plan["headline"], recommended);
        assert!(plan["headline_note"].is_null());
    }
    // Each strategy's best is its fastest point among those the run supports (RMS SE ≤ 25% of the
    // RMS); faster unsupported points are said to exist; with none supported, its fastest point.
    let limit = plan["support_relative_se"].as_f64().unwrap();
    assert_eq!(limit, 0.25);
    let supported =
        |p: &Value| p["rms_percent_stderr"].as_f64().is_some_and(|se| se <= limit * p["rms_percent"].as_f64().unwrap());
    let mut left_aside = 0;
    for best in plan["best"].as_array().unwrap() {
        let t = best["seconds_to_target"].as_f64().unwrap();
        let mine: Vec<&Value> = points.iter().filter(|p| p["strategy"] == best["strategy"]).collect();
        assert_eq!(best["supported"], supported(best), "{best}");
        let faster = mine.iter().filter(|p| p["seconds_to_target"].as_f64().unwrap() < t).collect::<Vec<_>>();
        if best["supported"] == true {
            assert!(faster.iter().all(|p| !supported(p)), "{best}");
            assert_eq!(best["faster_unsupported"], !faster.is_empty(), "{best}");
            left_aside += faster.len();
        } else {
            assert!(faster.is_empty() && mine.iter().all(|p| !supported(p)), "{best}");
        }
        let expected = best["seconds_per_iteration"].as_f64().unwrap()
            * (best["rms_percent"].as_f64().unwrap() / 1.0).powi(2).max(1.0);
        assert!((t - expected).abs() <= 1e-9 * t, "time = iterations × seconds per iteration");
    }
    // The guard has something to do at this run's length (far budgets are predicted from 3,000
    // iterations), and the ranking puts the supported strategies first among those ranked.
    assert!(left_aside > 0, "no faster unsupported point in {}", plan["best"]);
    // The fixed-time curve: T is the paper's time; each ratio's point is a supported grid point's
    // R·√(t/T), the lowest of its strategy's supported points at that ratio.
    let fixed = &plan["fixed_time"];
    let big_t = fixed["seconds"].as_f64().unwrap();
    assert_eq!(big_t, plan["paper"]["seconds_to_target"].as_f64().unwrap());
    let curve = fixed["curve"].as_array().unwrap();
    assert!(curve.iter().filter(|c| c["strategy"] == "plane1").count() < light_steps + camera_steps, "{curve:?}");
    let at_t =
        |p: &Value| p["rms_percent"].as_f64().unwrap() * (p["seconds_per_iteration"].as_f64().unwrap() / big_t).sqrt();
    let ratio = |p: &Value| {
        (p["budget"]["light_paths"].as_f64().unwrap() / p["budget"]["camera_paths"].as_f64().unwrap()).log10()
    };
    for c in curve {
        let same = |p: &&Value| {
            p["strategy"] == c["strategy"]
                && (ratio(p) - c["ratio"].as_f64().unwrap().log10()).abs() < 0.05
                && supported(p)
        };
        let kept = points.iter().filter(same).find(|p| p["budget"] == c["budget"]).expect("a grid point");
        let rms = c["rms_percent"].as_f64().unwrap();
        assert!((rms - at_t(kept)).abs() <= 1e-9 * rms);
        assert!(points.iter().filter(same).all(|p| at_t(p) >= rms * (1.0 - 1e-12)));
    }
    for p in points.iter().filter(|p| supported(p)) {
        assert!(
            curve
                .iter()
                .any(|c| c["strategy"] == p["strategy"]
                    && (ratio(p) - c["ratio"].as_f64().unwrap().log10()).abs() < 0.05),
            "a supported point's ratio is on the curve: {p}"
        );
    }
    let missing = optimis(dir.path(), &["predict", "job.json"], &[]);
    assert!(!missing.status.success());
}

/// Issue 15's conventions: `--set` overrides any field, progress lines on a non-terminal stderr
/// (`--quiet` silences them), CSV tables beside the JSON, errors that name the input at fault and
/// exit codes that tell bad input, conflicts and I/O apart.
#[test]
fn set_progress_csv_and_exit_codes() {
    let dir = tempfile::tempdir().unwrap();
    let run = [
        "run",
        "--preset",
        "paper-table1",
        "--iterations",
        "400",
        "--set",
        "scene.l3=9",
        "--set",
        "solver.fixed.w0=null",
        "--progress-seconds",
        "0.1",
        "--json",
        "--csv",
        "noise.csv",
        "--weights-csv",
        "weights.csv",
        "--out",
        "a.json",
    ];
    let output = optimis(dir.path(), &run, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr).to_string();
    let report: Value = serde_json::from_slice(&ok(output)).unwrap();
    assert!(stderr.contains("optimis: 400 iterations done in"), "a final progress line: {stderr}");
    let doc: Value = serde_json::from_slice(&std::fs::read(dir.path().join("a.json")).unwrap()).unwrap();
    assert_eq!(doc["spec"]["scene"]["l3"], 9.0);
    assert!(doc["spec"]["solver"]["fixed"].get("w0").is_none(), "null removes the fixed w0");
    // The CSV tables hold the JSON's figures.
    let noise = std::fs::read_to_string(dir.path().join("noise.csv")).unwrap();
    let lines: Vec<&str> = noise.lines().collect();
    // docs/csv.md's vocabulary, in its order.
    assert!(
        lines[0].starts_with("strategy,paper_case,luminance,luminance_stderr,expected_luminance,z,"),
        "{}",
        lines[0]
    );
    assert_eq!(lines.len(), 1 + report["noise_table"].as_array().unwrap().len());
    let column = |name: &str| lines[0].split(',').position(|c| c == name).unwrap();
    let switch = report["noise_table"].as_array().unwrap().iter().find(|r| r["strategy"] == "switch").unwrap();
    let row: Vec<&str> = lines.iter().find(|l| l.starts_with("switch,")).unwrap().split(',').collect();
    assert_eq!(row[column("rms_percent")].parse::<f64>().unwrap(), switch["rms_percent"].as_f64().unwrap());
    assert_eq!(row[column("z")].parse::<f64>().unwrap(), switch["z"].as_f64().unwrap());
    assert_eq!(row[column("paper_case")], "4", "switch is the paper's case 4 (whether or not its figures apply)");
    let recommended = report["recommended"]["strategy"].as_str().unwrap();
    let chosen: Vec<&str> =
        lines[1..].iter().copied().filter(|l| l.split(',').nth(column("recommended")) == Some("true")).collect();
    assert!(chosen.len() == 1 && chosen[0].starts_with(&format!("{recommended},")), "{chosen:?}");
    let same_weights = |csv: &str, report: &Value| {
        let weights = std::fs::read_to_string(dir.path().join(csv)).unwrap();
        let rows = report["weights"].as_array().unwrap();
        if rows.is_empty() {
            // A per-path recommendation has no table: its effective weights, labelled, one row per
            // (r2, r3) bin — never an empty file.
            // (The paper's grid: 2 r2 bins × 26 r3 bins, one φ bin.)
            assert_eq!(weights.lines().count(), 1 + 52);
            let recommended = report["recommended"]["strategy"].as_str().unwrap();
            for line in weights.lines().skip(1) {
                let cells: Vec<&str> = line.split(',').collect();
                assert_eq!(cells.len(), 23, "{line}");
                assert_eq!((cells[0], cells[1], cells[2]), ("effective", recommended, "heuristic"), "{line}");
                // A heuristic over planes 2–3: w0 = 0 and w1 + w2 = 1 wherever a path carries light.
                if let (Ok(w0), Ok(w1), Ok(w2)) =
                    (cells[10].parse::<f64>(), cells[12].parse::<f64>(), cells[14].parse::<f64>())
                {
                    assert!(w0 == 0.0 && (w1 + w2 - 1.0).abs() < 1e-12, "{line}");
                }
            }
            return;
        }
        assert_eq!(weights.lines().count(), 1 + rows.len());
        for (line, w) in weights.lines().skip(1).zip(rows) {
            let cells: Vec<&str> = line.split(',').collect();
            assert_eq!(cells.len(), 18, "{line}");
            assert_eq!(cells[1], report["weights_fit"]["strategy"].as_str().unwrap(), "which table it is");
            assert_eq!(cells[17], w["status"].as_str().unwrap(), "statuses as the JSON writes them");
            assert_eq!(cells[12].parse::<f64>().unwrap(), w["w1"].as_f64().unwrap());
        }
    };
    same_weights("weights.csv", &report);
    // A per-path strategy recommended has no table (its weights are the heuristic's); a fitted
    // row's table is asked for by λ.
    assert_eq!(report["weights"].as_array().unwrap().is_empty(), report["recommended"]["lambda"].is_null());
    let args = ["report", "a.json", "--weights-lambda", "0.1", "--weights-of", "optimal_stacked", "--json"];
    let args = [&args[..], &["--weights-csv", "stacked.csv"]].concat();
    let stacked: Value = serde_json::from_slice(&ok(optimis(dir.path(), &args, &[]))).unwrap();
    assert_eq!(stacked["weights"].as_array().unwrap().len(), 52);
    assert_eq!(stacked["weights_fit"]["strategy"], "optimal_stacked");
    same_weights("stacked.csv", &stacked);
    let quiet =
        optimis(dir.path(), &["run", "--preset", "paper-table1", "--iterations", "50", "--quiet", "--json"], &[]);
    assert!(quiet.status.success() && quiet.stderr.is_empty(), "{}", String::from_utf8_lossy(&quiet.stderr));

    // Exit codes: 3 bad input (naming the field), 4 a conflict (naming the input at fault), 5 I/O.
    let bad = optimis(dir.path(), &["run", "--set", "scene.l4=1"], &[]);
    assert_eq!(bad.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("scene.l4"));
    ok(optimis(
        dir.path(),
        &["run", "--preset", "paper-table1", "--iterations", "20", "--quiet", "--out", "b.json"],
        &[],
    ));
    let conflict = optimis(dir.path(), &["merge", "b.json", "a.json", "--out", "m.json"], &[]);
    assert_eq!(conflict.status.code(), Some(4));
    // The merge names the input at fault and the configuration fields that differ (a.json has
    // l3 = 9; both keep the preset's engine and cells).
    let stderr = String::from_utf8_lossy(&conflict.stderr);
    assert!(stderr.starts_with("optimis: a.json: the statistics were drawn under another configuration"), "{stderr}");
    assert!(stderr.contains("scene.l3: 9.0 vs 3.0"), "{stderr}");
    let overlap = optimis(dir.path(), &["merge", "b.json", "b.json", "--out", "m.json"], &[]);
    assert_eq!(overlap.status.code(), Some(4));
    let missing = optimis(dir.path(), &["report", "missing.json"], &[]);
    assert_eq!(missing.status.code(), Some(5));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("missing.json"));
}

/// What a cluster task does (`optimis serve --executor slurm`): a shard of [f, f + M) whose
/// document path holds `{shard}`, resumed from the partial document an interrupted attempt left —
/// the same bytes as an uninterrupted run; a document of another run is refused, not resumed.
#[test]
fn a_task_resumes_its_shard_from_its_partial_document() {
    let dir = tempfile::tempdir().unwrap();
    let spec = r#"{"light_paths": 40000, "camera_paths": 200, "merge_radius": 0.02, "iterations": 24, "first_iteration": 100, "seed": 8}"#;
    std::fs::write(dir.path().join("job.json"), spec).unwrap();
    let read = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    // Shard 1 of 3 of [100, 124) is [108, 116).
    ok(optimis(
        dir.path(),
        &["run", "--spec", "job.json", "--shard", "1/3", "--out", "task-{shard}.json", "--json"],
        &[],
    ));
    let whole: Value = serde_json::from_slice(&read("task-1.json")).unwrap();
    assert_eq!(whole["coverage"], serde_json::json!([{ "seed": 8, "ranges": [[108, 116]] }]));
    // An attempt interrupted after 3 iterations left [108, 111).
    let first3 = ["--set", "first_iteration=108", "--set", "iterations=3"];
    ok(optimis(
        dir.path(),
        &[&["run", "--spec", "job.json", "--out", "resumed-1.json", "--json"][..], &first3].concat(),
        &[],
    ));
    let resume = [
        "run",
        "--spec",
        "job.json",
        "--shard",
        "1/3",
        "--out",
        "resumed-{shard}.json",
        "--resume",
        "--checkpoint-seconds",
        "0.1",
        "--json",
    ];
    ok(optimis(dir.path(), &resume, &[]));
    assert_eq!(read("resumed-1.json"), read("task-1.json"), "a resumed task is bit-identical to an uninterrupted one");
    // Nothing to resume from: a fresh start.
    ok(optimis(
        dir.path(),
        &["run", "--spec", "job.json", "--shard", "1/3", "--out", "fresh-{shard}.json", "--resume", "--json"],
        &[],
    ));
    assert_eq!(read("fresh-1.json"), read("task-1.json"));
    // Another seed's document in its place: refused, and left as it was.
    ok(optimis(
        dir.path(),
        &[&["run", "--spec", "job.json", "--out", "other-1.json", "--set", "seed=9", "--json"][..], &first3].concat(),
        &[],
    ));
    let before = read("other-1.json");
    let refused = optimis(
        dir.path(),
        &["run", "--spec", "job.json", "--shard", "1/3", "--out", "other-{shard}.json", "--resume"],
        &[],
    );
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("--resume"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
    assert_eq!(read("other-1.json"), before);
}

/// Counts on the command line read as the JSON API reads them (`1e4`), and a negative one is
/// refused naming the flag, not taken for an unknown option.
#[test]
fn counts_take_the_json_forms_and_negative_ones_name_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let run = |counts: [&str; 3], out: &str| {
        let args = ["run", "--iterations", counts[0], "--light-paths", counts[1], "--camera-paths", counts[2]];
        let rest = ["--set", "merge_radius=0.02", "--out", out, "--quiet"];
        ok(optimis(dir.path(), &[&args[..], &rest].concat(), &[]));
        std::fs::read(dir.path().join(out)).unwrap()
    };
    assert_eq!(run(["2e1", "2e4", "1e2"], "short.json"), run(["20", "20000", "100"], "plain.json"));
    let negative = optimis(dir.path(), &["run", "--iterations", "-5"], &[]);
    assert!(!negative.status.success());
    let stderr = String::from_utf8_lossy(&negative.stderr);
    assert!(stderr.contains("--iterations") && stderr.contains("non-negative whole number"), "{stderr}");
}

/// Issue 42: an interrupted run exited silently. Now Ctrl-C (SIGINT) stops it after its batch,
/// keeps its iterations in --out, says so with how to continue, and exits with 130; `--resume`
/// then gives the document an uninterrupted run writes, byte for byte.
#[test]
fn an_interrupted_run_keeps_its_iterations_and_says_how_to_resume() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["run", "--preset", "paper-table1", "--iterations", "60000", "--seed", "9", "--quiet"];
    let mut child = Command::new(env!("CARGO_BIN_EXE_optimis"))
        .current_dir(dir.path())
        .args(args)
        .args(["--out", "cut.json", "--checkpoint-seconds", "0.1"])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Interrupted once it has written its first checkpoint (it has iterations to keep).
    while !dir.path().join("cut.json").exists() {
        assert!(child.try_wait().unwrap().is_none(), "the run ended before it could be interrupted");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let killed = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(
        stderr.contains("interrupted at ") && stderr.contains("of 60000 iterations; they are in cut.json"),
        "{stderr}"
    );
    assert!(stderr.contains("--resume"), "{stderr}");
    ok(optimis(dir.path(), &[&args[..], &["--out", "cut.json", "--resume"]].concat(), &[]));
    ok(optimis(dir.path(), &[&args[..], &["--out", "whole.json"]].concat(), &[]));
    let (cut, whole) =
        (std::fs::read(dir.path().join("cut.json")).unwrap(), std::fs::read(dir.path().join("whole.json")).unwrap());
    assert!(cut == whole, "the resumed run's document is the uninterrupted run's");
}
