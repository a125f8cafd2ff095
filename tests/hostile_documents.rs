//! Hostile moments documents: real exported documents, mutated at random (numbers, counts, part
//! lists, coverage, nesting) and — as anyone can — re-sealed with a valid checksum. Every parse,
//! verification and merge must return (the work is bounded by construction: at most 40 parts per
//! sum, bounded lists, linear coverage walks; a case that looped would hang this test, which the
//! watchdog turns into a failure), never panic, and a refused merge must leave the target's
//! moments byte-identical.

use std::sync::mpsc;
use std::time::Duration;

use optimis::sim::document::{MomentsDocument, merge_documents};
use optimis::sim::runner::run;
use optimis::sim::spec::parse_job_spec;
use optimis::sim::stats::moments::Moments;
use proptest::prelude::*;
use serde_json::{Value, json};

/// A small real document: shard `index` of 2 of a 6-cell study.
fn exported(index: u64) -> MomentsDocument {
    let spec = parse_job_spec(&json!({ "engine": "brute", "light_paths": 20_000, "camera_paths": 100,
        "merge_radius": 0.02, "iterations": 8, "seed": 3, "shard": { "index": index, "count": 2 },
        "cells": { "r2_edges": [0, 0.5], "r3_edges": [0, 0.01, 0.02] } }))
    .unwrap();
    let job = spec.validate().unwrap();
    let moments = run(job.config(), spec.seed, spec.iteration_range());
    MomentsDocument::new(spec, moments)
}

/// Values a forger would try.
fn hostile_number() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(json!(1.7976931348623157e308)),
        Just(json!(-1.7976931348623157e308)),
        Just(json!(1e301)),
        Just(json!(-1.0)),
        Just(json!(0)),
        Just(json!(u64::MAX)),
        Just(json!(i64::MIN)),
        Just(json!(1u64 << 63)),
        Just(json!([1.7976931348623157e308, 1.7976931348623157e308])),
        Just(json!(vec![1e300; 41])),
        Just(json!(vec![-1e-300; 40])),
        Just(json!([[0u64, 1u64 << 63], [0u64, 1u64 << 63]])),
        Just(json!([])),
        Just(json!({ "seed": 1, "ranges": [[0, 4]] })),
        Just(json!(null)),
        Just(json!("1e400")),
        any::<f64>().prop_filter("finite", |x| x.is_finite()).prop_map(|x| json!(x)),
        any::<u64>().prop_map(|x| json!(x)),
    ]
}

/// Every path to a leaf or a container of `value`, as JSON pointers.
fn pointers(value: &Value, at: String, out: &mut Vec<String>) {
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                pointers(v, format!("{at}/{k}"), out);
            }
        }
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                pointers(v, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
    out.push(at);
}

/// How a mutation changes the document.
#[derive(Debug, Clone)]
enum Mutation {
    /// Replace the value at the pointer.
    Replace(Value),
    /// Wrap the value in an array (nesting).
    Wrap,
    /// Drop an object field or an array element.
    Remove,
    /// Repeat an array's elements (lengths beyond the shape).
    Repeat(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        6 => hostile_number().prop_map(Mutation::Replace),
        1 => Just(Mutation::Wrap),
        1 => Just(Mutation::Remove),
        1 => (2usize..40).prop_map(Mutation::Repeat),
    ]
}

fn apply(doc: &mut Value, pointer: &str, mutation: &Mutation) {
    match mutation {
        Mutation::Replace(v) => {
            if let Some(slot) = doc.pointer_mut(pointer) {
                *slot = v.clone();
            }
        }
        Mutation::Wrap => {
            if let Some(slot) = doc.pointer_mut(pointer) {
                *slot = json!([slot.take()]);
            }
        }
        Mutation::Remove => {
            let (parent, last) = pointer.rsplit_once('/').unwrap_or(("", pointer));
            match doc.pointer_mut(parent) {
                Some(Value::Object(map)) => {
                    map.remove(last);
                }
                Some(Value::Array(items)) => {
                    if let Ok(i) = last.parse::<usize>()
                        && i < items.len()
                    {
                        items.remove(i);
                    }
                }
                _ => {}
            }
        }
        Mutation::Repeat(times) => {
            if let Some(Value::Array(items)) = doc.pointer_mut(pointer) {
                let copy = items.clone();
                for _ in 1..*times {
                    items.extend(copy.iter().cloned());
                }
            }
        }
    }
}

