//! Headless Chromium for the tests of what a browser runs (the live view, the Foxglove
//! layout's script): finding the binary (Debian's `chromium`, installed by .ci/run), loading a
//! page with a budget of virtual time, and reading the DOM it leaves. Included by those tests
//! (`#[path = "support/browser.rs"] mod browser;`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The Chromium binary, or None (the test is skipped, except under CI where it fails).
pub fn chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    let dirs: Vec<PathBuf> = std::env::split_paths(&path).collect();
    let found = std::env::var_os("OMNIROW_CHROMIUM")
        .map(PathBuf::from)
        .or_else(|| {
            ["chromium", "chromium-browser", "google-chrome"]
                .iter()
                .flat_map(|b| dirs.iter().map(move |d| d.join(b)))
                .find(|p| p.is_file())
        });
    if found.is_none() {
        let why = "no chromium (apt-get install chromium, or set OMNIROW_CHROMIUM)";
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("{why}");
        }
        eprintln!("skipped: {why}");
    }
    found
}

/// Runs headless Chromium on `url` with `args` (e.g. `--dump-dom`), giving the page `budget_ms`
/// of virtual time; returns stdout.
pub fn browse(chromium: &Path, profile: &Path, url: &str, budget_ms: u32, args: &[&str]) -> String {
    let out = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--window-size=1400,900",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--virtual-time-budget={budget_ms}"))
        .args(args)
        .arg(url)
        .output()
        .expect("running chromium");
    assert!(
        out.status.success(),
        "chromium failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The text of the element with `id` in `dom`.
pub fn text_of(dom: &str, id: &str) -> String {
    let at = dom
        .find(&format!("id=\"{id}\""))
        .unwrap_or_else(|| panic!("no #{id} in the page"));
    let start = at + dom[at..].find('>').unwrap() + 1;
    let end = start + dom[start..].find('<').unwrap();
    dom[start..end].trim().to_owned()
}
