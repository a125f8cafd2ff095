//! The recommendation acted on in one run (issue 21), checked from outside: each seed's result is
//! scored on an independent long run of another seed — what a researcher's renderer would get —
//! with the same `evaluate` a user calls. A smaller version of docs/results.md §10 (30 seeds ×
//! 10⁴ iterations against 10⁶): 8 seeds × 2000 iterations against 10⁵.
//!
//! * no recommended row delivers more noise than the paper's hand-tuned switch on the long run;
//! * the reported RMS of every honest fitted row (and of the recommended one) covers what its
//!   weights deliver within 2.5 reported standard errors in at least 80% of seeds;
//! * the stacked optimum contains `correlation_aware_planes23`: in sample its variance is never
//!   larger.

use optimis::sim::runner::run;
use optimis::sim::solve::evaluate::{GivenCell, GivenHeuristic, GivenWeights, evaluate};
use optimis::sim::solve::noise::noise_table;
use optimis::sim::solve::report::weight_rows;
use optimis::sim::spec::{ValidJob, parse_job_spec};
use serde_json::json;

fn job(seed: u64, iterations: u64) -> ValidJob {
    let doc = json!({ "preset": "paper-table1", "iterations": iterations, "seed": seed });
    parse_job_spec(&doc).unwrap().validate().unwrap()
}

fn pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap()
}

#[test]
fn the_recommendation_delivers_what_it_reports_on_an_independent_run() {
    let long_job = job(1000, 100_000);
    let config = &long_job.config();
    let long = pool().install(|| run(config, 1000, 0..100_000));
    let switch_delivered = {
        let given = GivenWeights { recommended: Some(named("switch")), ..GivenWeights::default() };
        evaluate(&long, config.cells(), &given, &Default::default()).unwrap().evaluated.rms_percent.unwrap()
    };
    let (mut covered, mut scored) = (0, 0);
    for seed in 1..=8 {
        let short = job(seed, 2000);
        let moments = pool().install(|| run(short.config(), seed, 0..2000));
        let table = noise_table(&moments, short.config().cells(), &short.spec().solver);
        let recommended = table.recommended.as_ref().expect("a recommendation");
        // Every honest fitted row, and the recommended row, scored on the long run.
        let mut rows: Vec<(String, f64, f64, GivenWeights)> = Vec::new();
        for f in &table.fitted {
            let row = table.rows.iter().find(|r| r.strategy == f.strategy).unwrap();
            let (Some(rms), Some(se)) = (row.rms_percent, row.rms_percent_stderr) else { continue };
            let cells = weight_rows(short.config().cells(), &f.scored.all, None)
                .into_iter()
                .map(|w| GivenCell { r2: w.r2, r3: w.r3, phi: w.phi, w0: w.w0, w1: w.w1, w2: w.w2 })
                .collect();
            let heuristics = f
                .scored
                .all
                .heuristics
                .iter()
                .map(|&(h, beta)| GivenHeuristic {
                    strategy: optimis::sim::solve::strategy::Strategy::of_path(h),
                    beta,
                })
                .collect();
            rows.push((
                f.strategy.name().into(),
                rms,
                se,
                GivenWeights { weights: cells, heuristics, ..Default::default() },
            ));
        }
        let chosen = table.rows.iter().find(|r| r.strategy == recommended.strategy).unwrap();
        if recommended.fitted.is_none() {
            let given =
                GivenWeights { recommended: Some(named(recommended.strategy.name())), ..GivenWeights::default() };
            rows.push((
                recommended.strategy.name().into(),
                chosen.rms_percent.unwrap(),
                chosen.rms_percent_stderr.unwrap(),
                given,
            ));
        }
        for (name, rms, se, given) in &rows {
            let delivered =
                evaluate(&long, config.cells(), given, &Default::default()).unwrap().evaluated.rms_percent.unwrap();
            let inside = (rms - delivered).abs() <= 2.5 * se;
            eprintln!(
                "seed {seed}: {name:<40} reported {rms:6.2} ± {se:5.2}, delivered {delivered:6.2} {}",
                if inside { "" } else { "(outside 2.5 SE)" }
            );
            scored += 1;
            covered += usize::from(inside);
            if name == recommended.strategy.name() {
                assert!(
                    delivered <= switch_delivered,
                    "seed {seed}: the recommended {name} delivers {delivered:.2}%, worse than switch's {switch_delivered:.2}%"
                );
            }
        }
        // In sample, the stacked family's variance is at most that of any member (its penalty is
        // zero on a constant table): the standard deviation, RMS × |L|.
        let std_of = |name: &str| {
            let r = table.rows.iter().find(|r| r.strategy.name() == name).unwrap();
            match (r.in_sample_rms_percent, r.in_sample_luminance) {
                (Some(rms), Some(l)) => rms * l.abs(),
                _ => r.rms_percent.unwrap() * r.luminance.unwrap().abs(),
            }
        };
        let (stacked, heuristic) = (std_of("optimal_stacked"), std_of("correlation_aware_planes23"));
        assert!(
            stacked <= heuristic * (1.0 + 1e-6),
            "seed {seed}: stacked in sample {stacked} vs the heuristic it contains {heuristic}"
        );
    }
    eprintln!(
        "{covered} of {scored} reported RMS within 2.5 SE of the delivered; switch delivers {switch_delivered:.2}%"
    );
    assert!(covered * 10 >= scored * 8, "{covered} of {scored} covered");
}

