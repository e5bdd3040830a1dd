//! Scaramuzza's Taylor model exactly as OCamCalib writes it (`calib_results.txt`).
//!
//! Owns the polynomial camera model: parsing the OCamCalib text format (quirks included),
//! pixel → unit ray (`cam2world`), unit ray → pixel (`world2cam`, with the inverse
//! polynomial refined on the direct one and a numeric fallback where the inverse fit is
//! not valid), and rescaling to another resolution by a uniform factor.
//!
//! Frame: OCamCalib's native frame — x along image rows (down), y along image columns
//! (right), z = f(rho); scene points in front of the lens have z < 0. Pixels are
//! (row, col), 0-based, pixel centres at integer coordinates.

use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// An error reading or validating an OCamCalib calibration. Names the file, the line and the problem.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    #[error("{path}: cannot read calibration: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}:{line}: {problem}")]
    Parse {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
}

/// The five sections of an OCamCalib file, in file order.
const SECTIONS: [&str; 5] = [
    "direct polynomial (ss)",
    "inverse polynomial (invpol)",
    "centre (row col)",
    "affine parameters (c d e)",
    "image size (height width)",
];

/// Number of samples of the monotone rho → theta table used for the numeric inverse.
const TABLE_SAMPLES: usize = 1024;

/// The largest image side a calibration may name, in pixels. The largest machine-vision
/// sensors are about 14 000 pixels wide; a side beyond this is a typing error, and a model
/// checked pixel by pixel over it would take minutes to load.
pub const MAX_IMAGE_SIDE: u32 = 20_000;

/// Scaramuzza/OCamCalib Taylor camera model.
#[derive(Debug, Clone, PartialEq)]
pub struct OcamModel {
    /// Direct polynomial f(rho), ascending powers (`ss[0] + ss[1] rho + ...`).
    pub ss: Vec<f64>,
    /// Inverse polynomial rho(theta), ascending powers.
    pub invpol: Vec<f64>,
    /// Centre row (0-based).
    pub xc: f64,
    /// Centre column (0-based).
    pub yc: f64,
    /// Affine parameters: (row-xc, col-yc) = [c d; e 1] (x, y).
    pub c: f64,
    pub d: f64,
    pub e: f64,
    /// Image height in pixels (rows).
    pub height: u32,
    /// Image width in pixels (columns).
    pub width: u32,
    /// Largest rho (affine-corrected pixels) over which theta(rho) increases monotonically.
    rho_valid_max: f64,
    /// theta at rho = 0 and at `rho_valid_max`.
    theta_min: f64,
    theta_max: f64,
    /// Monotone table of theta(rho) at `TABLE_SAMPLES` equally spaced rho in [0, rho_valid_max].
    theta_table: Vec<f64>,
}

#[inline]
fn horner(coeffs: &[f64], x: f64) -> f64 {
    coeffs.iter().rev().fold(0.0, |acc, &c| acc * x + c)
}

/// f(x) and f'(x) by Horner.
#[inline]
fn horner_d(coeffs: &[f64], x: f64) -> (f64, f64) {
    let mut p = 0.0;
    let mut dp = 0.0;
    for &c in coeffs.iter().rev() {
        dp = dp * x + p;
        p = p * x + c;
    }
    (p, dp)
}

