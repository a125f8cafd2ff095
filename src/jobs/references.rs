//! Each configuration's expected luminances at its merge radius (`sim::checks::references`),
//! computed once per configuration: a quadrature of up to about a second, which every checkpoint
//! and re-solve of a job — and every run of a sweep over seeds — would otherwise repeat. Callers
//! are on the job pool or the request pool's blocking threads, never on a tokio worker.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use crate::sim::checks::references;
use crate::sim::model::config::SimConfig;
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
