//! Moments written by an earlier build (format 2: seven per-path strategies, no heuristic columns)
//! keep working: their documents verify and report (rows that need what they lack say so), a job
//! started under format 2 resumes in it bit for bit, and the two formats never merge.
//!
//! A format-2 value is made by keeping exactly what format 2 kept of a format-3 run: the first
//! seven strategies' sums and the (A, B) block of ΣY and ΣYYᵀ. Exact sums do not depend on what
//! else was summed beside them, so this is bit for bit what the earlier build wrote.

use std::sync::atomic::AtomicBool;

use optimis::sim::document::MomentsDocument;
use optimis::sim::runner::{run, run_iterations};
use optimis::sim::solve::report::{ReportInputs, build_report};
use optimis::sim::spec::{ValidJob, parse_job_spec};
use optimis::sim::stats::moments::{MergeError, Moments, packed_index};
use serde_json::json;

fn job() -> ValidJob {
    let doc = json!({ "preset": "paper-table1", "light_paths": 1_000_000, "iterations": 400, "seed": 7 });
    parse_job_spec(&doc).unwrap().validate().unwrap()
}

/// What format 2 kept of format-3 moments.
fn as_format_2(moments: &Moments, job: &ValidJob) -> Moments {
    let mut old = moments.clone();
    let k = moments.cells;
    let (n_old, n_new) = (2 * k + 1, moments.layout().dimension());
    old.format_version = 2;
    old.fingerprint = job.config().fingerprint_of_format(2);
    for fold in &mut old.folds {
        fold.sum_y.truncate(n_old);
        let full = std::mem::take(&mut fold.sum_yy);
        for i in 0..n_old {
            for j in i..n_old {
                fold.sum_yy.push(full[packed_index(n_new, i, j)].clone());
            }
        }
        fold.strategies.truncate(7);
        assert!(fold.components.is_none());
    }
    old.check_well_formed().expect("a well-formed format-2 value");
    old
}

#[test]
fn format_2_documents_report_and_refuse_to_merge_with_format_3() {
    let job = job();
    let config = &job.config();
    let new = run(config, 7, 0..400);
    let old = as_format_2(&new, &job);

    // The document an earlier build wrote verifies with its format's fingerprint.
    let doc = MomentsDocument::new(job.spec().clone(), old.clone());
    let read = MomentsDocument::from_json(&doc.to_json()).expect("a format-2 document reads");
    assert_eq!(read.moments, old);

    // Its report: the rows format 2 kept are the very figures of the format-3 run; the rest say why
    // they are missing.
    let inputs = ReportInputs::default();
    let (r_old, r_new) = (
        build_report(&old, config.cells(), &job.spec().solver, &inputs),
        build_report(&new, config.cells(), &job.spec().solver, &inputs),
    );
    let row = |r: &optimis::sim::solve::report::RunReport, name: &str| {
        r.noise_table.iter().find(|x| x.strategy.name() == name).unwrap().clone()
    };
    for name in ["plane1", "plane2", "plane3", "switch", "balance", "power", "correlation_aware"] {
        assert_eq!(row(&r_old, name), row(&r_new, name), "{name}");
    }
    // The table's fits read the same (A, B) sums; only the length of the vectors they are read
    // from differs, which may move the last bits of a matrix product.
    for name in ["optimal", "optimal_holdout", "optimal_cv"] {
        let (a, b) = (row(&r_old, name), row(&r_new, name));
        let close = |x: Option<f64>, y: Option<f64>| (x.unwrap() - y.unwrap()).abs() <= 1e-9 * y.unwrap().abs();
        assert!(close(a.luminance, b.luminance) && close(a.rms_percent, b.rms_percent), "{name}: {a:?} vs {b:?}");
    }
    for name in ["correlation_aware_planes23", "optimal_stacked"] {
        let row = r_old.noise_table.iter().find(|x| x.strategy.name() == name).unwrap();
        assert!(row.luminance.is_none() && row.error.as_deref().is_some_and(|e| e.contains("format 2")), "{row:?}");
    }
    assert!(r_old.recommended.is_some(), "a format-2 run still gets a recommendation");

    // The formats never merge, whichever way round.
    let mut target = new.clone();
    let other = run(config, 8, 0..10);
    assert!(matches!(target.merge(&as_format_2(&other, &job)), Err(MergeError::FormatMix { found: 2, expected: 3 })));
    let mut old_target = old.clone();
    assert!(matches!(old_target.merge(&other), Err(MergeError::FormatMix { found: 3, expected: 2 })));
    // Two format-2 values merge as they always did.
    old_target.merge(&as_format_2(&other, &job)).expect("format 2 merges with format 2");
}

/// A job checkpointed under format 2 and resumed by this build continues in format 2: the result
/// is bit for bit the format-2 value of one uninterrupted run.
#[test]
fn a_format_2_checkpoint_resumes_in_format_2() {
    let job = job();
    let config = &job.config();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let mut resumed = as_format_2(&run(config, 7, 0..150), &job);
    let cancel = AtomicBool::new(false);
    pool.install(|| {
        run_iterations(config, 7, 150..400, &mut resumed, &cancel, |_, _| std::ops::ControlFlow::Continue(()))
    })
    .unwrap();
    let whole = as_format_2(&pool.install(|| run(config, 7, 0..400)), &job);
    assert_eq!(resumed, whole);
    assert_eq!(resumed.format_version, 2);
}
