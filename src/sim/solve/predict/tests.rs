//! Which predicted rows a recommendation may choose from (the support limit).

use super::*;

const FROM: Budget = Budget { light_paths: 10_000_000, camera_paths: 100 };
const TO: Budget = Budget { light_paths: 10_000_000, camera_paths: 1000 };

fn row(strategy: Strategy, rms: Option<f64>, stderr: Option<f64>) -> NoiseRow {
    NoiseRow {
        rms_percent: rms,
        rms_percent_stderr: stderr,
        error: None,
        ..NoiseRow::from_sums(strategy, 0.0, 0.0, 0.0, None)
    }
}

fn table() -> Vec<NoiseRow> {
    vec![
        row(Strategy::Switch, Some(13.4), Some(4.4)), // 33% of itself: the seed-21 case
        row(Strategy::Plane3, Some(48.0), Some(12.0)), // exactly the limit: supported
        row(Strategy::Plane2, Some(80.0), None),      // no SE: not supported
        row(Strategy::OptimalCv, Some(18.2), Some(0.7)),
        NoiseRow { error: Some("cannot be predicted".into()), ..row(Strategy::CorrelationAware, None, None) },
    ]
}

#[test]
fn at_the_measured_budget_every_row_competes() {
    let rows = table();
    let (kept, left) = recommendable(&rows, FROM, FROM);
    assert_eq!(kept, rows);
    assert!(left.is_empty());
}

#[test]
fn at_another_budget_rows_without_support_are_left_out_and_named() {
    let rows = table();
    let (kept, left) = recommendable(&rows, FROM, TO);
    assert_eq!(left, vec![Strategy::Switch, Strategy::Plane2]);
    let kept: Vec<Strategy> = kept.iter().map(|r| r.strategy).collect();
    assert_eq!(kept, vec![Strategy::Plane3, Strategy::OptimalCv, Strategy::CorrelationAware]);
    let note = left_out_note(&rows, &left);
    assert!(note.contains("switch (13.4 ± 4.4%)") && note.contains("plane2 (80.0%, no SE)"), "{note}");
    assert!(note.contains("25%"), "{note}");
    assert!(left_out_note(&rows, &[]).is_empty());
}

#[test]
fn the_limit_is_inclusive_and_needs_an_error_bar() {
    assert!(supported(20.0, Some(5.0)));
    assert!(!supported(20.0, Some(5.000_001)));
    assert!(!supported(20.0, None));
}
