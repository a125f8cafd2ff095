//! The plain parameter types of the model — the scene, the light's profile, the cell grid — as the
//! JSON documents spell them, and their validation: every range a scene value must lie in is
//! checked here, once, naming the field and the range ([`SpecError`]) — but for the least flux of
//! the light's rings ([`MIN_RING_FLUX`]), which needs the profile built and so is checked by
//! [`super::illumination::validate_flux`] (this file imports nothing from `illumination`).

use serde::{Deserialize, Deserializer, Serialize};
use serde_json::Value;

use super::cells::{CellGrid, MAX_CELLS};

/// A rejected field: which one (a JSON path such as `scene.illumination.a`) and why, with the
/// allowed range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct SpecError {
    /// JSON path of the offending field (`""` for the document itself).
    pub field: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl SpecError {
    /// An error about the field at JSON path `field`.
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self { field: field.into(), message: message.into() }
    }
}

/// The three planes and the light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Distance from plane 1 (z = 0) to plane 2.
    pub l2: f64,
    /// Distance from plane 2 to plane 3.
    pub l3: f64,
    /// Width β of the plane-2 transmission lobe, in degrees.
    pub beta_deg: f64,
    /// The radial profile I(r) of the light on plane 3.
    pub illumination: IlluminationSpec,
}

/// The radial illumination profile I(r) of plane 3 (normalised to total flux 1 by the model).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum IlluminationSpec {
    /// The paper's profile: `contrast` for r ≤ a, 1 for a < r < r_ls, 0 beyond.
    Spot {
        /// Radius of the bright spot.
        a: f64,
        /// Radius of the whole light source.
        r_ls: f64,
        /// Level of the spot relative to the rest of the source.
        contrast: f64,
    },
    /// 1 for r < r_ls, 0 beyond.
    Uniform {
        /// Radius of the light source.
        r_ls: f64,
    },
    /// Piecewise constant: `level` up to `outer_radius`, ring after ring, 0 beyond the last.
    Rings {
        /// The rings, innermost first, with increasing outer radii.
        rings: Vec<RingSpec>,
    },
}

/// One ring of a `rings` profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct RingSpec {
    /// Outer radius of the ring (its inner radius is the previous ring's outer radius, or 0).
    #[cfg_attr(feature = "server", schema(minimum = 1e-9, maximum = 1e6))]
    pub outer_radius: f64,
    /// Unnormalised level of the ring (the model normalises the profile to total flux 1).
    #[cfg_attr(feature = "server", schema(minimum = 0.0, maximum = 1e12))]
    pub level: f64,
}

/// The cell grid of the tabulated weights over the join path's (r2, r3, φ).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct CellSpec {
    /// Cell edges on r2, starting at 0; the last edge opens a tail cell to infinity.
    pub r2_edges: Vec<f64>,
    /// Cell edges on r3, starting at 0; the last edge opens a tail cell to infinity.
    pub r3_edges: Vec<f64>,
    /// Number of equal φ bins on [0, π].
    #[serde(deserialize_with = "count_u32")]
    pub phi_bins: u32,
}

/// Accepts integers and integral floats (`1e7`) for counts: users write both, and JSON Schema
/// counts `1.0` as an integer.
pub fn count<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    use serde::de::Error;
    let v = Value::deserialize(d)?;
    if let Some(n) = v.as_u64() {
        return Ok(n);
    }
    v.as_f64()
        .and_then(whole_number)
        .ok_or_else(|| D::Error::custom(format!("expected a non-negative integer, got {v}")))
}

/// A count written as a number: a non-negative whole number up to 2^53 (so `1e4` is 10,000, as
/// in JSON).
fn whole_number(x: f64) -> Option<u64> {
    (x >= 0.0 && x.fract() == 0.0 && x <= 9_007_199_254_740_992.0).then_some(x as u64)
}

/// A count on a command line, read as the JSON API reads one: `10000`, `1e4` and `1.5e8` are
/// accepted, `-5`, `2.5` and `ten` are not.
pub fn parse_count(text: &str) -> Result<u64, String> {
    let text = text.trim();
    text.parse::<u64>()
        .ok()
        .or_else(|| text.parse::<f64>().ok().and_then(whole_number))
        .ok_or_else(|| format!("expected a non-negative whole number (e.g. 10000 or 1e4), got {text:?}"))
}

/// [`count`] for an optional field (use with `#[serde(default)]`).
pub fn optional_count<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    count(d).map(Some)
}

/// [`count`] for a field that must fit in a `u32`.
pub fn count_u32<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    use serde::de::Error;
    let n = count(d)?;
    u32::try_from(n).map_err(|_| D::Error::custom(format!("expected at most {}, got {n}", u32::MAX)))
}

/// Most light paths N_F per iteration.
pub const MAX_LIGHT_PATHS: u64 = 1_000_000_000_000;
/// Most camera paths N_B per iteration.
pub const MAX_CAMERA_PATHS: u64 = 1_000_000;

