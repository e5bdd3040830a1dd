//! The `omnirow` binary: parses the command line, runs it, and turns errors into exit codes.

use std::process::ExitCode;

fn main() -> ExitCode {
    match omnirow::cli::main() {
        Ok(code) => code,
        Err(err) => {
            eprintln!("omnirow: error: {}", omnirow::cli::error_line(&err));
            ExitCode::from(2)
        }
    }
}
