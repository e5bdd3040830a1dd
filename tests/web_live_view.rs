//! The live view in a real browser: headless Chromium (Debian's `chromium`, installed by
//! .ci/run) loads `/` from a running `omnirow run`, and the test checks that the numbers the
//! page shows (heading, tilt, quality, the guidance's offset, tracking state, spacing and row
//! index) are those of `/status` and that the frame (with the followed line) and the plot
//! render. The node runs the synthetic drive standing still, so every estimate is the same
//! and the page and `/status` can be compared whenever each was read.

use std::time::Duration;

#[path = "support/node.rs"]
mod node;
use node::*;
#[path = "support/http.rs"]
mod http;
use http::*;
#[path = "support/browser.rs"]
mod browser;
use browser::*;

fn number(dom: &str, id: &str) -> f64 {
    let t = text_of(dom, id);
    t.parse()
        .unwrap_or_else(|_| panic!("#{id} shows {t:?}, not a number"))
}

#[test]
fn live_view_shows_the_status_numbers_frame_and_plot() {
    let Some(chromium) = chromium() else {
        return;
    };
    let dir = tmpdir("web-live-view");
    // The synthetic drive standing still: every frame, so every estimate, is the same.
    let cfg = dir.join("still.toml");
    std::fs::write(
        &cfg,
        "[source.synthetic]\nwidth = 408\nheight = 342\nfps = 15.0\nseed = 5\nspeed_mps = 0.0\n\
         heading_amplitude_deg = 0.0\npitch_amplitude_deg = 0.0\noffset_amplitude_m = 0.0\n",
    )
    .unwrap();
    let node = Node::start(&cfg, &[]);
    // A few seconds of history for the plot.
    std::thread::sleep(Duration::from_secs(3));

    let url = format!("http://{}/", node.addr);
    let dom = browse(
        &chromium,
        &dir.join("profile-dom"),
        &url,
        5000,
        &["--dump-dom"],
    );
    let (code, _, body) = node.get("/status");
    assert_eq!(code, 200);
    let st: serde_json::Value = serde_json::from_slice(&body).unwrap();
    let latest = &st["latest"];
    assert_eq!(text_of(&dom, "connection"), "live");
    assert_eq!(
        text_of(&dom, "source-state"),
        st["source_state"].as_str().unwrap()
    );
    assert_eq!(
        text_of(&dom, "estimate-status"),
        latest["status"].as_str().unwrap()
    );
    let deg = |v: &serde_json::Value| v.as_f64().unwrap().to_degrees();
    assert!(latest["heading_rad"].is_f64(), "no heading: {st}");
    for (id, want, step) in [
        ("heading", deg(&latest["heading_rad"]), 0.01),
        ("tilt", deg(&latest["tilt_rad"]), 0.01),
        ("quality", latest["quality"].as_f64().unwrap(), 0.001),
    ] {
        let shown = number(&dom, id);
        assert!(
            (shown - want).abs() <= step * 0.51 + 1e-9,
            "#{id} shows {shown}, /status says {want}"
        );
    }
    // The guidance (on by default): the robot stands still between two rows, so the tracker
    // follows the same path from the first frames on, and the page shows its numbers.
    let g = &latest["guidance"];
    assert_eq!(g["tracking"], "tracking", "guidance: {g}");
    assert_eq!(text_of(&dom, "tracking"), "tracking");
    let offset_m = g["lateral_offset_m"]
        .as_f64()
        .expect("an offset while tracking");
    let shown = number(&dom, "offset");
    assert!(
        (shown - offset_m * 100.0).abs() <= 0.051,
        "#offset shows {shown} cm, /status says {offset_m} m"
    );
    let spacing_m = g["row_spacing_m"]
        .as_f64()
        .expect("a spacing while tracking");
    assert!((number(&dom, "spacing") - spacing_m * 100.0).abs() <= 0.051);
    assert_eq!(number(&dom, "row-index"), g["row_index"].as_f64().unwrap());
    let fps = number(&dom, "fps");
    // Up to 15 fps; a loaded machine may detect fewer.
    assert!(fps > 1.0 && fps < 20.0, "fps shown {fps}");
    assert!(number(&dom, "seq") >= 1.0);
    // The frame was loaded (its caption names the frame shown).
    assert!(
        text_of(&dom, "frame-seq").parse::<u64>().is_ok(),
        "no frame shown"
    );

    let shot = dir.join("live-view.png");
    browse(
        &chromium,
        &dir.join("profile-shot"),
        &url,
        5000,
        &[&format!("--screenshot={}", shot.display())],
    );
    let img = image::open(&shot).expect("a screenshot").to_rgb8();
    assert_eq!((img.width(), img.height()), (1400, 900));
    // The plot's heading and quality lines are drawn in their colours.
    let has = |c: [u8; 3]| {
        img.pixels()
            .filter(|p| p.0.iter().zip(c).all(|(a, b)| a.abs_diff(b) <= 12))
            .count()
    };
    assert!(has([0xff, 0x9f, 0x1c]) > 50, "no heading line in the plot");
    assert!(has([0x2e, 0xc4, 0xb6]) > 50, "no quality line in the plot");
    // The plot's offset line, and the followed line drawn over the frame (cyan).
    assert!(has([0xc7, 0x7d, 0xff]) > 50, "no offset line in the plot");
    let followed = img
        .enumerate_pixels()
        .filter(|(x, _, p)| {
            *x < 800
                && p.0
                    .iter()
                    .zip([0u8, 230, 255])
                    .all(|(a, b)| a.abs_diff(b) <= 40)
        })
        .count();
    assert!(
        followed > 100,
        "only {followed} pixels of the followed line"
    );
    // The frame is in colour: many pixels with a clear hue in the picture's area (left half).
    let coloured = img
        .enumerate_pixels()
        .filter(|(x, y, p)| {
            *x < 700 && *y > 50 && {
                let (mx, mn) = (*p.0.iter().max().unwrap(), *p.0.iter().min().unwrap());
                mx - mn > 30
            }
        })
        .count();
    assert!(
        coloured > 20_000,
        "only {coloured} coloured pixels in the frame's area"
    );
    node.stop();
}