/// Runs `f` on a thread and fails if it does not return within a generous hang guard (the bound
/// is structural, not a performance limit: a working case takes milliseconds).
fn returns<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    });
    match rx.recv_timeout(Duration::from_secs(120)) {
        Ok(Ok(value)) => value,
        Ok(Err(_)) => panic!("a parse, verification or merge panicked"),
        Err(_) => panic!("a parse, verification or merge did not return (hang guard)"),
    }
}

/// What one mutated document does: parse (unsealed and re-sealed), then merge into a target.
fn exercise(base: Value, pointer: String, mutation: Mutation, target: Moments) {
    let mut mutated = base;
    apply(&mut mutated, &pointer, &mutation);
    let text = mutated.to_string();
    returns(move || {
        // As sent: the checksum no longer matches, unless the mutation changed nothing.
        let _ = MomentsDocument::from_json(text.as_bytes());
        // Re-sealed: only the document's own consistency checks stand in the way.
        let Ok(typed) = serde_json::from_str::<MomentsDocument>(&text) else { return };
        let forged = typed.sealed().to_json();
        let Ok(doc) = MomentsDocument::from_json(&forged) else { return };
        // A verified document: merging it either works or changes nothing.
        let before = serde_json::to_vec(&target).unwrap();
        let mut merged = target.clone();
        if merged.merge(&doc.moments).is_err() {
            assert_eq!(serde_json::to_vec(&merged).unwrap(), before, "a refused merge changed the target");
        } else if merged.check_bounded().is_ok() {
            // What was merged reads back.
            let round = serde_json::to_vec(&merged).unwrap();
            let back: Moments = serde_json::from_slice(&round).expect("merged moments read back");
            optimis::sim::stats::well_formed::check_well_formed(&back).expect("merged moments stay well formed");
        }
        let _ = merge_documents(&[doc.clone(), doc]);
    });
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn hostile_documents_are_refused_or_merged_exactly(pick in any::<prop::sample::Index>(), mutation in mutation(), second in any::<bool>()) {
        let base = serde_json::to_value(exported(u64::from(second))).unwrap();
        let target = exported(u64::from(!second)).moments;
        let mut all = Vec::new();
        pointers(&base, String::new(), &mut all);
        let pointer = all[pick.index(all.len())].clone();
        exercise(base, pointer, mutation, target);
    }
}

/// The mutations the adversarial review found, each named.
#[test]
fn the_reviewed_poisons_are_refused() {
    let doc = serde_json::to_value(exported(0)).unwrap();
    let target = exported(1).moments;
    for (pointer, value) in [
        ("/moments/folds/0/sum_y/0", json!([1.7976931348623157e308, 1.7976931348623157e308])),
        ("/moments/folds/1/sum_yy/3", json!(vec![1e300; 41])),
        ("/moments/folds/0/strategies/0/1", json!(-1.0)),
        ("/moments/folds/0/iterations", json!(0)),
        ("/moments/folds/0/merges/2", json!(u64::MAX)),
        ("/moments/coverage", json!([{ "seed": 3, "ranges": [[0u64, 1u64 << 63]] }])),
    ] {
        let mut mutated = doc.clone();
        *mutated.pointer_mut(pointer).unwrap() = value.clone();
        let text = mutated.to_string();
        let forged = serde_json::from_str::<MomentsDocument>(&text).map(|d| d.sealed().to_json());
        if let Ok(forged) = forged {
            assert!(MomentsDocument::from_json(&forged).is_err(), "{pointer} = {value} must be refused");
        }
        exercise(doc.clone(), pointer.to_string(), Mutation::Replace(value), target.clone());
    }
}
