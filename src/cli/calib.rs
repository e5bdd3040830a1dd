//! `omnirow calib`: show a calibration, write one of the ideal lens models omnirow ships, or
//! convert a ROS camera_info YAML into omnirow's perspective TOML form.

use crate::camera::{
    camera_info, Calibration, ConversionError, IdealLens, Mounting, Pinhole, PinholeToml,
};
use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum CalibCommand {
    /// Print the model: size, centre, field of view at the mask's radii and the inscribed
    /// radius, the horizon radius, and the worst pixel → ray → pixel round-trip error.
    Show {
        /// OCamCalib calib_results.txt or omnirow TOML calibration.
        file: PathBuf,
    },
    /// Write an ideal lens calibration (for the GC2450C's 2448×2050 sensor by default).
    Ideal {
        #[arg(value_enum)]
        lens: LensArg,
        #[arg(long, default_value_t = 2050)]
        height: u32,
        #[arg(long, default_value_t = 2448)]
        width: u32,
        /// Output format.
        #[arg(long, value_enum, default_value_t = Format::Toml)]
        format: Format,
    },
    /// Convert a ROS camera_info YAML (plumb_bob or equidistant) into omnirow's TOML
    /// calibration (a [pinhole] table) and print the conversion's error in pixels.
    FromCameraInfo {
        /// camera_info YAML: camera_calibration's file or a CameraInfo message.
        file: PathBuf,
        /// The omnirow TOML calibration to write.
        #[arg(long, value_name = "FILE.toml")]
        out: PathBuf,
    },
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum LensArg {
    Fisheye185,
    Pal,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Format {
    Toml,
    Ocamcalib,
}

impl From<LensArg> for IdealLens {
    fn from(l: LensArg) -> Self {
        match l {
            LensArg::Fisheye185 => IdealLens::Fisheye185,
            LensArg::Pal => IdealLens::Pal,
        }
    }
}

pub fn run(cmd: CalibCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        CalibCommand::Show { file } => {
            let cal = Calibration::load(&file)?;
            print!("{}", describe(&cal));
            // A perspective calibration: how far its Taylor model lands from it.
            let text = std::fs::read_to_string(&file).unwrap_or_default();
            if let Ok(raw) = toml::from_str::<PinholeToml>(&text) {
                if let Ok((_, err)) = raw.pinhole.to_calibration(raw.mask, raw.mounting) {
                    println!("{}", conversion_line(&raw.pinhole, &err));
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        CalibCommand::FromCameraInfo { file, out } => {
            anyhow::ensure!(
                out.extension().is_some_and(|e| e == "toml"),
                "--out {}: omnirow's calibration is TOML; give a .toml file name",
                out.display()
            );
            let pinhole = camera_info::load(&file)?;
            let (_, err) = pinhole
                .to_calibration(None, Mounting::default())
                .map_err(|p| anyhow::anyhow!("{}: {p}", file.display()))?;
            let line = conversion_line(&pinhole, &err);
            let raw = PinholeToml {
                pinhole,
                mask: None,
                mounting: Mounting::default(),
            };
            let text = format!(
                "# Converted by omnirow calib from-camera-info from {}.\n# {line}\n# Set [mounting] to the camera's pose on the robot (see config/calibration.example.toml).\n\n{}",
                file.display(),
                raw.to_toml()
            );
            std::fs::write(&out, text).with_context(|| format!("writing {}", out.display()))?;
            println!("{line}");
            eprintln!("calib: wrote {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        CalibCommand::Ideal {
            lens,
            height,
            width,
            format,
        } => {
            let cal = IdealLens::from(lens).calibration(height, width)?;
            let text = match format {
                Format::Toml => cal.to_toml(),
                Format::Ocamcalib => cal.model.to_ocamcalib_text(),
            };
            use std::io::Write;
            std::io::stdout()
                .write_all(text.as_bytes())
                .context("writing to stdout")?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The conversion's error as one line.
fn conversion_line(p: &Pinhole, e: &ConversionError) -> String {
    let tangential = p.distortion_model == crate::camera::DistortionModel::PlumbBob
        && p.d.iter().skip(2).take(2).any(|&v| v != 0.0);
    format!(
        "conversion      Taylor model vs the pinhole over the image: max {:.4} px at row {:.0}, col {:.0}, RMS {:.4} px ({} pixels){}",
        e.max_px,
        e.worst_at[0],
        e.worst_at[1],
        e.rms_px,
        e.samples,
        if tangential {
            "; tangential distortion (p1, p2) has no Taylor counterpart"
        } else {
            ""
        }
    )
}

/// A human-readable description of a calibration (what `calib show` prints).
pub fn describe(cal: &Calibration) -> String {
    let m = &cal.model;
    let deg = |a: f64| a.to_degrees();
    let mut s = String::new();
    s.push_str(&format!(
        "image size      {} x {} (height x width)\n",
        m.height, m.width
    ));
    s.push_str(&format!(
        "centre          row {:.3}, col {:.3}\n",
        m.xc, m.yc
    ));
    s.push_str(&format!("affine          c {} d {} e {}\n", m.c, m.d, m.e));
    s.push_str(&format!(
        "polynomials     {} direct, {} inverse coefficients\n",
        m.ss.len(),
        m.invpol.len()
    ));
    let (tlo, thi) = m.theta_range();
    s.push_str(&format!(
        "model range     {:.2} deg .. {:.2} deg from the optical axis (rho <= {:.1} px)\n",
        deg(tlo) + 90.0,
        deg(thi) + 90.0,
        m.rho_valid_max()
    ));
    let inscribed = cal.inscribed_radius_px();
    s.push_str(&format!(
        "inscribed       radius {:.1} px: {:.2} deg from the axis\n",
        inscribed,
        deg(m.angle_at_radius(inscribed.min(m.rho_valid_max())))
    ));
    match cal.mask {
        Some(mask) => s.push_str(&format!(
            "mask            inner {:.1} px ({:.2} deg), outer {:.1} px ({:.2} deg)\n",
            mask.inner_radius_px,
            deg(m.angle_at_radius(mask.inner_radius_px)),
            mask.outer_radius_px,
            deg(m.angle_at_radius(mask.outer_radius_px.min(m.rho_valid_max())))
        )),
        None => s.push_str("mask            none (found from the image)\n"),
    }
    match cal.horizon_radius_px() {
        Some(r) => s.push_str(&format!(
            "horizon         radius {r:.1} px (90 deg from the axis)\n"
        )),
        None => s.push_str("horizon         not reached (the lens sees less than 90 deg)\n"),
    }
    let (worst, at) = cal.worst_round_trip_px(4);
    s.push_str(&format!(
        "round trip      worst {worst:.2e} px at row {:.0}, col {:.0} (pixel -> ray -> pixel, every 4th pixel)\n",
        at[0], at[1]
    ));
    let mt = cal.mounting;
    s.push_str(&format!(
        "mounting        roll {} pitch {} yaw {} deg after looking down, image top forward\n",
        mt.roll_deg, mt.pitch_deg, mt.yaw_deg
    ));
    s
}
