//! Logging: `[log]` of the node's configuration and the `tracing` subscriber it sets up.
//!
//! Logs go to stderr, human-readable or as JSON lines (`[log] format`, or the environment
//! variable `OMNIROW_LOG_FORMAT=json`), filtered by `[log] level` unless `RUST_LOG` is set.

use crate::check::{Check, Raw};
use serde::Deserialize;
use tracing_subscriber::EnvFilter;

/// Log format on stderr.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    Human,
    Json,
}

/// `[log]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLog {
    format: Raw<LogFormat>,
    level: Raw<String>,
}

impl RawLog {
    /// Checks `[log]`: the format and the level (or filter).
    pub(crate) fn validate(self, c: &mut Check) -> (LogFormat, String) {
        let level = c.get(&self.level, "info".to_string());
        if let Some(s) = &self.level {
            if EnvFilter::try_new(s.get_ref()).is_err() {
                c.bad(
                    "log.level",
                    s,
                    format!(
                        "`{}` is not a level or filter (e.g. info, debug, omnirow=debug)",
                        s.get_ref()
                    ),
                );
            }
        }
        (c.get(&self.format, LogFormat::Human), level)
    }
}

/// Sets up logging on stderr (once per process; later calls change nothing).
pub fn init(format: LogFormat, level: &str) {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(level));
    let json =
        format == LogFormat::Json || std::env::var("OMNIROW_LOG_FORMAT").is_ok_and(|v| v == "json");
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    let _ = if json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}
