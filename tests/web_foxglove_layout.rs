//! docs/foxglove-layout.json against a real recording: every topic a panel reads is a channel
//! of an `omnirow record` file or the output of the layout's user script, every message field a
//! plot or state panel reads is in that channel's messages, the layout tree places every
//! configured panel once, and the user script (TypeScript with its types stripped, run in
//! headless Chromium) turns a recorded estimate into the ground rows and the followed line
//! that omnirow's own overlay draws.

use std::collections::{BTreeMap, BTreeSet};

#[path = "support/node.rs"]
mod node;
use node::*;
#[path = "support/browser.rs"]
mod browser;
use browser::*;

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

/// The field at a dotted `path` in `msg`.
fn field<'a>(msg: &'a serde_json::Value, path: &str) -> Option<&'a serde_json::Value> {
    path.split('.').try_fold(msg, |m, k| m.get(k))
}

/// The layout's user script: (inputs, output, TypeScript source).
fn user_script(layout: &serde_json::Value) -> (Vec<String>, String, String) {
    let scripts = layout["userNodes"].as_object().expect("userNodes");
    assert_eq!(scripts.len(), 1, "one user script");
    let src = scripts.values().next().unwrap()["sourceCode"]
        .as_str()
        .unwrap()
        .to_owned();
    let after = |key: &str| {
        let at = src
            .find(key)
            .unwrap_or_else(|| panic!("no `{key}` in the script"));
        let rest = &src[at + key.len()..];
        rest[..rest.find(';').unwrap()].trim().to_owned()
    };
    let inputs: Vec<String> = serde_json::from_str(&after("export const inputs =")).unwrap();
    let output: String = serde_json::from_str(&after("export const output =")).unwrap();
    (inputs, output, src)
}

/// Runs the user script on `message` in headless Chromium: the TypeScript's annotations are
/// stripped (the script keeps to `name: type` forms a regular expression removes) and the
/// default export called as Foxglove calls it. Returns what it published.
fn run_script(
    chromium: &std::path::Path,
    dir: &std::path::Path,
    src: &str,
    topic: &str,
    message: &serde_json::Value,
) -> serde_json::Value {
    // `</` cannot end the page's script from inside a JSON string.
    let embed = |v: &serde_json::Value| v.to_string().replace("</", "<\\/");
    let page = format!(
        r#"<!doctype html><pre id="out">not run</pre><pre id="err"></pre><script>
try {{
  const js = {src}
    .replace(/^(import|type) .*$/gm, "")
    .replace(/^export default /gm, "").replace(/^export /gm, "")
    .replace(/: Input<"[^"]*">/g, "")
    .replace(/: (number|any|Output)(\[\])?/g, "");
  const script = new Function(js + "\nreturn script;")();
  const out = script({{ topic: {topic}, receiveTime: {{ sec: 1, nsec: 2 }}, message: {message} }});
  document.getElementById("out").textContent = JSON.stringify(out);
}} catch (e) {{
  document.getElementById("err").textContent = String(e);
}}
</script>"#,
        src = embed(&serde_json::Value::from(src)),
        topic = embed(&serde_json::Value::from(topic)),
        message = embed(message),
    );
    let file = dir.join("script.html");
    std::fs::write(&file, page).unwrap();
    let dom = browse(
        chromium,
        &dir.join("profile-script"),
        &format!("file://{}", file.display()),
        1000,
        &["--dump-dom"],
    );
    assert_eq!(text_of(&dom, "err"), "", "the script failed");
    let out = text_of(&dom, "out")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: the script published {out}"))
}

#[test]
fn layout_reads_what_a_recording_holds() {
    let dir = tmpdir("foxglove-layout");
    let cfg = small_config(&dir, "");
    let rec = dir.join("rec");
    let ok = bin()
        .args(["record", "--no-print", "--frames", "6", "--out"])
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
    // The first message of each JSON channel, every channel's topic, and the last estimate
    // that placed rows on the ground.
    let mut topics = BTreeSet::new();
    let mut first: BTreeMap<String, serde_json::Value> = BTreeMap::new();
    let mut with_rows = None;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.clone();
        topics.insert(topic.clone());
        if m.channel.message_encoding == "json" {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            if v["guidance"]["rows"]
                .as_array()
                .is_some_and(|r| r.len() >= 2)
                && v["guidance"]["lateral_offset_m"].is_f64()
            {
                with_rows = Some(v.clone());
            }
            first.entry(topic).or_insert(v);
        }
    }

    let layout = layout();
    let (inputs, output, src) = user_script(&layout);
    for t in &inputs {
        assert!(
            topics.contains(t),
            "the user script reads {t}, not in {topics:?}"
        );
    }
    assert!(output.starts_with("/studio_script/"), "{output}");
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
    let mut shown = false;
    let mut annotated = false;
    for (id, cfg) in panels {
        for t in cfg["topics"].as_object().into_iter().flat_map(|t| t.keys()) {
            assert!(
                topics.contains(t) || *t == output,
                "{id}: no channel or script output {t}"
            );
            shown |= *t == output;
            checked += 1;
        }
        if let Some(t) = cfg["imageMode"]["imageTopic"].as_str() {
            assert!(topics.contains(t), "{id}: no channel {t} in {topics:?}");
            checked += 1;
        }
        for t in cfg["imageMode"]["annotations"]
            .as_object()
            .into_iter()
            .flat_map(|t| t.keys())
        {
            assert!(topics.contains(t), "{id}: no annotations channel {t}");
            annotated = true;
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
                self::field(msg, field).is_some(),
                "{id}: {path}: no field {field} in {msg}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 14, "only {checked} references checked");
    assert!(shown, "no panel shows the user script's {output}");
    assert!(annotated, "the image panel draws no annotations channel");

    // The script on a recorded estimate: a grey line per ground row, then the followed line
    // where omnirow's overlay puts it.
    let Some(chromium) = chromium() else {
        return;
    };
    let estimate = with_rows.expect("an estimate with rows on the ground in 6 frames");
    let scene = run_script(&chromium, &dir, &src, &inputs[0], &estimate);
    let entity = &scene["entities"][0];
    assert_eq!(entity["frame_id"], "base_link");
    let lines = entity["lines"].as_array().unwrap();
    let e: omnirow::estimate::Estimate = serde_json::from_value(estimate).unwrap();
    let g = e.guidance.unwrap();
    assert_eq!(lines.len(), g.rows.len() + 1, "{scene}");
    let point = |p: &serde_json::Value| {
        nalgebra::Vector3::new(
            p["x"].as_f64().unwrap(),
            p["y"].as_f64().unwrap(),
            p["z"].as_f64().unwrap(),
        )
    };
    for (line, row) in lines.iter().zip(&g.rows) {
        let mid = (point(&line["points"][0]) * 6.0 + point(&line["points"][1]) * 2.0) / 8.0;
        assert!(
            (mid - nalgebra::Vector3::from(row.point_m)).norm() < 1e-9,
            "{line}"
        );
    }
    let want = omnirow::guidance::followed::followed_lines(&g)
        .unwrap()
        .line;
    let followed = lines.last().unwrap();
    for p in followed["points"].as_array().unwrap() {
        let v = point(p) - want.point_m;
        let off_line = (v - want.direction * v.dot(&want.direction)).norm();
        assert!(
            off_line < 1e-9,
            "{p} is {off_line} m off omnirow's followed line"
        );
    }
    assert!(entity["texts"][0]["text"]
        .as_str()
        .unwrap()
        .starts_with(g.tracking.name()));
}
