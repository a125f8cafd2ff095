//! Each configuration's expected luminances at its merge radius (`sim::checks::references`) and
//! each scene's R → 0 reference (`sim::checks::quadrature`), computed once per configuration or
//! scene: quadratures of up to about a second, which every checkpoint and re-solve of a job — and
//! every run of a sweep over seeds — would otherwise repeat. Callers are on the job pool or the
//! request pool's blocking threads, never on a tokio worker.

use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, OnceLock};

use crate::sim::checks::quadrature::{ReferenceError, reference_luminance, reference_luminance_until};
use crate::sim::checks::references;
use crate::sim::model::config::SimConfig;
use crate::sim::model::scene::Scene;
use crate::sim::solve::report::ExpectedLuminance;

/// Configurations or scenes remembered per cache; beyond it the cache starts afresh (each entry
/// is a few hundred bytes, and a recomputation costs at most about a second).
const CAPACITY: usize = 1024;

/// Key → value, for values that are expensive to compute and cheap to clone. A std `Mutex`: held
/// only to look up or insert, never while computing (two threads may compute the same key once
/// each; both get equal values).
struct Memo<V>(Mutex<HashMap<String, V>>);

impl<V: Clone> Memo<V> {
    fn new() -> Self {
        Self(Mutex::new(HashMap::new()))
    }

    fn get(&self, key: &str) -> Option<V> {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).get(key).cloned()
    }

    fn get_or_compute(&self, key: String, compute: impl FnOnce() -> V) -> V {
        if let Some(hit) = self.get(&key) {
            return hit;
        }
        let value = compute();
        let mut map = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if map.len() >= CAPACITY {
            map.clear();
        }
        map.insert(key, value.clone());
        value
    }
}

/// Fingerprint → expected luminances.
fn expected_cache() -> &'static Memo<Arc<Vec<ExpectedLuminance>>> {
    static CACHE: OnceLock<Memo<Arc<Vec<ExpectedLuminance>>>> = OnceLock::new();
    CACHE.get_or_init(Memo::new)
}

/// Scene (its canonical JSON) → the R → 0 reference, or none where the quadrature gave up.
fn scene_cache() -> &'static Memo<Option<f64>> {
    static CACHE: OnceLock<Memo<Option<f64>>> = OnceLock::new();
    CACHE.get_or_init(Memo::new)
}

fn scene_key(scene: &Scene) -> String {
    serde_json::to_string(&scene.spec).unwrap_or_default()
}

/// The expected luminances of `config`, from the cache or computed (CPU work: call from a blocking
/// context).
pub fn expected_luminances(config: &SimConfig) -> Arc<Vec<ExpectedLuminance>> {
    expected_cache()
        .get_or_compute(config.fingerprint().to_string(), || Arc::new(references::expected_luminances(config)))
}

/// The R → 0 reference luminance of a scene, from the cache or computed (CPU work: call from a
/// blocking context); none where the quadrature could not reach its tolerance (logged).
pub fn scene_reference(scene: &Scene) -> Option<f64> {
    scene_cache().get_or_compute(scene_key(scene), || {
        reference_luminance(scene).inspect_err(|e| tracing::warn!(error = %e, "no reference luminance")).ok()
    })
}

/// The R → 0 reference luminance of a scene, from the cache or computed until `stop` is set (a
/// job's own run computes its scene's reference, which a submission no longer waits for): none
/// where the quadrature could not reach its tolerance, `Err(Stopped)` if stopped first (nothing
/// is cached then).
pub fn scene_reference_until(scene: &Scene, stop: &AtomicBool) -> Result<Option<f64>, ReferenceError> {
    let key = scene_key(scene);
    if let Some(hit) = scene_cache().get(&key) {
        return Ok(hit);
    }
    let value = match reference_luminance_until(scene, stop) {
        Err(ReferenceError::Stopped) => return Err(ReferenceError::Stopped),
        Err(e) => {
            tracing::warn!(error = %e, "no reference luminance");
            None
        }
        Ok(value) => Some(value),
    };
    scene_cache().get_or_compute(key, || value);
    Ok(value)
}

/// A scene's reference if the cache holds it (`Some(None)`: the quadrature gave up), without
/// computing anything.
pub fn cached_scene_reference(scene: &Scene) -> Option<Option<f64>> {
    scene_cache().get(&scene_key(scene))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::spec::parse_job_spec;

    /// A sweep over seeds (one scene) computes its reference once; the cached value is the
    /// quadrature's, bit for bit.
    #[test]
    fn a_scene_reference_is_computed_once_and_kept() {
        // A scene no other test uses, so that the cache starts without it.
        let job = parse_job_spec(&serde_json::json!({ "scene": { "l3": 3.125 } })).unwrap().validate().unwrap();
        let scene = &job.config().scene;
        assert_eq!(cached_scene_reference(scene), None);
        let first = scene_reference(scene);
        assert_eq!(cached_scene_reference(scene), Some(first));
        assert_eq!(first, reference_luminance(scene).ok());
        assert_eq!(scene_reference(scene).map(f64::to_bits), first.map(f64::to_bits));
    }
}
