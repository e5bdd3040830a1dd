//! The Python venv with the independent ROS 2 peers (cyclonedds, rosbags), shared by the
//! tests that use it (`#[path]`-included). Made by scripts/ci-python-env.sh.

use std::path::PathBuf;
use std::process::{Command, Stdio};

/// The venv (`OMNIROW_CI_VENV`, else `.venv-ci` in the crate) if it can import `modules`;
/// otherwise panics when `CI=true`, else prints why the test is skipped and returns None.
pub fn venv(modules: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("OMNIROW_CI_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".venv-ci"));
    let python = dir.join("bin/python");
    let ok = python.is_file()
        && Command::new(&python)
            .args(["-c", &format!("import {modules}")])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
    if ok {
        return Some(dir);
    }
    let why = format!(
        "no Python venv with {modules} at {} (run scripts/ci-python-env.sh)",
        dir.display()
    );
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{why}");
    }
    eprintln!("skipped: {why}");
    None
}
