//! Poisson variates by inversion, in pieces of mean ≤ 16 (a sum of independent Poisson variates is
//! Poisson), so that exp(−mean) never underflows and each search stays short; the pieces can be
//! interrupted, for means in the billions.

use std::sync::atomic::{AtomicBool, Ordering};

use super::rng::{StreamRng, uniform};

/// A Poisson variate of mean `mean`: sums of inversion draws of mean ≤ 16 (a sum of independent
/// Poisson variates is Poisson), so exp(−mean) never underflows and the search stays short.
pub fn poisson(rng: &mut StreamRng, mean: f64) -> u64 {
    poisson_until(rng, mean, &AtomicBool::new(false)).expect("never cancelled")
}

/// [`poisson`] that looks at `cancel` every 4,096 pieces (a mean of 10¹⁰ takes 6·10⁸ of them) and
/// gives up with `None` once it is set. The draws are those of [`poisson`], so a run that is not
/// cancelled is bit-identical.
pub fn poisson_until(rng: &mut StreamRng, mut mean: f64, cancel: &AtomicBool) -> Option<u64> {
    let mut count = 0;
    let mut pieces = 0u64;
    while mean > 16.0 {
        count += poisson_inversion(rng, 16.0);
        mean -= 16.0;
        pieces += 1;
        if pieces.is_multiple_of(4096) && cancel.load(Ordering::Relaxed) {
            return None;
        }
    }
    Some(count + poisson_inversion(rng, mean))
}

fn poisson_inversion(rng: &mut StreamRng, mean: f64) -> u64 {
    if mean <= 0.0 {
        return 0;
    }
    let u = uniform(rng);
    let mut p = (-mean).exp();
    let mut cdf = p;
    let mut k = 0;
    // The guard ends the search once the terms underflow (a u above the rounded total mass).
    while u >= cdf && p > f64::MIN_POSITIVE {
        k += 1;
        p *= mean / k as f64;
        cdf += p;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::math::rng::stream;

    #[test]
    fn poisson_has_the_right_mean_and_variance() {
        let mut rng = stream(3, 1, 4);
        for mean in [0.05, 2.5, 40.0] {
            let n = 200_000;
            let draws: Vec<f64> = (0..n).map(|_| poisson(&mut rng, mean) as f64).collect();
            let m = draws.iter().sum::<f64>() / f64::from(n);
            let var = draws.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (f64::from(n) - 1.0);
            // Mean: standard error √(mean/n); variance: standard error ≈ mean·√(2/n) (+ tail).
            assert!((m - mean).abs() < 4.0 * (mean / f64::from(n)).sqrt(), "mean {m} vs {mean}");
            assert!((var - mean).abs() < 5.0 * mean * (2.0 / f64::from(n)).sqrt() + 0.01 * mean, "var {var} vs {mean}");
        }
    }
}