/// Checks N_F and N_B against their ranges, naming them `fields` (a spec's `light_paths`, a
/// command line's `--light-paths`, …).
pub(crate) fn check_path_counts(light_paths: u64, camera_paths: u64, fields: [&str; 2]) -> Result<(), SpecError> {
    check((1..=MAX_LIGHT_PATHS).contains(&light_paths), fields[0], || {
        format!("must be in [1, 10^12], got {light_paths}")
    })?;
    check((1..=MAX_CAMERA_PATHS).contains(&camera_paths), fields[1], || {
        format!("must be in [1, 10^6], got {camera_paths}")
    })
}

pub(crate) fn check(ok: bool, field: &str, message: impl FnOnce() -> String) -> Result<(), SpecError> {
    if ok { Ok(()) } else { Err(SpecError::new(field, message())) }
}

/// `x` is finite and in (lo, hi].
pub(crate) fn in_open_closed(x: f64, lo: f64, hi: f64) -> bool {
    x.is_finite() && x > lo && x <= hi
}

/// Largest length accepted anywhere in a scene: far beyond any sensible scene, small enough that
/// squares and products stay finite.
pub const MAX_LENGTH: f64 = 1e6;

/// Smallest length accepted (plane distances, radii, the merge radius): far below any sensible
/// scene (the paper's lengths are of order 1), far above where the merge kernel 1/(πR²) and its
/// squares in the moments overflow.
pub const MIN_LENGTH: f64 = 1e-9;

/// Smallest lobe width β in degrees: the lobe's density grows as 1/β², and below this its
/// contributions' fourth powers (the noise table's standard errors) leave the doubles.
pub const MIN_BETA_DEG: f64 = 1e-6;
/// Widest plane-2 lobe β, in degrees.
pub const MAX_BETA_DEG: f64 = 45.0;
/// Largest illumination level (a spot's contrast, a ring's level; unnormalised).
pub const MAX_LEVEL: f64 = 1e12;
/// Most rings of a `rings` profile.
pub const MAX_RINGS: usize = 64;
/// Most φ bins of the cell grid.
pub const MAX_PHI_BINS: u32 = 360;

/// `x` is finite and in [lo, hi].
pub(crate) fn in_closed(x: f64, lo: f64, hi: f64) -> bool {
    x.is_finite() && x >= lo && x <= hi
}

/// Checks the scene: plane distances, lobe width and the light profile's ranges. The flux of the
/// profile's rings needs the profile built: [`validate_flux`](super::illumination::validate_flux)
/// checks it next.
pub fn validate_scene(s: &SceneSpec) -> Result<(), SpecError> {
    for (name, v) in [("scene.l2", s.l2), ("scene.l3", s.l3)] {
        check(in_closed(v, MIN_LENGTH, MAX_LENGTH), name, || {
            format!("must be a distance in [{MIN_LENGTH:e}, {MAX_LENGTH:e}], got {v}")
        })?;
    }
    check(in_closed(s.beta_deg, MIN_BETA_DEG, MAX_BETA_DEG), "scene.beta_deg", || {
        format!("must be in [{MIN_BETA_DEG:e}, {MAX_BETA_DEG}] degrees, got {}", s.beta_deg)
    })?;
    validate_profile(&s.illumination)
}

/// Smallest flux level·(r_out² − r_in²) of an emitting ring: far below any real profile, far above
/// the subnormals, whose reciprocals overflow (a subnormal flux once made the reference NaN).
pub const MIN_RING_FLUX: f64 = 1e-200;

fn validate_profile(ill: &IlluminationSpec) -> Result<(), SpecError> {
    let f = "scene.illumination";
    match *ill {
        IlluminationSpec::Spot { a, r_ls, contrast } => {
            check(in_closed(a, MIN_LENGTH, MAX_LENGTH), &format!("{f}.a"), || {
                format!("must be a radius in [{MIN_LENGTH:e}, {MAX_LENGTH:e}], got {a}")
            })?;
            check(in_open_closed(r_ls, a, MAX_LENGTH), &format!("{f}.r_ls"), || {
                format!("must be a radius in (a = {a}, {MAX_LENGTH:e}], got {r_ls}")
            })?;
            check(in_open_closed(contrast, 0.0, MAX_LEVEL), &format!("{f}.contrast"), || {
                format!("must be in (0, {MAX_LEVEL:e}], got {contrast}")
            })
        }
        IlluminationSpec::Uniform { r_ls } => {
            check(in_closed(r_ls, MIN_LENGTH, MAX_LENGTH), &format!("{f}.r_ls"), || {
                format!("must be a radius in [{MIN_LENGTH:e}, {MAX_LENGTH:e}], got {r_ls}")
            })
        }
        IlluminationSpec::Rings { ref rings } => {
            check((1..=MAX_RINGS).contains(&rings.len()), &format!("{f}.rings"), || {
                format!("must list 1 to {MAX_RINGS} rings, got {}", rings.len())
            })?;
            let mut inner = 0.0;
            let mut flux = 0.0;
            for (i, ring) in rings.iter().enumerate() {
                let field = format!("{f}.rings[{i}]");
                let ok = in_open_closed(ring.outer_radius, inner, MAX_LENGTH) && ring.outer_radius >= MIN_LENGTH;
                check(ok, &format!("{field}.outer_radius"), || {
                    format!(
                        "must be in ({inner}, {MAX_LENGTH:e}] and at least {MIN_LENGTH:e} (radii strictly increasing), \
                         got {}",
                        ring.outer_radius
                    )
                })?;
                check(
                    ring.level.is_finite() && (0.0..=MAX_LEVEL).contains(&ring.level),
                    &format!("{field}.level"),
                    || format!("must be in [0, {MAX_LEVEL:e}], got {}", ring.level),
                )?;
                flux += ring.level * (ring.outer_radius.powi(2) - inner * inner);
                inner = ring.outer_radius;
            }
            check(flux > 0.0, &format!("{f}.rings"), || "must emit some light: every level is 0".to_string())
        }
    }
}

