//! Numbers and draws that know nothing of the scene: the random streams, the vectorisable sine and
//! cosine, exact sums, Poisson variates, pure samplers, SHA-256 and CSV text.
//!
//! * [`rng`] — the stream of each (seed, iteration, chunk), scalar and multi-lane;
//! * [`fastmath`] — branch-free sine and cosine the hot loop can vectorise, with tested bounds;
//! * [`exact_sum`] — exact, order-independent sums of doubles (bounded when read from outside);
//! * [`window_sum`] — the same exact sums, fast: fixed-point limbs over a window of exponents;
//! * [`plane`] — a point's distance from the axis;
//! * [`poisson`] — Poisson variates that can be interrupted;
//! * [`sampling`] — points of the unit disc, cosine directions, rotations about an axis;
//! * [`digest`] — SHA-256 as hex;
//! * [`csv`] — RFC 4180 CSV text for the tables' exports.
//!
//! Imports: nothing from the crate

pub mod csv;
pub mod digest;
pub mod exact_sum;
pub mod fastmath;
pub mod plane;
pub mod poisson;
pub mod rng;
pub mod sampling;
pub mod window_sum;
