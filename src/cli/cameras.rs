//! `omnirow cameras`: list the cameras Aravis finds (vendor, model, serial, address).

use clap::Args;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct CamerasArgs {
    /// Print one JSON object per camera instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also enable Aravis's in-process fake camera interface (for trying things out).
    #[arg(long)]
    pub fake: bool,
}

#[cfg(feature = "camera")]
pub fn run(args: CamerasArgs) -> anyhow::Result<ExitCode> {
    use crate::gige::{enable_interface, list_cameras};
    if args.fake {
        enable_interface("Fake");
    }
    let cams = list_cameras();
    if args.json {
        for c in &cams {
            println!("{}", serde_json::to_string(c)?);
        }
    } else if cams.is_empty() {
        eprintln!("no camera found (GigE Vision discovery broadcasts on every interface; check the link, its address and the firewall)");
    } else {
        let row = |cols: [&str; 6]| {
            format!(
                "{:<28} {:<24} {:<18} {:<16} {:<18} {}",
                cols[0], cols[1], cols[2], cols[3], cols[4], cols[5]
            )
        };
        println!(
            "{}",
            row(["VENDOR", "MODEL", "SERIAL", "ADDRESS", "MAC", "PROTOCOL"])
        );
        for c in &cams {
            println!(
                "{}",
                row([
                    &c.vendor,
                    &c.model,
                    &c.serial,
                    &c.address,
                    &c.physical_id,
                    &c.protocol
                ])
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(not(feature = "camera"))]
pub fn run(_args: CamerasArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!(
        "this omnirow was built without camera support; rebuild with `cargo build --release --features camera` (needs libaravis-dev)"
    )
}
