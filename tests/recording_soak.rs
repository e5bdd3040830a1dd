//! The 60-second version of the soak (scripts/soak.sh; docs/recording.md, Soak): the node
//! recording from Aravis's simulator at full resolution, the camera killed and restarted
//! twice, 0.1% packet loss, the recording disk filled and freed (as root), HTTP scraped every
//! second; the script judges the run and exits 0 when every check passes.
#![cfg(feature = "camera")]

use std::process::Command;

#[test]
fn sixty_second_soak_with_faults() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let out = std::env::temp_dir().join(format!("omnirow-soak-{}", std::process::id()));
    let run = Command::new(format!("{dir}/scripts/soak.sh"))
        .args([
            "--duration",
            "60",
            "--kills",
            "2",
            "--loss",
            "1",
            "--fps",
            "5",
        ])
        .arg("--out")
        .arg(&out)
        .env("OMNIROW_BIN", env!("CARGO_BIN_EXE_omnirow"))
        .output()
        .expect("run scripts/soak.sh");
    let text = String::from_utf8_lossy(&run.stdout);
    println!("{text}");
    assert!(
        run.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let _ = std::fs::remove_dir_all(&out);
}
