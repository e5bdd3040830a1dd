//! The `[guidance]` section of the node's configuration.
//!
//! Owns [`GuidanceConfig`] (serde, unknown keys rejected) and its conversion into the typed,
//! validated [`GuidanceOptions`]; a problem names its key (`guidance.<key>`).

use super::{GuidanceOptions, Mode, TrackerOptions};
use serde::{Deserialize, Serialize};

/// `[guidance]` as the file says it. Every key optional; the defaults are
/// [`GuidanceOptions::default`] and [`TrackerOptions::default`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GuidanceConfig {
    /// Row guidance on every estimate (the `guidance` object of schema 2).
    pub enabled: bool,
    pub mode: Mode,
    /// The field's row spacing, metres (0: estimated from the rows).
    pub row_spacing_m: f64,
    pub fixed_spacing: bool,
    pub min_spacing_m: f64,
    pub max_spacing_m: f64,
    pub tool_point_m: [f64; 2],
    pub max_roll_deg: f64,
    pub min_rows: usize,
    pub row_sd_m: f64,
    pub heading_sd_deg: f64,
    pub spacing_tolerance: f64,
    /// Odometry older than this is ignored (the configured speed is used), seconds.
    pub odometry_max_age_s: f64,
    /// Forward speed, m/s (0: unknown).
    pub speed_mps: f64,
    pub offset_rate_sd: f64,
    pub heading_rate_sd: f64,
    pub curvature_rate_sd: f64,
    pub spacing_rate_sd: f64,
    pub gate_chi2: f64,
    pub coast_s: f64,
}

impl Default for GuidanceConfig {
    fn default() -> Self {
        let o = GuidanceOptions::default();
        let t = o.tracker;
        GuidanceConfig {
            enabled: true,
            mode: o.mode,
            row_spacing_m: o.row_spacing_m.unwrap_or(0.0),
            fixed_spacing: o.fixed_spacing,
            min_spacing_m: o.min_spacing_m,
            max_spacing_m: o.max_spacing_m,
            tool_point_m: o.tool_point_m,
            max_roll_deg: o.max_roll_deg,
            min_rows: o.min_rows,
            row_sd_m: o.row_sd_m,
            heading_sd_deg: 0.1, // GuidanceOptions::default().heading_sd_rad in degrees
            spacing_tolerance: o.spacing_tolerance,
            odometry_max_age_s: o.odometry_max_age_s,
            speed_mps: t.speed_mps,
            offset_rate_sd: t.offset_rate_sd,
            heading_rate_sd: t.heading_rate_sd,
            curvature_rate_sd: t.curvature_rate_sd,
            spacing_rate_sd: t.spacing_rate_sd,
            gate_chi2: t.gate_chi2,
            coast_s: t.coast_s,
        }
    }
}

impl GuidanceConfig {
    /// The typed options (`None` when guidance is off), or the problem naming its key.
    pub fn options(&self) -> Result<Option<GuidanceOptions>, String> {
        let o = GuidanceOptions {
            mode: self.mode,
            row_spacing_m: (self.row_spacing_m != 0.0).then_some(self.row_spacing_m),
            fixed_spacing: self.fixed_spacing,
            min_spacing_m: self.min_spacing_m,
            max_spacing_m: self.max_spacing_m,
            tool_point_m: self.tool_point_m,
            max_roll_deg: self.max_roll_deg,
            min_rows: self.min_rows,
            row_sd_m: self.row_sd_m,
            heading_sd_rad: self.heading_sd_deg.to_radians(),
            spacing_tolerance: self.spacing_tolerance,
            odometry_max_age_s: self.odometry_max_age_s,
            tracker: TrackerOptions {
                speed_mps: self.speed_mps,
                offset_rate_sd: self.offset_rate_sd,
                heading_rate_sd: self.heading_rate_sd,
                curvature_rate_sd: self.curvature_rate_sd,
                spacing_rate_sd: self.spacing_rate_sd,
                gate_chi2: self.gate_chi2,
                coast_s: self.coast_s,
                ..TrackerOptions::default()
            },
        };
        o.validate().map_err(|e| match e {
            super::GuidanceError::Options(m) => m.replace("heading_sd_rad", "heading_sd_deg"),
        })?;
        Ok(self.enabled.then_some(o))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_and_keys_checked() {
        let c: GuidanceConfig = toml::from_str("").unwrap();
        assert_eq!(c.options().unwrap(), Some(GuidanceOptions::default()));
        let c: GuidanceConfig =
            toml::from_str("mode = \"over_row\"\nrow_spacing_m = 0.75\nspeed_mps = 1.5\n").unwrap();
        let o = c.options().unwrap().unwrap();
        assert_eq!(o.mode, Mode::OverRow);
        assert_eq!(o.row_spacing_m, Some(0.75));
        assert_eq!(o.tracker.speed_mps, 1.5);
        assert!(toml::from_str::<GuidanceConfig>("spacing = 1\n").is_err());
        let c: GuidanceConfig = toml::from_str("fixed_spacing = true\n").unwrap();
        assert!(c.options().unwrap_err().contains("row_spacing_m"));
        let c: GuidanceConfig = toml::from_str("enabled = false\n").unwrap();
        assert_eq!(c.options().unwrap(), None);
    }
}