impl OcamModel {
    /// Builds a model from its parts, checking that it is usable.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ss: Vec<f64>,
        invpol: Vec<f64>,
        centre: (f64, f64),
        affine: (f64, f64, f64),
        size: (u32, u32),
    ) -> Result<Self, String> {
        let (xc, yc) = centre;
        let (c, d, e) = affine;
        let (height, width) = size;
        if ss.len() < 2 {
            return Err(format!(
                "direct polynomial needs at least 2 coefficients, has {}",
                ss.len()
            ));
        }
        if invpol.is_empty() {
            return Err("inverse polynomial has no coefficients".into());
        }
        let scalars = [xc, yc, c, d, e];
        if ss
            .iter()
            .chain(invpol.iter())
            .chain(scalars.iter())
            .any(|v| !v.is_finite())
        {
            return Err("a coefficient is not a finite number".into());
        }
        if ss[0] >= 0.0 {
            return Err(format!(
                "ss[0] = {} must be negative (OCamCalib: the principal point looks along -z)",
                ss[0]
            ));
        }
        let det = c - d * e;
        if det.abs() < 1e-9 {
            return Err(format!(
                "affine matrix [c d; e 1] is singular (c - d*e = {det})"
            ));
        }
        if height == 0 || width == 0 {
            return Err(format!("image size {height}x{width} is empty"));
        }
        if height > MAX_IMAGE_SIDE || width > MAX_IMAGE_SIDE {
            return Err(format!(
                "image size {height}x{width} has a side over {MAX_IMAGE_SIDE} pixels"
            ));
        }
        let mut m = OcamModel {
            ss,
            invpol,
            xc,
            yc,
            c,
            d,
            e,
            height,
            width,
            rho_valid_max: 0.0,
            theta_min: 0.0,
            theta_max: 0.0,
            theta_table: Vec::new(),
        };
        m.build_table()?;
        Ok(m)
    }

    /// theta(rho) = atan2(f(rho), rho): elevation of the ray from the plane perpendicular to the axis.
    #[inline]
    pub fn theta_of_rho(&self, rho: f64) -> f64 {
        horner(&self.ss, rho).atan2(rho)
    }

    fn build_table(&mut self) -> Result<(), String> {
        // Search rho up to twice the farthest image corner for the monotone range of
        // theta(rho): the whole sensor, and directions beyond it (a vanishing point outside
        // the image still has a pixel position).
        let h = self.height as f64;
        let w = self.width as f64;
        let corners = [
            (0.0, 0.0),
            (0.0, w - 1.0),
            (h - 1.0, 0.0),
            (h - 1.0, w - 1.0),
        ];
        let rho_search = corners
            .iter()
            .map(|&(r, c)| {
                let (x, y) = self.undistort_affine(r, c);
                (x * x + y * y).sqrt()
            })
            .fold(0.0, f64::max)
            * 2.0;
        let fine = 8 * TABLE_SAMPLES;
        let mut prev = self.theta_of_rho(0.0);
        let mut rho_max = rho_search;
        for i in 1..=fine {
            let rho = rho_search * i as f64 / fine as f64;
            let t = self.theta_of_rho(rho);
            if t <= prev {
                rho_max = rho_search * (i - 1) as f64 / fine as f64;
                break;
            }
            prev = t;
        }
        if rho_max <= 0.0 {
            return Err("direct polynomial gives no monotone range of ray angles".into());
        }
        self.rho_valid_max = rho_max;
        self.theta_table = (0..TABLE_SAMPLES)
            .map(|i| self.theta_of_rho(rho_max * i as f64 / (TABLE_SAMPLES - 1) as f64))
            .collect();
        self.theta_min = self.theta_table[0];
        self.theta_max = self.theta_table[TABLE_SAMPLES - 1];
        Ok(())
    }

    /// (row - xc, col - yc) → ideal sensor coordinates (x, y) through the inverse affine matrix.
    #[inline]
    fn undistort_affine(&self, row: f64, col: f64) -> (f64, f64) {
        let invdet = 1.0 / (self.c - self.d * self.e);
        let dr = row - self.xc;
        let dc = col - self.yc;
        (
            invdet * (dr - self.d * dc),
            invdet * (-self.e * dr + self.c * dc),
        )
    }

    /// Pixel (row, col) → unit ray in the OCamCalib frame (Scaramuzza's `cam2world`).
    #[inline]
    pub fn cam2world(&self, row: f64, col: f64) -> Vector3<f64> {
        let (xp, yp) = self.undistort_affine(row, col);
        let r = (xp * xp + yp * yp).sqrt();
        let zp = horner(&self.ss, r);
        Vector3::new(xp, yp, zp).normalize()
    }

    /// [`OcamModel::cam2world`] of every (row, col) in `pixels`, appended to `out`: the same
    /// rays to the bit, four pixels at a time so that their polynomials' long chains of
    /// dependent multiply-adds overlap.
    pub fn cam2world_many(&self, pixels: &[[f64; 2]], out: &mut Vec<Vector3<f64>>) {
        out.reserve(pixels.len());
        let mut quads = pixels.chunks_exact(4);
        for q in &mut quads {
            let mut x = [0.0; 4];
            let mut y = [0.0; 4];
            let mut r = [0.0; 4];
            for l in 0..4 {
                (x[l], y[l]) = self.undistort_affine(q[l][0], q[l][1]);
                r[l] = (x[l] * x[l] + y[l] * y[l]).sqrt();
            }
            let mut z = [0.0; 4];
            for &c in self.ss.iter().rev() {
                for l in 0..4 {
                    z[l] = z[l] * r[l] + c;
                }
            }
            for l in 0..4 {
                out.push(Vector3::new(x[l], y[l], z[l]).normalize());
            }
        }
        for p in quads.remainder() {
            out.push(self.cam2world(p[0], p[1]));
        }
    }

    /// The raw OCamCalib `world2cam` with the inverse polynomial as published, no validity check.
    pub fn world2cam_invpol(&self, ray: &Vector3<f64>) -> [f64; 2] {
        let norm = (ray.x * ray.x + ray.y * ray.y).sqrt();
        if norm == 0.0 {
            return [self.xc, self.yc];
        }
        let theta = (ray.z / norm).atan();
        let rho = horner(&self.invpol, theta);
        self.ideal_to_pixel(ray.x / norm * rho, ray.y / norm * rho)
    }

    #[inline]
    fn ideal_to_pixel(&self, x: f64, y: f64) -> [f64; 2] {
        [x * self.c + y * self.d + self.xc, x * self.e + y + self.yc]
    }

    /// rho for a ray elevation theta, solved on the direct polynomial (the inverse polynomial is
    /// used only as a starting point). `None` outside the monotone range of the model.
    pub fn rho_of_theta(&self, theta: f64) -> Option<f64> {
        if !(theta >= self.theta_min && theta <= self.theta_max) {
            return None;
        }
        // Bracket from the table (binary search), then safeguarded Newton.
        let t = &self.theta_table;
        let n = t.len();
        let step = self.rho_valid_max / (n - 1) as f64;
        let idx = t.partition_point(|&v| v < theta).clamp(1, n - 1);
        let (mut lo, mut hi) = ((idx - 1) as f64 * step, idx as f64 * step);
        let guess = horner(&self.invpol, theta);
        let mut rho = if guess > lo && guess < hi {
            guess
        } else {
            let (t0, t1) = (t[idx - 1], t[idx]);
            lo + (hi - lo) * ((theta - t0) / (t1 - t0)).clamp(0.0, 1.0)
        };
        for _ in 0..30 {
            // g(rho) = atan2(f, rho) - theta; g' = (f' rho - f) / (rho^2 + f^2)
            let (f, df) = horner_d(&self.ss, rho);
            let g = f.atan2(rho) - theta;
            if g.abs() < 1e-15 {
                break;
            }
            if g > 0.0 {
                hi = rho;
            } else {
                lo = rho;
            }
            let dg = (df * rho - f) / (rho * rho + f * f);
            let mut next = rho - g / dg;
            if !(next > lo && next < hi && next.is_finite()) {
                next = 0.5 * (lo + hi);
            }
            if (next - rho).abs() < 1e-12 {
                rho = next;
                break;
            }
            rho = next;
        }
        Some(rho)
    }

    /// Unit ray (any length) → pixel (row, col). `None` where the ray lies outside the
    /// range of angles the model describes. The pixel may lie outside the image.
    #[inline]
    pub fn world2cam(&self, ray: &Vector3<f64>) -> Option<[f64; 2]> {
        let norm = (ray.x * ray.x + ray.y * ray.y).sqrt();
        if norm == 0.0 {
            return if ray.z < 0.0 {
                Some([self.xc, self.yc])
            } else {
                None
            };
        }
        let theta = (ray.z / norm).atan();
        let rho = self.rho_of_theta(theta)?;
        Some(self.ideal_to_pixel(ray.x / norm * rho, ray.y / norm * rho))
    }

    /// The largest rho (ideal pixels) over which the model is monotone (valid).
    pub fn rho_valid_max(&self) -> f64 {
        self.rho_valid_max
    }

    /// Range of ray elevations theta (radians) the model describes.
    pub fn theta_range(&self) -> (f64, f64) {
        (self.theta_min, self.theta_max)
    }

    /// Angle of a ray from the optical axis (-z), radians.
    pub fn off_axis_angle(ray: &Vector3<f64>) -> f64 {
        let norm = (ray.x * ray.x + ray.y * ray.y).sqrt();
        norm.atan2(-ray.z)
    }

    /// Radius in pixels (distance from the centre, image coordinates) at which rays make
    /// `angle` radians with the optical axis, measured along the image's column axis.
    pub fn radius_at_angle(&self, angle: f64) -> Option<f64> {
        let theta = angle - std::f64::consts::FRAC_PI_2;
        self.rho_of_theta(theta)
    }

    /// Angle from the optical axis (radians) of the rays at `radius` ideal pixels from the centre.
    pub fn angle_at_radius(&self, radius: f64) -> f64 {
        self.theta_of_rho(radius) + std::f64::consts::FRAC_PI_2
    }

    /// The same camera at another resolution: `factor` = old size / new size (2 for half
    /// resolution). A new pixel (r, c) covers old pixels factor·r .. factor·r + factor − 1,
    /// so its centre is at factor·r + (factor − 1)/2 in the old calibration.
    pub fn rescaled(&self, factor: f64) -> Result<Self, String> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(format!("rescale factor {factor} must be positive"));
        }
        let h = self.height as f64 / factor;
        let w = self.width as f64 / factor;
        if (h - h.round()).abs() > 1e-6 || (w - w.round()).abs() > 1e-6 {
            return Err(format!(
                "{}x{} is not divisible by the factor {factor}",
                self.height, self.width
            ));
        }
        self.reduced(factor, (h.round() as u32, w.round() as u32))
    }

    /// The camera seen through an image reduced by an integer `factor` whose size is rounded
    /// down: new pixel (r, c) covers old pixels factor·r .. factor·r + factor − 1 as in
    /// [`OcamModel::rescaled`], and the old pixels past the last whole block are cropped.
    pub fn reduced_cropped(&self, factor: u32) -> Result<Self, String> {
        if factor == 0 {
            return Err("reduction factor 0 must be at least 1".into());
        }
        let (h, w) = (self.height / factor, self.width / factor);
        if h == 0 || w == 0 {
            return Err(format!(
                "{}x{} reduced by {factor} leaves no pixel",
                self.height, self.width
            ));
        }
        self.reduced(factor as f64, (h, w))
    }

    fn reduced(&self, factor: f64, (h, w): (u32, u32)) -> Result<Self, String> {
        let off = (factor - 1.0) / 2.0;
        let ss = self
            .ss
            .iter()
            .enumerate()
            .map(|(k, &a)| a * factor.powi(k as i32 - 1))
            .collect();
        let invpol = self.invpol.iter().map(|&a| a / factor).collect();
        OcamModel::new(
            ss,
            invpol,
            ((self.xc - off) / factor, (self.yc - off) / factor),
            (self.c, self.d, self.e),
            (h, w),
        )
    }

    /// Parses an OCamCalib `calib_results.txt` from text. `path` is used in error messages only.
    pub fn parse(text: &str, path: &Path) -> Result<Self, CalibError> {
        let perr = |line: usize, problem: String| CalibError::Parse {
            path: path.to_path_buf(),
            line,
            problem,
        };
        let mut rows: Vec<(usize, Vec<f64>)> = Vec::with_capacity(5);
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let lineno = i + 1;
            let section = SECTIONS[rows.len()];
            let mut nums = Vec::new();
            for tok in line.split_whitespace() {
                let v: f64 = tok
                    .parse()
                    .map_err(|_| perr(lineno, format!("{section}: '{tok}' is not a number")))?;
                nums.push(v);
            }
            rows.push((lineno, nums));
            if rows.len() == 5 {
                break;
            }
        }
        let poly = |(line, nums): &(usize, Vec<f64>), name: &str| -> Result<Vec<f64>, CalibError> {
            let n = nums[0];
            if n.fract() != 0.0 || n < 1.0 {
                return Err(perr(
                    *line,
                    format!("{name}: leading coefficient count {n} is not a positive integer"),
                ));
            }
            let n = n as usize;
            if nums.len() - 1 != n {
                return Err(perr(
                    *line,
                    format!(
                        "{name}: the line announces {n} coefficients but holds {}",
                        nums.len() - 1
                    ),
                ));
            }
            Ok(nums[1..].to_vec())
        };
        for (i, row) in rows.iter().enumerate().take(2) {
            poly(row, SECTIONS[i])?;
        }
        if rows.len() < 5 {
            let last = text.lines().count();
            return Err(perr(
                last.max(1),
                format!(
                    "file ends before the {} section (found {} of 5 sections)",
                    SECTIONS[rows.len()],
                    rows.len()
                ),
            ));
        }
        let ss = poly(&rows[0], SECTIONS[0])?;
        let invpol = poly(&rows[1], SECTIONS[1])?;
        let exact = |idx: usize, count: usize| -> Result<&[f64], CalibError> {
            let (line, nums) = &rows[idx];
            if nums.len() != count {
                return Err(perr(
                    *line,
                    format!(
                        "{}: expected {count} numbers, found {}",
                        SECTIONS[idx],
                        nums.len()
                    ),
                ));
            }
            Ok(nums)
        };
        let centre = exact(2, 2)?;
        let affine = exact(3, 3)?;
        let size = exact(4, 2)?;
        let size_line = rows[4].0;
        let dim = |v: f64, what: &str| -> Result<u32, CalibError> {
            if v.fract() != 0.0 || !(1.0..=MAX_IMAGE_SIDE as f64).contains(&v) {
                return Err(perr(
                    size_line,
                    format!(
                        "image size: {what} {v} is not a whole number of pixels in 1..={MAX_IMAGE_SIDE}"
                    ),
                ));
            }
            Ok(v as u32)
        };
        let height = dim(size[0], "height")?;
        let width = dim(size[1], "width")?;
        let (line_of_poly, line_of_affine) = (rows[0].0, rows[3].0);
        OcamModel::new(
            ss,
            invpol,
            (centre[0], centre[1]),
            (affine[0], affine[1], affine[2]),
            (height, width),
        )
        .map_err(|problem| {
            let line = if problem.contains("affine") {
                line_of_affine
            } else {
                line_of_poly
            };
            perr(line, problem)
        })
    }

    /// Reads an OCamCalib `calib_results.txt` file.
    pub fn load(path: &Path) -> Result<Self, CalibError> {
        let text = std::fs::read_to_string(path).map_err(|source| CalibError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Writes the model in OCamCalib's own format (as `export_data.m` does).
    pub fn to_ocamcalib_text(&self) -> String {
        let mut s = String::new();
        s.push_str("#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). These are used by cam2world\n\n");
        s.push_str(&format!("{} ", self.ss.len()));
        for v in &self.ss {
            s.push_str(&format!("{v:e} "));
        }
        s.push_str("\n\n#polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB). These are used by world2cam\n\n");
        s.push_str(&format!("{} ", self.invpol.len()));
        for v in &self.invpol {
            s.push_str(&format!("{v} "));
        }
        s.push_str(&format!(
            "\n\n#center: \"row\" and \"column\", starting from 0 (C convention)\n\n{} {}\n\n#affine parameters \"c\", \"d\", \"e\"\n\n{} {} {}\n\n#image size: \"height\" and \"width\"\n\n{} {}\n",
            self.xc, self.yc, self.c, self.d, self.e, self.height, self.width
        ));
        s
    }

    /// Fits an inverse polynomial rho(theta) of the given degree over the model's valid range
    /// (least squares on the direct polynomial), as OCamCalib's `findinvpoly.m` does.
    pub fn fit_invpol(ss: &[f64], rho_max: f64, degree: usize) -> Vec<f64> {
        let n = 400;
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, degree + 1);
        let mut b = nalgebra::DVector::<f64>::zeros(n);
        for i in 0..n {
            let rho = rho_max * i as f64 / (n - 1) as f64;
            let theta = horner(ss, rho).atan2(rho);
            let mut p = 1.0;
            for k in 0..=degree {
                a[(i, k)] = p;
                p *= theta;
            }
            b[i] = rho;
        }
        let svd = a.svd(true, true);
        let x = svd
            .solve(&b, 1e-14)
            .unwrap_or_else(|_| nalgebra::DVector::zeros(degree + 1));
        x.iter().copied().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> OcamModel {
        let text = "#c\n\n5 -4.714441e+02 0.000000e+00 7.356108e-04 -3.773045e-07 5.800006e-10 \n\n#i\n\n10 772.405470 504.754051 7.034666 45.327180 54.651570 0.458049 -7.873745 15.588713 13.743404 2.968883 \n\n#c\n\n794.308657 798.175741\n\n#a\n\n1.000305 -0.000277 -0.000925\n\n#s\n\n1600 1600\n";
        OcamModel::parse(text, Path::new("mem")).unwrap()
    }

    proptest::proptest! {
        /// Four pixels at a time give the rays one pixel at a time gives, to the bit (and
        /// the remainder after the last four too).
        #[test]
        fn cam2world_many_is_cam2world(
            pixels in proptest::collection::vec((-100.0f64..1700.0, -100.0f64..1700.0), 0..23),
        ) {
            let m = sample();
            let pixels: Vec<[f64; 2]> = pixels.into_iter().map(|(r, c)| [r, c]).collect();
            let mut many = vec![Vector3::zeros()];
            m.cam2world_many(&pixels, &mut many);
            proptest::prop_assert_eq!(many.len(), pixels.len() + 1);
            for (p, r) in pixels.iter().zip(&many[1..]) {
                let one = m.cam2world(p[0], p[1]);
                proptest::prop_assert!(
                    one.iter().zip(r.iter()).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{p:?}: {one:?} and {r:?}"
                );
            }
        }
    }

    #[test]
    fn centre_maps_to_minus_z() {
        let m = sample();
        let r = m.cam2world(m.xc, m.yc);
        assert!((r - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
    }

    #[test]
    fn round_trip_komatsu() {
        let m = sample();
        let mut worst: f64 = 0.0;
        for row in (0..1600).step_by(37) {
            for col in (0..1600).step_by(41) {
                let (x, y) = m.undistort_affine(row as f64, col as f64);
                if (x * x + y * y).sqrt() > m.rho_valid_max() {
                    continue;
                }
                let ray = m.cam2world(row as f64, col as f64);
                let p = m.world2cam(&ray).unwrap();
                worst = worst.max((p[0] - row as f64).hypot(p[1] - col as f64));
            }
        }
        assert!(worst < 1e-6, "worst {worst}");
    }

    #[test]
    fn rescale_half_matches_full() {
        let m = sample();
        let h = m.rescaled(2.0).unwrap();
        assert_eq!((h.height, h.width), (800, 800));
        for &(r, c) in &[(0.0, 0.0), (100.0, 250.0), (399.0, 399.0), (799.0, 10.0)] {
            let a = h.cam2world(r, c);
            let b = m.cam2world(2.0 * r + 0.5, 2.0 * c + 0.5);
            assert!((a - b).norm() < 1e-12, "{r},{c}");
        }
        assert!(m.rescaled(3.0).is_err());
    }

    #[test]
    fn reduce_cropped_keeps_whole_blocks() {
        let m = sample();
        let t = m.reduced_cropped(3).unwrap();
        assert_eq!((t.height, t.width), (533, 533));
        for &(r, c) in &[(0.0, 0.0), (100.0, 250.0), (532.0, 532.0), (17.0, 400.0)] {
            let a = t.cam2world(r, c);
            let b = m.cam2world(3.0 * r + 1.0, 3.0 * c + 1.0);
            assert!((a - b).norm() < 1e-12, "{r},{c}");
        }
        assert_eq!(m.reduced_cropped(2).unwrap(), m.rescaled(2.0).unwrap());
        assert!(m.reduced_cropped(0).is_err());
        assert!(m.reduced_cropped(2000).is_err());
    }

    #[test]
    fn bad_files_name_line() {
        let p = Path::new("bad.txt");
        let e = OcamModel::parse("", p).unwrap_err().to_string();
        assert!(
            e.contains("bad.txt") && e.contains("direct polynomial"),
            "{e}"
        );
        let e = OcamModel::parse("3 -1 0\n", p).unwrap_err().to_string();
        assert!(e.contains("bad.txt:1") && e.contains("announces 3"), "{e}");
        let e = OcamModel::parse("2 -1 0\n1 2\nx 3\n", p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.txt:3") && e.contains("'x'"), "{e}");
        let e = OcamModel::parse("2 -100 0\n1 2\n3 3\n0 0 0\n10 10\n", p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.txt:4") && e.contains("singular"), "{e}");
        let e = OcamModel::parse("2 -100 0\n1 2\n3 3\n1 0 0\n10\n", p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.txt:5") && e.contains("expected 2"), "{e}");
        let e = OcamModel::parse("2 -100 0\n1 2\n3 3\n1 0 0\n10 20001\n", p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.txt:5") && e.contains("width 20001"), "{e}");
        let big = (MAX_IMAGE_SIDE + 1, 10);
        let e = OcamModel::new(
            vec![-100.0, 0.0],
            vec![1.0],
            (0.0, 0.0),
            (1.0, 0.0, 0.0),
            big,
        );
        assert!(e.unwrap_err().contains("over 20000"));
    }
}

#[cfg(test)]
mod parse_props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Arbitrary text never panics the parser: it parses or names a line.
        #[test]
        fn arbitrary_text_never_panics(text in "[0-9eE+\\-. #\\nx]{0,200}") {
            if let Err(e) = OcamModel::parse(&text, Path::new("p.txt")) {
                prop_assert!(e.to_string().starts_with("p.txt"));
            }
        }

        /// Valid files with perturbed numbers either load or give an error, never a panic,
        /// and anything that loads round-trips its centre.
        #[test]
        fn perturbed_files_load_or_error(a0 in -2000.0f64..10.0, a2 in -1e-2f64..1e-2, c in -2.0f64..2.0, h in 0u32..3000, w in 0u32..3000) {
            let text = format!("3 {a0:e} 0 {a2:e}\n2 100 200\n{} {}\n{c} 0 0\n{h} {w}\n", h / 2, w / 2);
            if let Ok(m) = OcamModel::parse(&text, Path::new("q.txt")) {
                let r = m.cam2world(m.xc, m.yc);
                let p = m.world2cam(&r).unwrap();
                prop_assert!((p[0] - m.xc).abs() < 1e-6 && (p[1] - m.yc).abs() < 1e-6);
            }
        }
    }
}
