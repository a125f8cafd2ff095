//! Moments written by an earlier build (format 2: seven per-path strategies, no heuristic columns)
//! keep working: their documents verify and report (rows that need what they lack say so), a job
//! started under format 2 resumes in it bit for bit, and the two formats never merge.
//!
//! A format-2 value is made by keeping exactly what format 2 kept of a format-3 run: the first
//! seven strategies' sums and the (A, B) block of ΣY and ΣYYᵀ. Exact sums do not depend on what
//! else was summed beside them, so this is bit for bit what the earlier build wrote.
//!
//! Format 3 with noise components (before issue 26: components over all of Y) is made by this
//! build itself: a job checkpointed in format 3 resumes in it, so running into an empty format-3
//! value writes what the earlier build wrote.

use std::sync::atomic::AtomicBool;

use optimis::sim::document::MomentsDocument;
use optimis::sim::runner::{run, run_iterations};
use optimis::sim::solve::predict::{Budget, predict};
use optimis::sim::solve::report::{ReportInputs, build_report};
use optimis::sim::spec::{ValidJob, parse_job_spec};
use optimis::sim::stats::components::ComponentSums;
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
    optimis::sim::stats::well_formed::check_well_formed(&old).expect("a well-formed format-2 value");
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

/// An empty format-3 value with noise components for `job` (what a job checkpointed by an earlier
/// build before its first iteration holds).
fn empty_format_3(job: &ValidJob) -> Moments {
    let mut moments = Moments::new(job.config());
    assert_eq!(moments.format_version, 4, "moments with components are format 4");
    moments.format_version = 3;
    moments.fingerprint = job.config().fingerprint_of_format(3);
    let layout = moments.layout();
    for fold in &mut moments.folds {
        fold.components = Some(ComponentSums::empty(layout));
    }
    moments
}

/// Format 4 keeps of the noise components exactly the entries a prediction reads: its sums are
/// format 3's over Y's leading n_c entries, bit for bit, the predictions at other budgets are the
/// same, moments without components are still format 3 (same fingerprint and sums as before), and
/// formats 3 and 4 with components never merge.
#[test]
fn format_4_components_are_format_3_s_over_the_predictable_prefix() {
    let doc = json!({ "preset": "paper-table1", "light_paths": 1_000_000, "iterations": 300, "seed": 5,
        "noise_components": true });
    let job = parse_job_spec(&doc).unwrap().validate().unwrap();
    let config = job.config();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let new = pool.install(|| run(config, 5, 0..300));
    let mut old = empty_format_3(&job);
    let never = AtomicBool::new(false);
    pool.install(|| run_iterations(config, 5, 0..300, &mut old, &never, |_, _| std::ops::ControlFlow::Continue(())))
        .unwrap();
    assert_eq!((old.format_version, new.format_version), (3, 4));
    optimis::sim::stats::well_formed::check_well_formed(&old).expect("a well-formed format-3 value");
    optimis::sim::stats::well_formed::check_well_formed(&new).expect("a well-formed format-4 value");

    // Everything but the components is the same, and the components agree on the prefix.
    let (n, n_c) = (new.layout().dimension(), new.layout().component_dimension());
    assert_eq!((n, n_c), (old.layout().dimension(), 2 * new.cells + 2));
    assert_eq!(old.layout().component_dimension(), n);
    for (a, b) in old.folds.iter().zip(&new.folds) {
        assert_eq!((&a.sum_y, &a.sum_yy, &a.strategies), (&b.sum_y, &b.sum_yy, &b.strategies));
        let (ca, cb) = (a.components.as_ref().unwrap(), b.components.as_ref().unwrap());
        assert_eq!(ca.strategies, cb.strategies);
        for kind in 0..3 {
            let (full, kept) = (ca.matrix(kind), cb.matrix(kind));
            assert_eq!(kept.len(), n_c * (n_c + 1) / 2);
            for i in 0..n_c {
                for j in i..n_c {
                    assert_eq!(full[packed_index(n, i, j)], kept[packed_index(n_c, i, j)], "kind {kind} ({i}, {j})");
                }
            }
            // Format 3 summed the heuristics' columns too (they are not all zero).
            assert!(
                (n_c..n)
                    .any(|j| full[packed_index(n, 0, j)].value() != 0.0 || full[packed_index(n, j, j)].value() != 0.0)
            );
        }
    }

    // Predictions at other budgets read only the prefix: the same rows and weights.
    let from = Budget { light_paths: 1_000_000, camera_paths: 100 };
    for to in
        [Budget { light_paths: 10_000_000, camera_paths: 1000 }, Budget { light_paths: 100_000, camera_paths: 10 }]
    {
        let p = |m: &Moments| predict(m, config.cells(), &job.spec().solver, from, to).unwrap();
        let (p_old, p_new) = (p(&old), p(&new));
        assert_eq!(p_old.noise_table, p_new.noise_table, "{to:?}");
        assert_eq!(p_old.weights, p_new.weights, "{to:?}");
        assert_eq!(p_old.recommended, p_new.recommended, "{to:?}");
    }

    // A format-3 document with components still verifies; the two formats never merge.
    let read = MomentsDocument::from_json(&MomentsDocument::new(job.spec().clone(), old.clone()).to_json())
        .expect("a format-3 document with components reads");
    assert_eq!(read.moments, old);
    let mut target = new.clone();
    let other = pool.install(|| run(config, 6, 0..10));
    assert!(matches!(target.merge(&old), Err(MergeError::FormatMix { found: 3, expected: 4 })));
    let mut old_target = old.clone();
    assert!(matches!(old_target.merge(&other), Err(MergeError::FormatMix { found: 4, expected: 3 })));

    // Without components nothing changed: format 3, with format 3's fingerprint.
    let plain = (**config).clone().with_noise_components(false);
    assert_eq!(Moments::new(&plain).format_version, 3);
    assert_eq!(plain.fingerprint(), plain.fingerprint_of_format(3));
}
