//! Random scenes for the paper's synthetic experiments (section IV-A).
//!
//! Owns [`Protocol`] and [`random_scene`], which draws a scene's settings from a seed:
//!
//! - [`Protocol::Table1`] (accuracy of the vanishing point, Table I): yaw uniform in
//!   ±30°, pitch uniform in ±10°, roll 0; background noise density 0.1; plant distance
//!   0.03 m, so that the rows are almost solid lines; no position noise, no weeds; the camera
//!   uniformly anywhere across one row spacing (lateral 0..0.5 m) and along one plant distance.
//! - [`Protocol::Table2`] (methods compared under heavy noise, Table II): yaw ±30°, pitch
//!   ±10°, roll ±3°; background noise density uniform in 0.1..0.6; plant distance uniform in
//!   0.03..0.25 m; plant position error along the row uniform in 0..0.05 m (sd) and across
//!   it 0..0.05 m (sd; the paper's "row distance" error, which bends the rows); 0..800 weeds
//!   within ±5 m of the camera; lateral 0..0.5 m. The paper's noise "is high which gives a
//!   lot of failures": these ranges make the better single method (Hough) fail on about a
//!   quarter of the fisheye and a few percent of the catadioptric images (seed 1, full
//!   resolution), where the earlier, milder ranges (noise 0.1..0.5, plant distance
//!   0.03..0.30 m, errors 0.03/0.02 m, 0..300 weeds) let it fail on none. Plant distances
//!   beyond about 0.25 m are left out on purpose: there, under this noise, the edge method
//!   finds almost no correct row (measured on seed 1: 1 correct of 137 edge rows over the 43
//!   images with a plant distance over 0.2 m, against 1139 of 2380 below), so the table
//!   would only measure the Hough method twice.
//!
//! The lens is the caller's choice (the paper alternates fisheye and catadioptric).
//! Everything else keeps the [`SynthOptions`] defaults (height 1 m, rows 0.5 m apart).

use super::options::SynthOptions;
use super::rng::Rng;

/// One of the paper's synthetic test protocols.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    /// Table I: random yaw and pitch, background noise 0.1, nearly solid rows.
    Table1,
    /// Table II: random heavy noise levels, plant distances, position errors and weeds.
    Table2,
}

/// The settings of random scene number `seed` under `protocol` (see the module's ranges).
pub fn random_scene(seed: u64, protocol: Protocol) -> SynthOptions {
    let mut rng = Rng::stream(seed, 100);
    let base = SynthOptions::default();
    let spacing = base.row_spacing_m;
    match protocol {
        Protocol::Table1 => {
            let plant_distance_m = 0.03;
            SynthOptions {
                yaw_deg: rng.range(-30.0, 30.0),
                pitch_deg: rng.range(-10.0, 10.0),
                lateral_m: rng.range(0.0, spacing),
                along_m: rng.range(0.0, plant_distance_m),
                plant_distance_m,
                noise: 0.1,
                ..base
            }
        }
        Protocol::Table2 => {
            let plant_distance_m = rng.range(0.03, 0.25);
            SynthOptions {
                yaw_deg: rng.range(-30.0, 30.0),
                pitch_deg: rng.range(-10.0, 10.0),
                roll_deg: rng.range(-3.0, 3.0),
                lateral_m: rng.range(0.0, spacing),
                along_m: rng.range(0.0, plant_distance_m),
                plant_distance_m,
                noise: rng.range(0.1, 0.6),
                along_sd_m: rng.range(0.0, 0.05),
                across_sd_m: rng.range(0.0, 0.05),
                weeds: rng.below(801) as usize,
                weed_area_half_m: 5.0,
                ..base
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenes_are_valid_deterministic_and_in_range() {
        for seed in 0..200 {
            for p in [Protocol::Table1, Protocol::Table2] {
                let o = random_scene(seed, p);
                o.validate().unwrap();
                assert_eq!(o, random_scene(seed, p));
                assert!(o.yaw_deg.abs() <= 30.0 && o.pitch_deg.abs() <= 10.0);
                match p {
                    Protocol::Table1 => {
                        assert_eq!(o.noise, 0.1);
                        assert_eq!(o.weeds, 0);
                        assert_eq!(o.roll_deg, 0.0);
                    }
                    Protocol::Table2 => {
                        assert!((0.1..=0.6).contains(&o.noise));
                        assert!((0.03..=0.25).contains(&o.plant_distance_m));
                        assert!(o.weeds <= 800);
                        assert!(o.across_sd_m <= 0.05 && o.along_sd_m <= 0.05);
                    }
                }
            }
        }
        assert_ne!(
            random_scene(1, Protocol::Table2),
            random_scene(2, Protocol::Table2)
        );
    }
}
