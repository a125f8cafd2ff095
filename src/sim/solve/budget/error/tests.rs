//! The error plan's arithmetic: merges scaled to a budget, and the progressive schedule.

use super::*;

fn knot(radius: f64, rms: f64, bias: f64, seconds: f64) -> Knot {
    Knot { radius, variance: rms * rms, relative_se: 0.01, bias, seconds }
}

#[test]
fn merges_scale_with_the_light_paths_and_the_pairs() {
    let measured = Budget { light_paths: 1000, camera_paths: 10 };
    let to = Budget { light_paths: 4000, camera_paths: 30 };
    // Plane 1 ∝ N_F (×4), planes 2 and 3 ∝ N_F·N_B (×12).
    assert_eq!(merges_at([1.0, 2.0, 3.0], measured, to), 4.0 + 5.0 * 12.0);
    assert_eq!(merges_at([1.0, 2.0, 3.0], measured, measured), 6.0);
}

#[test]
fn a_schedule_at_one_radius_needs_what_a_fixed_radius_needs() {
    // Equal knots: the schedule is a fixed radius, n = σ²/(P² − b²) iterations.
    let (rms, bias, target) = (10.0, 0.6, 1.0);
    let knots = [knot(0.01, rms, bias, 2.0), knot(0.02, rms, bias, 2.0)];
    let (n, seconds) = schedule(&knots, 0.02, target).reached.expect("reached");
    let exact = rms * rms / (target * target - bias * bias);
    assert!((n - exact).abs() <= 1.0 + 1e-4 * exact, "{n} vs {exact}");
    assert!((seconds - 2.0 * n).abs() <= 1e-3 * seconds, "{seconds} vs {}", 2.0 * n);
    // A bias beyond the target is never averaged away.
    let far = [knot(0.01, rms, 1.5, 2.0), knot(0.02, rms, 1.5, 2.0)];
    assert_eq!(schedule(&far, 0.02, target).reached, None);
}

#[test]
fn a_shrinking_radius_averages_its_bias_down_to_the_smallest_radius() {
    // A bias ∝ R: 2% at R = 0.02, 0.5% at 0.005 — out of reach at 0.02 for a 1% target, but a
    // schedule from 0.02 shrinks R (R_i = R₁·i^(−1/6)) until the average bias falls below it.
    let knots = [knot(0.005, 5.0, 0.5, 1.0), knot(0.02, 5.0, 2.0, 4.0)];
    let run = schedule(&knots, 0.02, 1.0);
    let ((n, _), last) = (run.reached.expect("reached by shrinking"), run.last);
    assert!((0.005..0.02).contains(&last), "{last}");
    let radius = |i: f64| (0.02 * i.powf(-1.0 / 6.0)).max(0.005);
    let mean_bias: f64 = (1..=n as u64).map(|i| 2.0 * radius(i as f64) / 0.02).sum::<f64>() / n;
    assert!(mean_bias < 1.0, "the average bias at n = {n} is {mean_bias}");
    let at = interpolate(&knots, 0.0125);
    assert!((at.bias - 1.25).abs() < 1e-12, "b linear in R: {}", at.bias);
    assert!(
        (at.seconds - (1.0 + 3.0 * (0.0125f64.powi(2) - 0.005f64.powi(2)) / (0.02f64.powi(2) - 0.005f64.powi(2))))
            .abs()
            < 1e-12
    );
}
