//! `omnirow config check FILE`, `omnirow config default` and `omnirow config detector`.

use crate::config::Config;
use clap::Subcommand;
use std::path::PathBuf;
use std::process::ExitCode;

/// `omnirow config …`
#[derive(Debug, Subcommand)]
pub enum ConfigCommand {
    /// Validate a configuration file: prints every problem with its line and key, and exits
    /// non-zero if there is any.
    Check { file: PathBuf },
    /// Print the documented default configuration (config/omnirow.toml).
    Default,
    /// Print every detector option with its default value, as a `[detector]` section to
    /// paste into the configuration (or into an options file) and tune.
    Detector {
        /// Also show, for this calibration, the angular resolution at the detector's working
        /// resolution and each option's angle in pixels (and pixel length in degrees).
        #[arg(long, value_name = "FILE")]
        calib: Option<PathBuf>,
    },
}

/// `omnirow config check|default`.
pub fn run(cmd: ConfigCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        ConfigCommand::Check { file } => match Config::load(&file) {
            Ok(_) => {
                println!("{}: ok", file.display());
                Ok(ExitCode::SUCCESS)
            }
            Err(e) => {
                eprintln!("{e}");
                Ok(ExitCode::from(1))
            }
        },
        ConfigCommand::Default => {
            print!("{}", include_str!("../../config/omnirow.toml"));
            Ok(ExitCode::SUCCESS)
        }
        ConfigCommand::Detector { calib } => {
            let Some(path) = calib else {
                print!("{}", detector_defaults()?);
                return Ok(ExitCode::SUCCESS);
            };
            let cal = crate::camera::Calibration::load(&path)?;
            let defaults = crate::detect::DetectorOptions::default();
            let in_force = crate::detect::scale::resolve(&cal, &defaults)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?
                .0;
            let report = crate::detect::scale::scales_report(&cal, &defaults)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            println!("# The detector's scales for {}:\n{report}", path.display());
            print!(
                "{}",
                detector_toml(
                    &in_force,
                    &format!(
                        "# omnirow's detector options in force for {} (`omnirow config detector \
                         --calib`):\n# the angular options derived from it are written out; \
                         paste only what you mean to fix.\n",
                        path.display()
                    )
                )?
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The detector's default options as TOML tables under `[detector]`.
pub fn detector_defaults() -> anyhow::Result<String> {
    detector_toml(
        &crate::detect::DetectorOptions::default(),
        "# omnirow's detector options and their defaults (`omnirow config detector`).\n\
         # Paste into the node's configuration and keep only what you change.\n\
         # Absent here, derived from the calibration's angular resolution unless set\n\
         # (`omnirow config detector --calib FILE` shows their values in force): angle_scale,\n\
         # hough.phi_bins, hough.theta_bins, hough.min_tolerance_deg, hough.merge_angle_deg,\n\
         # vanishing.azimuth_bins, vanishing.elevation_bin_deg, vanishing.inlier_deg,\n\
         # vanishing.min_spread_deg, combined.pair_max_deg, pencil.polish_max_band_deg.\n",
    )
}

/// `opts` as TOML tables under `[detector]`, after `header`.
fn detector_toml(opts: &crate::detect::DetectorOptions, header: &str) -> anyhow::Result<String> {
    #[derive(serde::Serialize)]
    struct Wrapper<'a> {
        detector: &'a crate::detect::DetectorOptions,
    }
    let text = toml::to_string(&Wrapper { detector: opts })?;
    Ok(format!("{header}\n{text}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detector_defaults_parse_back_to_the_defaults() {
        let text = detector_defaults().unwrap();
        let cfg = Config::parse(&text, "detector.toml").unwrap();
        assert_eq!(cfg.detector, crate::detect::DetectorOptions::default());
        assert!(text.contains("[detector.hough]"), "{text}");
    }
}
