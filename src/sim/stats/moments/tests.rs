//! Tests of the moments: exact accumulation, merges, the packed layout and their checks.

use super::*;
use crate::sim::stats::well_formed::check_well_formed;

#[test]
fn packed_index_enumerates_the_upper_triangle() {
    for n in [1, 2, 5, 9] {
        let mut expected = 0;
        for i in 0..n {
            for j in i..n {
                assert_eq!(packed_index(n, i, j), expected, "n={n} i={i} j={j}");
                expected += 1;
            }
        }
        assert_eq!(expected, packed_len(n));
    }
}

/// Moments of the two-fold format 1 (written before K-fold cross-fitting) are refused, and the
/// message says why and what to do; so are fold counts outside [2, 20] and coverage that does not
/// match the folds.
#[test]
fn old_formats_and_foreign_fold_layouts_are_refused() {
    let spec = crate::sim::spec::parse_job_spec(&serde_json::json!({ "folds": 3 })).unwrap();
    let config = spec.validate().unwrap().config().clone();
    let mut old = Moments::new(&config);
    old.format_version = 1;
    let message = check_well_formed(&old).unwrap_err().to_string();
    assert!(message.contains("format 1") && message.contains("K folds") && message.contains("again"), "{message}");
    let mut one_fold = Moments::new(&config);
    one_fold.folds.truncate(1);
    assert!(matches!(check_well_formed(&one_fold), Err(MergeError::Malformed(_))));
    let mut other = Moments::new(&config);
    other.coverage.insert(1, 0, 1); // iteration 0 belongs to fold 0, which counts none
    let message = check_well_formed(&other).unwrap_err().to_string();
    assert!(message.contains("≡ 0 (mod 3)"), "{message}");
}
