//! `omnirow config check FILE` and `omnirow config default`.

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
    }
}
