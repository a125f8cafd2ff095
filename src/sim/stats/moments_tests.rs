//! Tests of the moments: exact accumulation, merges, the packed layout and their checks.

use super::*;

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
