//! `omnirow config check FILE`, `omnirow config default` and `omnirow config detector`.

use crate::config::Config;
use crate::detect::options::{resolve, scales_report, OPTIONS};
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
    /// Print every detector option with its default value and a line saying what it does,
    /// as a `[detector]` section to paste into the configuration and tune.
    Detector {
        /// Show the values in force for this calibration instead (the method `auto` stands
        /// for, the scales derived from its field of view), with its angular resolution and
        /// each angular scale in pixels.
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
            let at = |e: crate::detect::DetectError| anyhow::anyhow!("{}: {e}", path.display());
            let in_force = resolve(&cal, &defaults).map_err(at)?.0;
            let report = scales_report(&cal, &defaults).map_err(at)?;
            println!("# The detector's scales for {}:\n{report}", path.display());
            print!(
                "{}",
                detector_toml(
                    &in_force,
                    &format!(
                        "# omnirow's detector options in force for {} (`omnirow config detector \
                         --calib`):\n# paste only what you mean to fix.\n",
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
         # Paste into the node's configuration and keep only what you change; an option\n\
         # commented out is derived from the calibration or the method unless set\n\
         # (`omnirow config detector --calib FILE` shows the values in force).\n",
    )
}

/// `opts` as TOML tables under `[detector]`, after `header`: every option of
/// [`OPTIONS`] under its line of description, commented out where it is absent.
fn detector_toml(opts: &crate::detect::DetectorOptions, header: &str) -> anyhow::Result<String> {
    let table: toml::Table = toml::Table::try_from(opts)?;
    let mut out = format!("{header}\n[detector]\n");
    let mut section = "";
    for (key, doc) in OPTIONS {
        let (sec, name) = key.rsplit_once('.').unwrap_or(("", key));
        if sec != section {
            out += &format!("\n[detector.{sec}]\n");
            section = sec;
        }
        let value = match sec {
            "" => table.get(name),
            _ => table.get(sec).and_then(|t| t.get(name)),
        };
        out += &format!("# {doc}\n");
        out += &match value {
            Some(v) => format!("{name} = {v}\n"),
            None => format!("# {name} =\n"),
        };
    }
    Ok(out)
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
        // one line of description above each option, every option listed
        let described = text.lines().filter(|l| l.starts_with("# ")).count();
        assert!(described > OPTIONS.len(), "{text}");
        for (key, _) in OPTIONS {
            let name = key.rsplit('.').next().unwrap();
            assert!(text.contains(&format!("{name} =")), "{key}: {text}");
        }
    }
}
