//! The command-line interface: argument parsing (clap) and one module per subcommand.
//!
//! Owns turning command-line words into calls into the library and results into output.
//! Each subcommand returns an exit code (`ExitCode`) or an error that `main` reports.

mod calib;
mod cameras;
mod config;
pub mod detect;
mod eval;
mod eval_real;
mod recording;
mod run;
mod sim;
pub(crate) mod synth;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Crop-row and vanishing-point detection for omnidirectional cameras.
#[derive(Debug, Parser)]
#[command(name = "omnirow", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Inspect or produce calibrations.
    #[command(subcommand)]
    Calib(calib::CalibCommand),
    /// Render a synthetic field image with its ground truth.
    Synth(Box<synth::SynthArgs>),
    /// Detect rows, their vanishing point, heading and tilt in images (one JSON line each).
    Detect(detect::DetectArgs),
    /// Regenerate the paper's evaluation on synthetic images: tables and plots.
    Eval(Box<eval::EvalArgs>),
    /// Check the node's configuration file, or print the documented defaults.
    #[command(subcommand)]
    Config(config::ConfigCommand),
    /// Run the node: frames from a source, heading and tilt published at frame rate.
    /// Without a configuration: the synthetic drive.
    Run(Box<run::RunArgs>),
    /// Run the node and record frames and estimates into MCAP files in DIR.
    Record {
        #[arg(long, value_name = "DIR")]
        out: std::path::PathBuf,
        #[command(flatten)]
        args: Box<run::RunArgs>,
    },
    /// List the GigE Vision / USB3 Vision cameras Aravis finds (needs the `camera` feature).
    Cameras(cameras::CamerasArgs),
    /// The closed steering loop on a synthetic field: a robot steered by the node's own
    /// row guidance, scored against its true pose (docs/sim.md).
    Sim(Box<sim::SimArgs>),
    /// Check MCAP recordings for damage, or repair one (docs/recording.md).
    #[command(subcommand)]
    Recording(recording::RecordingCommand),
}

/// Parses the process arguments and runs the command.
pub fn main() -> anyhow::Result<ExitCode> {
    let cli = Cli::parse();
    if !matches!(cli.command, Command::Run(_) | Command::Record { .. }) {
        init_logging();
    }
    match cli.command {
        Command::Calib(c) => calib::run(c),
        Command::Synth(a) => synth::run(*a),
        Command::Detect(a) => detect::run(a),
        Command::Eval(a) => eval::run(*a),
        Command::Config(c) => config::run(c),
        // The node sets up logging from its configuration.
        Command::Run(a) => run::run(*a, None),
        Command::Record { out, args } => run::run(*args, Some(out)),
        Command::Cameras(a) => cameras::run(a),
        Command::Recording(c) => recording::run(c),
        Command::Sim(a) => sim::run(*a),
    }
}

/// The one line `main` prints for an error: its chain of causes joined by ": ", each cause
/// left out when the text so far already ends with it (many errors name their cause in
/// their own message, and would otherwise print it twice).
pub fn error_line(err: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if line.is_empty() {
            line = text;
        } else if !line.ends_with(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
    }
    line
}

/// Logs through tracing to stderr at level info; `RUST_LOG` filters, `OMNIROW_LOG_FORMAT=json`
/// selects JSON (the node takes both from its configuration instead).
pub fn init_logging() {
    crate::logging::init(crate::logging::LogFormat::Human, "info");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    enum Outer {
        #[error("loading {0}: {1}")]
        Named(&'static str, #[source] std::io::Error),
        #[error("loading {0}")]
        Bare(&'static str, #[source] std::io::Error),
    }

    #[test]
    fn a_cause_already_in_the_message_is_printed_once() {
        let io = || std::io::Error::other("disk on fire");
        let named = anyhow::Error::new(Outer::Named("a.toml", io())).context("config");
        assert_eq!(error_line(&named), "config: loading a.toml: disk on fire");
        let bare = anyhow::Error::new(Outer::Bare("a.toml", io())).context("config");
        assert_eq!(error_line(&bare), "config: loading a.toml: disk on fire");
        assert_eq!(error_line(&anyhow::anyhow!("plain")), "plain");
    }
}
