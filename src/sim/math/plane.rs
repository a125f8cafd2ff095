//! Points of the scene's planes: their distance from the axis.

/// |p| of a point of a plane: √(x² + y²), not `hypot`, whose overflow-safe library call costs
/// four times as much in the engines' hot paths (issue 26); the coordinates of the scene are far
/// from the squares' overflow and underflow.
#[inline(always)]
pub fn radius(p: [f64; 2]) -> f64 {
    (p[0] * p[0] + p[1] * p[1]).sqrt()
}