fn validate_edges(edges: &[f64], field: &str) -> Result<(), SpecError> {
    check(!edges.is_empty() && edges[0] == 0.0, field, || {
        format!("must start at 0 (the first cell begins at r = 0), got {edges:?}")
    })?;
    for (i, pair) in edges.windows(2).enumerate() {
        check(
            pair[1].is_finite() && pair[1] > pair[0] && pair[1] <= MAX_LENGTH,
            &format!("{field}[{}]", i + 1),
            || {
                format!(
                    "edges must be finite and strictly increasing (≤ {MAX_LENGTH:e}), got {} after {}",
                    pair[1], pair[0]
                )
            },
        )?;
    }
    Ok(())
}

/// Checks the cell grid (edges from 0, strictly increasing and bounded; φ bins in 1–360) and
/// builds it.
pub fn validate_cells(cells: &CellSpec) -> Result<CellGrid, SpecError> {
    validate_edges(&cells.r2_edges, "cells.r2_edges")?;
    validate_edges(&cells.r3_edges, "cells.r3_edges")?;
    check((1..=MAX_PHI_BINS).contains(&cells.phi_bins), "cells.phi_bins", || {
        format!("must be in [1, {MAX_PHI_BINS}], got {}", cells.phi_bins)
    })?;
    let total = cells.r2_edges.len() * cells.r3_edges.len() * cells.phi_bins as usize;
    check(total <= MAX_CELLS, "cells", || {
        format!(
            "{} r2 cells × {} r3 cells × {} φ bins = {total} cells; at most {MAX_CELLS} are allowed",
            cells.r2_edges.len(),
            cells.r3_edges.len(),
            cells.phi_bins
        )
    })?;
    Ok(CellGrid::new(cells.r2_edges.clone(), cells.r3_edges.clone(), cells.phi_bins))
}

/// Applies `patch` to `base` by JSON Merge Patch, except that an object whose `kind` differs from
/// the base's replaces it whole.
pub fn merge_patch(base: &mut Value, patch: &Value) {
    match (base, patch) {
        (Value::Object(base_map), Value::Object(patch_map)) => {
            for (key, value) in patch_map {
                if value.is_null() {
                    base_map.remove(key);
                    continue;
                }
                match base_map.get_mut(key) {
                    Some(slot) if slot.is_object() && value.is_object() && !kind_differs(slot, value) => {
                        merge_patch(slot, value)
                    }
                    _ => {
                        base_map.insert(key.clone(), value.clone());
                    }
                }
            }
        }
        (base, patch) => *base = patch.clone(),
    }
}

/// Most identifiers in a dotted field path (`scene.illumination.a` has 3).
pub const MAX_PATH_SEGMENTS: usize = 8;
/// Most bytes of a dotted field path.
const MAX_PATH_BYTES: usize = 200;

/// The merge patch that sets the field at dotted `path` to `value` (`scene.l3` → `{"scene": {"l3":
/// value}}`), or None when `path` is not a dotted path of at most [`MAX_PATH_SEGMENTS`] lower-case
/// identifiers. Sweep axes and the CLI's `--set` name fields this way.
pub fn path_patch(path: &str, value: &Value) -> Option<Value> {
    let segments: Vec<&str> = path.split('.').collect();
    let identifier =
        |s: &&str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_');
    if path.len() > MAX_PATH_BYTES || segments.len() > MAX_PATH_SEGMENTS || !segments.iter().all(identifier) {
        return None;
    }
    Some(segments.iter().rev().fold(value.clone(), |inner, key| {
        let mut map = serde_json::Map::new();
        map.insert((*key).to_string(), inner);
        Value::Object(map)
    }))
}

fn kind_differs(a: &Value, b: &Value) -> bool {
    match (a.get("kind"), b.get("kind")) {
        (Some(x), Some(y)) => x != y,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::parse_count;

    #[test]
    fn counts_on_a_command_line_read_as_in_json() {
        assert_eq!(parse_count("10000"), Ok(10_000));
        assert_eq!(parse_count("1e4"), Ok(10_000));
        assert_eq!(parse_count("1.5e8"), Ok(150_000_000));
        assert_eq!(parse_count("18446744073709551615"), Ok(u64::MAX));
        for bad in ["-5", "2.5", "ten", "", "1e300", "-0.5"] {
            let e = parse_count(bad).unwrap_err();
            assert!(e.contains("non-negative whole number"), "{bad}: {e}");
        }
    }
}
