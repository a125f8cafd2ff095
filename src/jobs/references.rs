//! Each configuration's expected luminances at its merge radius (`sim::checks::references`) and
//! each scene's R → 0 reference (`sim::checks::quadrature`), computed once per configuration or
//! scene: quadratures of up to about a second, which every checkpoint and re-solve of a job — and
//! every run of a sweep over seeds — would otherwise repeat. Callers are on the job pool or the
//! request pool's blocking threads, never on a tokio worker.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use crate::sim::checks::quadrature::reference_luminance;
use crate::sim::checks::references;
use crate::sim::model::config::SimConfig;
use crate::sim::model::params::SceneSpec;
use crate::sim::model::scene::Scene;
use crate::sim::solve::report::ExpectedLuminance;

/// Configurations remembered; beyond it the cache starts afresh (each entry is a few hundred bytes,
/// and a recomputation costs at most about a second).
const CAPACITY: usize = 1024;

/// Fingerprint → expected luminances. A std `Mutex`: held only to look up or insert, never while
/// computing (two threads may compute the same configuration once each; both get equal values).
fn cache() -> &'static Mutex<HashMap<String, Arc<Vec<ExpectedLuminance>>>> {
    static CACHE: OnceLock<Mutex<HashMap<String, Arc<Vec<ExpectedLuminance>>>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The expected luminances of `config`, from the cache or computed (CPU work: call from a blocking
/// context).
pub fn expected_luminances(config: &SimConfig) -> Arc<Vec<ExpectedLuminance>> {
    let key = config.fingerprint().to_string();
    if let Some(hit) = cache().lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return hit.clone();
    }
    let value = Arc::new(references::expected_luminances(config));
    let mut map = cache().lock().unwrap_or_else(|e| e.into_inner());
    if map.len() >= CAPACITY {
        map.clear();
    }
    map.insert(key, value.clone());
    value
}

/// Scene (its canonical JSON) → the R → 0 reference, or none where the quadrature gave up.
fn scene_cache() -> &'static Mutex<HashMap<String, Option<f64>>> {
    static CACHE: OnceLock<Mutex<HashMap<String, Option<f64>>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The R → 0 reference luminance of a scene, from the cache or computed (CPU work: call from a
/// blocking context); none where the quadrature could not reach its tolerance (logged).
pub fn scene_reference(scene: &Scene) -> Option<f64> {
    let key = serde_json::to_string(&scene.spec).unwrap_or_default();
    if let Some(hit) = scene_cache().lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return *hit;
    }
    let value = reference_luminance(scene).inspect_err(|e| tracing::warn!(error = %e, "no reference luminance")).ok();
    let mut map = scene_cache().lock().unwrap_or_else(|e| e.into_inner());
    if map.len() >= CAPACITY {
        map.clear();
    }
    map.insert(key, value);
    value
}

/// Whether a scene's reference is cached (for tests of the callers that must share it).
pub fn scene_reference_is_cached(spec: &SceneSpec) -> bool {
    let key = serde_json::to_string(spec).unwrap_or_default();
    scene_cache().lock().unwrap_or_else(|e| e.into_inner()).contains_key(&key)
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
        let scene = &job.config.scene;
        assert!(!scene_reference_is_cached(&scene.spec));
        let first = scene_reference(scene);
        assert!(scene_reference_is_cached(&scene.spec));
        assert_eq!(first, reference_luminance(scene).ok());
        assert_eq!(scene_reference(scene).map(f64::to_bits), first.map(f64::to_bits));
    }
}
