//! `omnirow config check`: the real binary on good and bad configuration files.

use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
}

#[path = "support/scratch.rs"]
mod scratch;

/// Writes `text` to `name` in a scratch directory of its own (removed when the test passes).
fn write(name: &str, text: &str) -> (scratch::Scratch, PathBuf) {
    let dir = scratch::Scratch::new("cfgtest", name);
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

/// Runs `config check` and returns (success, stderr).
fn check(path: &std::path::Path) -> (bool, String) {
    let out = bin().args(["config", "check"]).arg(path).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn shipped_config_passes() {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/config/omnirow.toml");
    let out = bin().args(["config", "check", p]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains(": ok"));
    // `config default` prints exactly the shipped, documented file.
    let out = bin().args(["config", "default"]).output().unwrap();
    assert_eq!(out.stdout, std::fs::read(p).unwrap());
}

#[test]
fn unknown_key_is_named_with_its_line() {
    let (_dir, p) = write(
        "unknown.toml",
        "[pipeline]\nframe_queue = 2\n\n[http]\nlisten = \"127.0.0.1:1\"\nlistne = 3\n",
    );
    let (ok, err) = check(&p);
    assert!(!ok);
    assert!(
        err.contains("unknown.toml:6: `http.listne`: unknown field `listne`"),
        "{err}"
    );
}

#[test]
fn wrong_type_is_named_with_its_line() {
    let (_dir, p) = write("type.toml", "# comment\n[record]\nenabled = \"yes\"\n");
    let (ok, err) = check(&p);
    assert!(!ok);
    assert!(
        err.contains("type.toml:3: `record.enabled`: invalid type"),
        "{err}"
    );
}

#[test]
fn impossible_values_are_named_with_their_lines() {
    let (_dir, p) = write(
        "values.toml",
        "[pipeline]\nframe_queue = 0\n[source]\nkind = \"replay\"\n[source.replay]\nspeed = -1.0\n",
    );
    let (ok, err) = check(&p);
    assert!(!ok);
    assert!(
        err.contains("values.toml:6: `source.replay.speed`: -1 is out of range"),
        "{err}"
    );
    assert!(
        err.contains("values.toml:4: `source.kind`: `replay` needs source.replay.path"),
        "{err}"
    );
    assert!(
        err.contains("values.toml:2: `pipeline.frame_queue`: 0 is out of range"),
        "{err}"
    );
}

#[test]
fn missing_file_is_an_error_naming_it() {
    let (ok, err) = check(std::path::Path::new("/nonexistent/omnirow.toml"));
    assert!(!ok);
    assert!(err.contains("/nonexistent/omnirow.toml"), "{err}");
}

#[test]
fn config_detector_shows_the_scales_of_a_calibration() {
    let root = env!("CARGO_MANIFEST_DIR");
    // (the Hough cell in pixels, the angular scales' factor in force)
    let scales = |file: &str| -> (f64, f64) {
        let out = bin()
            .args(["config", "detector", "--calib"])
            .arg(format!("{root}/config/calib/{file}"))
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(text.contains("[detector.hough]"), "{text}");
        let line = text
            .lines()
            .find(|l| l.contains("hough cell"))
            .unwrap_or_else(|| panic!("{text}"));
        let px: f64 = line
            .split('=')
            .nth(1)
            .and_then(|t| t.trim().trim_end_matches("px").trim().parse().ok())
            .unwrap_or_else(|| panic!("{line}"));
        // The values in force are written out, so that they can be pasted and fixed.
        let factor: f64 = text
            .lines()
            .find_map(|l| l.strip_prefix("angle_scale = "))
            .and_then(|t| t.trim().parse().ok())
            .unwrap_or_else(|| panic!("{text}"));
        (px, factor)
    };
    // The Hough cell is a share of the field of view's extent: about the same number of
    // pixels through a lens with three times the focal length, so about 2.5 times the cells
    // over the sphere (the wide lens's 1.74 sr have an extent 2.4 times the narrow one's
    // 0.30 sr), and the GC2450C keeps its 90 cells of 2°.
    let ((a, na), (b, nb)) = (
        scales("pinhole_512_f300.toml"),
        scales("pinhole_512_f900.toml"),
    );
    assert!((b / a - 1.0).abs() < 0.2, "{a} px against {b} px");
    let r = na / nb;
    assert!(r > 2.2 && r < 2.7, "factors {na} against {nb}");
    assert_eq!(scales("fisheye185_gc2450c.toml").1, 1.0);
    assert_eq!(scales("pal_gc2450c.toml").1, 1.0);
    let out = bin()
        .args(["config", "detector", "--calib", "/nonexistent/calib.toml"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/calib.toml"));
}
