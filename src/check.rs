//! Checks of configuration values: what every section of the node's configuration turns its
//! raw TOML values into typed settings with.
//!
//! Owns [`Check`], which collects a [`Finding`] (the key, where its value is in the file,
//! what is wrong) for every impossible value, so that all problems of a file are reported at
//! once, and the common checks (defaults, ranges, socket addresses). Each section keeps its
//! raw struct (every value a [`Raw`], i.e. with its span) and its checks next to the code it
//! configures; [`crate::config`] composes the sections and turns findings into errors that
//! name the file and the line.

use std::fmt;
use std::net::SocketAddr;
use toml::Spanned;

/// An optional configuration value with its span in the file.
pub type Raw<T> = Option<Spanned<T>>;

/// One impossible value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// The dotted key, e.g. `pipeline.frame_queue`.
    pub key: String,
    /// The byte offset of the value in the file (None: no position).
    pub at: Option<usize>,
    pub message: String,
}

/// Collects the findings of a configuration's checks.
#[derive(Debug, Default)]
pub struct Check {
    findings: Vec<Finding>,
}

impl Check {
    /// Records that the value of `key` is impossible.
    pub fn bad<T>(&mut self, key: &str, v: &Spanned<T>, message: impl Into<String>) {
        self.bad_at(key.into(), Some(v.span().start), message.into());
    }

    /// Records a problem at byte offset `at` (e.g. a whole table's, for the sections that
    /// check themselves).
    pub fn bad_at(&mut self, key: String, at: Option<usize>, message: String) {
        self.findings.push(Finding { key, at, message });
    }

    /// The value, or the default when absent.
    pub fn get<T: Clone>(&self, v: &Raw<T>, default: T) -> T {
        v.as_ref().map(|s| s.get_ref().clone()).unwrap_or(default)
    }

    /// A number in `lo..=hi` (the default when absent or out of range).
    pub fn range<T>(&mut self, key: &str, v: &Raw<T>, default: T, lo: T, hi: T) -> T
    where
        T: Copy + PartialOrd + fmt::Display,
    {
        match v {
            None => default,
            Some(s) => {
                let x = *s.get_ref();
                // `!(lo <= x && x <= hi)` also rejects NaN.
                if !(lo <= x && x <= hi) {
                    self.bad(key, s, format!("{x} is out of range ({lo} ..= {hi})"));
                    default
                } else {
                    x
                }
            }
        }
    }

    /// A socket address (`host:port`).
    pub fn addr(&mut self, key: &str, v: &Spanned<String>) -> Option<SocketAddr> {
        match v.get_ref().parse::<SocketAddr>() {
            Ok(a) => Some(a),
            Err(_) => {
                self.bad(
                    key,
                    v,
                    format!(
                        "`{}` is not an address:port (e.g. 127.0.0.1:7447 or [::1]:7447)",
                        v.get_ref()
                    ),
                );
                None
            }
        }
    }

    /// Every finding, in the order the checks ran.
    pub fn into_findings(self) -> Vec<Finding> {
        self.findings
    }
}
