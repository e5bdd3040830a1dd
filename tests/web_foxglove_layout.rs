//! docs/foxglove-layout.json against a real recording: every topic a panel reads is a channel
//! of an `omnirow record` file, every message field a plot or state panel reads is in that
//! channel's messages, and the layout tree places every configured panel once.

use std::collections::{BTreeMap, BTreeSet};

#[path = "support/node.rs"]
mod node;
use node::*;

fn layout() -> serde_json::Value {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/foxglove-layout.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).expect("the layout is JSON")
}

/// The panel ids the layout tree places.
fn placed(node: &serde_json::Value, out: &mut Vec<String>) {
    match node {
        serde_json::Value::String(id) => out.push(id.clone()),
        serde_json::Value::Object(split) => {
            placed(&split["first"], out);
            placed(&split["second"], out);
        }
        other => panic!("unexpected layout node {other}"),
    }
}

#[test]
fn layout_reads_what_a_recording_holds() {
    let dir = tmpdir("foxglove-layout");
    let cfg = small_config(&dir, "");
    let rec = dir.join("rec");
    let ok = bin()
        .args(["record", "--no-print", "--frames", "3", "--out"])
        .arg(&rec)
        .arg("--config")
        .arg(&cfg)
        .status()
        .unwrap()
        .success();
    assert!(ok);
    let file = std::fs::read_dir(&rec)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .unwrap();
    let bytes = std::fs::read(file).unwrap();
    // The first message of each JSON channel, and every channel's topic.
    let mut topics = BTreeSet::new();
    let mut first: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        topics.insert(topic.clone());
        if m.channel.message_encoding == "json" && !first.contains_key(&topic) {
            first.insert(topic, serde_json::from_slice(&m.data).unwrap());
        }
    }

    let layout = layout();
    let panels = layout["configById"].as_object().unwrap();
    let mut ids = Vec::new();
    placed(&layout["layout"], &mut ids);
    let mut sorted = ids.clone();
    sorted.sort();
    sorted.dedup();
    assert_eq!(sorted.len(), ids.len(), "a panel placed twice: {ids:?}");
    assert_eq!(
        sorted,
        panels.keys().cloned().collect::<Vec<_>>(),
        "placed panels and configured panels differ"
    );

    let mut checked = 0;
    for (id, cfg) in panels {
        if let Some(t) = cfg["imageMode"]["imageTopic"].as_str() {
            assert!(topics.contains(t), "{id}: no channel {t} in {topics:?}");
            checked += 1;
        }
        if let Some(t) = cfg["topicPath"].as_str() {
            assert!(topics.contains(t), "{id}: no channel {t} in {topics:?}");
            checked += 1;
        }
        for p in cfg["paths"].as_array().into_iter().flatten() {
            let path = p["value"].as_str().unwrap();
            let (topic, field) = path.split_once('.').unwrap();
            let msg = first
                .get(topic)
                .unwrap_or_else(|| panic!("{id}: {path}: no JSON channel {topic}"));
            assert!(
                msg.get(field).is_some(),
                "{id}: {path}: no field {field} in {msg}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 10, "only {checked} references checked");
}
