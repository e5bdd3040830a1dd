//! `[record]` of the node's configuration: the raw section, its checks, and the
//! [`RecordOptions`] they give.

use super::{JsonChannels, RecordOptions};
use crate::check::{Check, Raw};
use serde::Deserialize;
use std::path::PathBuf;
use std::time::Duration;

/// `[record]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRecord {
    enabled: Raw<bool>,
    dir: Raw<String>,
    prefix: Raw<String>,
    frames: Raw<bool>,
    rotate_mb: Raw<i64>,
    rotate_s: Raw<f64>,
    reserve_mb: Raw<i64>,
    sync_interval_ms: Raw<i64>,
    json_channels: Raw<JsonChannels>,
    annotations: Raw<bool>,
}

impl RawRecord {
    /// Checks `[record]` whether or not it is enabled (`omnirow record` uses these settings
    /// too): whether it is enabled, and the options, with `frame_id` from `[camera]`.
    pub(crate) fn validate(self, frame_id: String, c: &mut Check) -> (bool, RecordOptions) {
        let sync_ms = c.range(
            "record.sync_interval_ms",
            &self.sync_interval_ms,
            1000,
            10,
            60_000,
        );
        let prefix = c.get(&self.prefix, "omnirow".to_string());
        if let Some(p) = &self.prefix {
            if prefix.is_empty() || prefix.contains('/') {
                c.bad(
                    "record.prefix",
                    p,
                    "must be a non-empty file name part without '/'",
                );
            }
        }
        let options = RecordOptions {
            dir: PathBuf::from(c.get(&self.dir, "/var/lib/omnirow".to_string())),
            prefix,
            rotate_bytes: c.range("record.rotate_mb", &self.rotate_mb, 4096, 0, 1 << 30) as u64
                * (1 << 20),
            rotate_after: Duration::from_secs_f64(c.range(
                "record.rotate_s",
                &self.rotate_s,
                600.0,
                0.0,
                1e7,
            )),
            reserve_bytes: c.range("record.reserve_mb", &self.reserve_mb, 1024, 0, 1 << 30) as u64
                * (1 << 20),
            sync_interval: Duration::from_millis(sync_ms as u64),
            frames: c.get(&self.frames, true),
            frame_id,
            calibration_toml: None,
            json_channels: c.get(&self.json_channels, JsonChannels::Json),
            annotations: c.get(&self.annotations, true),
            annotate: None,
        };
        (c.get(&self.enabled, false), options)
    }
}