/// The weights a table's recommendation hands to a renderer, as `evaluate` takes them.
fn recommended_weights(table: &optimis::sim::solve::noise::NoiseTable, job: &ValidJob) -> GivenWeights {
    let recommended = table.recommended.as_ref().expect("a recommendation");
    match recommended.fit() {
        None => GivenWeights { recommended: Some(named(recommended.strategy.name())), ..GivenWeights::default() },
        Some(fit) => GivenWeights {
            weights: weight_rows(job.config().cells(), fit, None)
                .into_iter()
                .map(|w| GivenCell { r2: w.r2, r3: w.r3, phi: w.phi, w0: w.w0, w1: w.w1, w2: w.w2 })
                .collect(),
            heuristics: fit
                .heuristics
                .iter()
                .map(|&(h, beta)| GivenHeuristic {
                    strategy: optimis::sim::solve::strategy::Strategy::of_path(h),
                    beta,
                })
                .collect(),
            ..Default::default()
        },
    }
}

/// Issue 40: outside the paper's preset a short run could recommend weights several times noisier
/// than the heuristic beside them while reporting them better. At merge radius 0.01, seeds 44, 56
/// and 60 of 10⁴ iterations recommended fits that moved plane-3 merges in the bright spot to
/// w2 ≈ 1.1 (and plane 2 to −0.7): on this independent 10⁵-iteration run they delivered 74.5%,
/// 40.1% and 81.9% RMS where `correlation_aware_planes23` delivers 20.4% (docs/results.md §18).
/// Trusted only within 0.25 of that heuristic's weights, every recommendation stays within 10% of
/// what the heuristic delivers, and its reported RMS covers what it delivers within 2.5 SE.
#[test]
fn outside_the_preset_a_short_run_never_recommends_a_gamble() {
    let at = |seed: u64, iterations: u64| {
        let doc = json!({ "preset": "paper-table1", "merge_radius": 0.01, "iterations": iterations, "seed": seed });
        parse_job_spec(&doc).unwrap().validate().unwrap()
    };
    let long_job = at(1_000_003, 100_000);
    let config = long_job.config();
    let long = pool().install(|| run(config, 1_000_003, 0..100_000));
    let anchor = GivenWeights { recommended: Some(named("correlation_aware_planes23")), ..GivenWeights::default() };
    let anchor_delivered =
        evaluate(&long, config.cells(), &anchor, &Default::default()).unwrap().evaluated.rms_percent.unwrap();
    for seed in [44, 56, 60] {
        let short = at(seed, 10_000);
        let moments = pool().install(|| run(short.config(), seed, 0..10_000));
        let table = noise_table(&moments, short.config().cells(), &short.spec().solver);
        let recommended = table.recommended.as_ref().unwrap();
        let row = table.rows.iter().find(|r| r.strategy == recommended.strategy).unwrap();
        let (reported, se) = (row.rms_percent.unwrap(), row.rms_percent_stderr.unwrap());
        let delivered = evaluate(&long, config.cells(), &recommended_weights(&table, &short), &Default::default())
            .unwrap()
            .evaluated
            .rms_percent
            .unwrap();
        eprintln!(
            "seed {seed}: {} reported {reported:.2} ± {se:.2}, delivered {delivered:.2}; the heuristic delivers {anchor_delivered:.2}",
            recommended.strategy
        );
        assert!(
            delivered <= 1.10 * anchor_delivered,
            "seed {seed}: {} delivers {delivered:.2}%, more than 10% above correlation_aware_planes23's {anchor_delivered:.2}%",
            recommended.strategy
        );
        assert!(
            (reported - delivered).abs() <= 2.5 * se,
            "seed {seed}: reported {reported:.2} ± {se:.2}, delivered {delivered:.2}"
        );
    }
}

