//! ROS `camera_info` YAML: the calibration file ROS's camera_calibration and
//! camera_info_manager write (`image_width`, `camera_matrix: {rows, cols, data}`,
//! `distortion_model`, `distortion_coefficients`), or a `sensor_msgs/CameraInfo` message as
//! YAML (`width`, `k`, `d`). Owns reading either into a [`Pinhole`]; errors name the file
//! (and the line, for YAML errors) as [`CalibError`]s.

use super::pinhole::{DistortionModel, Pinhole};
use super::CalibError;
use serde::Deserialize;
use std::path::Path;

/// A matrix as camera_calibration writes it (`{rows, cols, data}`) or as a message's flat list.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum Matrix {
    Table {
        rows: usize,
        cols: usize,
        data: Vec<f64>,
    },
    List(Vec<f64>),
}

impl Matrix {
    fn data(&self, what: &str, rows: usize, cols: Option<usize>) -> Result<&[f64], String> {
        let (data, shape) = match self {
            Matrix::Table { rows, cols, data } => (data, Some((*rows, *cols))),
            Matrix::List(d) => (d, None),
        };
        if let Some((r, c)) = shape {
            if r * c != data.len() {
                return Err(format!(
                    "{what}: rows {r} x cols {c} but {} numbers",
                    data.len()
                ));
            }
        }
        if let Some(c) = cols {
            if data.len() != rows * c {
                return Err(format!(
                    "{what}: {} numbers, expected {rows} x {c}",
                    data.len()
                ));
            }
        }
        Ok(data)
    }
}

/// The keys omnirow reads (others, such as the rectification and projection matrices or a
/// message's header, are ignored: a rectified image is not what the detector reads).
#[derive(Debug, Deserialize)]
struct Raw {
    #[serde(alias = "width")]
    image_width: u32,
    #[serde(alias = "height")]
    image_height: u32,
    #[serde(alias = "k")]
    camera_matrix: Matrix,
    #[serde(default)]
    distortion_model: Option<String>,
    #[serde(default, alias = "d")]
    distortion_coefficients: Option<Matrix>,
}

/// Parses camera_info YAML text (`path` names it in errors).
pub fn parse(text: &str, path: &Path) -> Result<Pinhole, CalibError> {
    let raw: Raw = serde_yaml_ng::from_str(text).map_err(|e| CalibError::Parse {
        path: path.to_path_buf(),
        line: e.location().map(|l| l.line()).unwrap_or(1),
        problem: e.to_string(),
    })?;
    let invalid = |problem: String| CalibError::Invalid {
        path: path.to_path_buf(),
        problem,
    };
    let k = raw
        .camera_matrix
        .data("camera_matrix", 3, Some(3))
        .map_err(invalid)?;
    if k[1] != 0.0 {
        return Err(invalid(format!(
            "camera_matrix: skew {} is not supported (omnirow's affine term is for the sensor's aspect only)",
            k[1]
        )));
    }
    let d = match &raw.distortion_coefficients {
        Some(m) => m
            .data("distortion_coefficients", 1, None)
            .map_err(invalid)?
            .to_vec(),
        None => Vec::new(),
    };
    let model = match raw.distortion_model.as_deref().unwrap_or("") {
        "" | "none" => DistortionModel::None,
        "plumb_bob" => DistortionModel::PlumbBob,
        "equidistant" | "fisheye" => DistortionModel::Equidistant,
        other => {
            return Err(invalid(format!(
                "distortion_model '{other}' is not supported (plumb_bob, equidistant)"
            )))
        }
    };
    let model = if model == DistortionModel::PlumbBob && d.iter().all(|&v| v == 0.0) {
        DistortionModel::None
    } else {
        model
    };
    let pinhole = Pinhole {
        width: raw.image_width,
        height: raw.image_height,
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
        distortion_model: model,
        d: if model == DistortionModel::None {
            Vec::new()
        } else {
            d
        },
    };
    pinhole.validate().map_err(invalid)?;
    Ok(pinhole)
}

/// Reads a camera_info YAML file.
pub fn load(path: &Path) -> Result<Pinhole, CalibError> {
    let text = std::fs::read_to_string(path).map_err(|source| CalibError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CALIBRATION_FILE: &str = "image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [500.5, 0, 319.5, 0, 502.0, 241.25, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.28, 0.07, 0.001, -0.0005, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [500, 0, 320, 0, 0, 500, 240, 0, 0, 0, 1, 0]
";

    #[test]
    fn reads_both_forms() {
        let p = parse(CALIBRATION_FILE, Path::new("c.yaml")).unwrap();
        assert_eq!((p.width, p.height), (640, 480));
        assert_eq!((p.fx, p.fy, p.cx, p.cy), (500.5, 502.0, 319.5, 241.25));
        assert_eq!(p.distortion_model, DistortionModel::PlumbBob);
        assert_eq!(p.d, vec![-0.28, 0.07, 0.001, -0.0005, 0.0]);
        let msg = "header:\n  frame_id: cam\nheight: 1200\nwidth: 1600\ndistortion_model: equidistant\nd: [0.1, -0.02, 0.003, 0.0]\nk: [600, 0, 800, 0, 600, 600, 0, 0, 1]\nbinning_x: 0\n";
        let p = parse(msg, Path::new("m.yaml")).unwrap();
        assert_eq!(p.distortion_model, DistortionModel::Equidistant);
        assert_eq!((p.width, p.height, p.cx), (1600, 1200, 800.0));
    }

    #[test]
    fn errors_name_the_file_and_the_problem() {
        let e = parse("image_width: [1]\n", Path::new("c.yaml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("c.yaml:1:"), "{e}");
        let bad = CALIBRATION_FILE.replace(
            "data: [500.5, 0, 319.5, 0, 502.0, 241.25, 0, 0, 1]",
            "data: [500.5, 0, 319.5]",
        );
        let e = parse(&bad, Path::new("c.yaml")).unwrap_err().to_string();
        assert!(
            e.contains("camera_matrix") && e.contains("3 numbers"),
            "{e}"
        );
        let bad = CALIBRATION_FILE.replace("plumb_bob", "rational_polynomial");
        let e = parse(&bad, Path::new("c.yaml")).unwrap_err().to_string();
        assert!(e.contains("rational_polynomial"), "{e}");
        let bad = CALIBRATION_FILE.replace("500.5, 0, 319.5", "-1, 0, 319.5");
        let e = parse(&bad, Path::new("c.yaml")).unwrap_err().to_string();
        assert!(e.contains("fx"), "{e}");
        let e = load(Path::new("/nonexistent.yaml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent.yaml"), "{e}");
    }
}
