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
            if let Some(path) = calib {
                let cal = crate::camera::Calibration::load(&path)?;
                let report = crate::detect::scale::scales_report(&cal, &Default::default())
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
                println!("# The detector's scales for {}:\n{report}", path.display());
            }
            print!("{}", detector_defaults()?);
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The detector's default options as TOML tables under `[detector]`.
pub fn detector_defaults() -> anyhow::Result<String> {
    #[derive(serde::Serialize)]
    struct Wrapper {
        detector: crate::detect::DetectorOptions,
    }
    let text = toml::to_string(&Wrapper {
        detector: crate::detect::DetectorOptions::default(),
    })?;
    Ok(format!(
        "# omnirow's detector options and their defaults (`omnirow config detector`).\n\
         # Paste into the node's configuration and keep only what you change.\n\n{text}"
    ))
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