/// The recommendation of a per-path strategy, as a result document names it.
fn named(strategy: &str) -> optimis::sim::solve::evaluate::GivenRecommendation {
    serde_json::from_value(json!({ "strategy": strategy })).unwrap()
}

/// Issue 40: with ten camera paths an iteration (merge radius 0.005), one run of 10⁴ iterations
/// (seed 8) showed `balance_planes23` at 41.6 ± 0.3% RMS — the lowest per-path row by far — and it
/// was recommended; on a long run it delivers 446% (docs/results.md §18): the run lacked the rare
/// plane-3 events in the spot that carry its variance. Its L says so: 22.6 standard errors below
/// its exact expectation at R (the quadrature, an analytic value). Such a row is marked
/// `tail_missing`, warned about, and passed over for `correlation_aware_planes23`.
#[test]
fn a_per_path_row_missing_its_tail_is_not_recommended() {
    use optimis::sim::checks::references::expected_luminances;
    use optimis::sim::solve::noise::noise_table_with;
    use optimis::sim::solve::strategy::Strategy;
    let doc =
        json!({ "preset": "paper-table1", "merge_radius": 0.005, "camera_paths": 10, "iterations": 10_000, "seed": 8 });
    let job = parse_job_spec(&doc).unwrap().validate().unwrap();
    let config = job.config();
    let moments = pool().install(|| run(config, 8, 0..10_000));
    let expected = pool().install(|| expected_luminances(config));
    let table = noise_table_with(&moments, config.cells(), &job.spec().solver, Some(&expected));
    let row = |s: Strategy| table.rows.iter().find(|r| r.strategy == s).unwrap();
    let balance = row(Strategy::BalancePlanes23);
    let (z, rms) = (balance.z.unwrap(), balance.rms_percent.unwrap());
    eprintln!("balance_planes23: RMS {rms:.1}%, z = {z:.1}");
    assert!(balance.tail_missing && z < -10.0, "z = {z}");
    assert!(rms < row(Strategy::CorrelationAwarePlanes23).rms_percent.unwrap(), "it looks the best per-path row");
    assert!(!row(Strategy::CorrelationAwarePlanes23).tail_missing);
    let recommended = table.recommended.as_ref().unwrap();
    assert_eq!(recommended.strategy, Strategy::CorrelationAwarePlanes23, "{}", recommended.reason);
    let warnings = optimis::sim::solve::warnings::warnings(&moments, &table);
    assert!(
        warnings.iter().any(|w| w.code == optimis::sim::solve::warnings::WarningCode::TailMissing
            && w.strategy == Some(Strategy::BalancePlanes23)),
        "{warnings:?}"
    );
}
