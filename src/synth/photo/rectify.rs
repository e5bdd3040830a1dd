//! A labelled perspective photograph of straight rows, rectified onto the ground plane.
//!
//! Owns the geometry from labelled rows to a homography image → ground: each row fitted as a
//! straight line (orthogonal least squares), the lines' common vanishing point, and the
//! ground plane of a pinhole with its principal point at the image centre, an assumed focal
//! length and no roll. The vanishing point gives the direction of the rows in the camera; no
//! roll (the camera's x axis level) gives the ground's normal; the known row spacing gives
//! the camera's height (the scale), fitted to all rows at once; the rows' lateral positions
//! after rectification must be evenly spaced within a tolerance. Every reason to refuse a
//! photograph is a [`Rejection`].

use nalgebra::{Matrix2, Matrix3, SymmetricEigen, Vector3};

/// How a photograph is rectified, and what it must satisfy.
#[derive(Debug, Clone, PartialEq)]
pub struct RectifyOptions {
    /// Distance between neighbouring rows on the ground, metres.
    pub row_spacing_m: f64,
    /// Focal length of the photograph, pixels; `None`: 0.8 × its larger side (a phone's main
    /// camera, about 64° across the larger side).
    pub focal_px: Option<f64>,
    /// A row is straight when its points lie within this RMS distance (pixels) of a line.
    pub straight_rms_px: f64,
    /// The rows meet in one vanishing point when each row's line passes the common point
    /// within this many pixels (its end farthest from the point moved to pass through it).
    pub concurrent_px: f64,
    /// Labelled rows spanning fewer scan lines are ignored.
    pub min_row_scan_lines: usize,
    /// At least this many rows must remain.
    pub min_rows: usize,
    /// After rectification, no row may lie farther than this fraction of the spacing from
    /// its place in the evenly spaced fit.
    pub evenness: f64,
}

impl Default for RectifyOptions {
    fn default() -> Self {
        RectifyOptions {
            row_spacing_m: 0.5,
            focal_px: None,
            straight_rms_px: 2.0,
            concurrent_px: 4.0,
            min_row_scan_lines: 40,
            min_rows: 3,
            evenness: 0.15,
        }
    }
}

/// Why a photograph cannot give a ground texture.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Rejection {
    #[error("{rows} labelled rows span at least {min_scan_lines} scan lines; at least {need} are needed")]
    TooFewRows {
        rows: usize,
        need: usize,
        min_scan_lines: usize,
    },
    #[error("row {row} is not straight: {rms_px:.2} px RMS from its line (limit {limit_px} px)")]
    NotStraight {
        row: usize,
        rms_px: f64,
        limit_px: f64,
    },
    #[error("the rows do not meet in one vanishing point: row {row} misses it by {miss_px:.1} px (limit {limit_px} px)")]
    NotConcurrent {
        row: usize,
        miss_px: f64,
        limit_px: f64,
    },
    #[error("the rows' vanishing point is not above them (rows at row {lowest_row:.0} and below, vanishing point at row {vp_row:.0}): not a view of rows receding ahead")]
    NotAhead { vp_row: f64, lowest_row: f64 },
    #[error("the rows are unevenly spaced after rectification: a row lies {worst_m:.3} m from its place (limit {limit_m:.3} m at {spacing_m} m spacing)")]
    Uneven {
        worst_m: f64,
        limit_m: f64,
        spacing_m: f64,
    },
    #[error("too little resolution: no stretch of at least {min_length_m} m along {rows} rows is sampled finer than {limit_m} m per pixel (finest {best_m:.3} m)")]
    Resolution {
        min_length_m: f64,
        rows: usize,
        limit_m: f64,
        best_m: f64,
    },
    #[error("{0}")]
    Geometry(String),
}

impl Rejection {
    /// A short name of the reason, for counting rejections.
    pub fn kind(&self) -> &'static str {
        match self {
            Rejection::TooFewRows { .. } => "too few rows",
            Rejection::NotStraight { .. } => "rows not straight",
            Rejection::NotConcurrent { .. } => "no common vanishing point",
            Rejection::NotAhead { .. } => "vanishing point not above the rows",
            Rejection::Uneven { .. } => "spacing uneven",
            Rejection::Resolution { .. } => "too little resolution",
            Rejection::Geometry(_) => "geometry",
        }
    }
}

/// One labelled row fitted as a line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowLine {
    /// The line a·col + b·row + c = 0 with a² + b² = 1.
    pub line: Vector3<f64>,
    /// RMS distance of the row's points from the line, pixels.
    pub rms_px: f64,
    /// The row's lowest point on the line (nearest the camera): (row, col).
    pub bottom: [f64; 2],
    /// The row's highest point on the line: (row, col).
    pub top: [f64; 2],
}

impl RowLine {
    /// Fits a line to (row, col) points by orthogonal least squares.
    pub fn fit(points: &[[f64; 2]]) -> Option<RowLine> {
        let n = points.len();
        if n < 2 {
            return None;
        }
        let (mr, mc) = points.iter().fold((0.0, 0.0), |(a, b), p| {
            (a + p[0] / n as f64, b + p[1] / n as f64)
        });
        let (mut srr, mut scc, mut src) = (0.0, 0.0, 0.0);
        for p in points {
            let (dr, dc) = (p[0] - mr, p[1] - mc);
            srr += dr * dr;
            scc += dc * dc;
            src += dr * dc;
        }
        // Direction of the line: the larger eigenvector of the scatter (row, col).
        let theta = 0.5 * (2.0 * src).atan2(srr - scc);
        let (dr, dc) = (theta.cos(), theta.sin());
        // Normal in (col, row) order: perpendicular to (dc, dr).
        let (a, b) = (dr, -dc);
        let c = -(a * mc + b * mr);
        let rms = (points
            .iter()
            .map(|p| (a * p[1] + b * p[0] + c).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt();
        let project = |p: &[f64; 2]| {
            let t = (p[0] - mr) * dr + (p[1] - mc) * dc;
            [mr + t * dr, mc + t * dc]
        };
        let (lo, hi) = points.iter().fold((points[0], points[0]), |(lo, hi), p| {
            (
                if p[0] > lo[0] { *p } else { lo },
                if p[0] < hi[0] { *p } else { hi },
            )
        });
        if !(rms.is_finite() && srr + scc > 0.0) {
            return None;
        }
        Some(RowLine {
            line: Vector3::new(a, b, c),
            rms_px: rms,
            bottom: project(&lo),
            top: project(&hi),
        })
    }
}

/// The common point (homogeneous: col, row, w) of lines with unit normals: the point whose
/// squared distances (pixels) from the lines sum least, or, for lines parallel in the image,
/// the point at infinity along them (w = 0, pointing up the image).
pub fn vanishing_point(lines: &[RowLine]) -> Vector3<f64> {
    let (mut saa, mut sab, mut sbb, mut sac, mut sbc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for l in lines {
        let (a, b, c) = (l.line.x, l.line.y, l.line.z);
        saa += a * a;
        sab += a * b;
        sbb += b * b;
        sac += a * c;
        sbc += b * c;
    }
    let det = saa * sbb - sab * sab;
    let n = lines.len().max(1) as f64;
    if det > 1e-10 * n * n {
        let col = (-sac * sbb + sbc * sab) / det;
        let row = (-sbc * saa + sac * sab) / det;
        return Vector3::new(col, row, 1.0);
    }
    // Parallel: the lines' direction (perpendicular to their mean normal), up the image.
    let eig = SymmetricEigen::new(Matrix2::new(saa, sab, sab, sbb));
    let i = eig.eigenvalues.imax();
    let nrm = eig.eigenvectors.column(i);
    let (dc, dr) = (-nrm[1], nrm[0]);
    if dr > 0.0 {
        Vector3::new(-dc, -dr, 0.0)
    } else {
        Vector3::new(dc, dr, 0.0)
    }
}

/// How far (pixels) a row's far end lies from the line joining its near end to the vanishing
/// point `v` (homogeneous).
fn miss_px(row: &RowLine, v: &Vector3<f64>) -> f64 {
    let p = Vector3::new(row.bottom[1], row.bottom[0], 1.0);
    let q = Vector3::new(row.top[1], row.top[0], 1.0);
    // The line through the bottom point and v, then the top point's distance from it.
    let l = p.cross(v);
    let norm = l.x.hypot(l.y);
    if norm == 0.0 {
        return 0.0;
    }
    (l.dot(&q) / norm).abs()
}

/// A rectified photograph: its homography to the ground and how well the rows fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Rectification {
    /// Image (col, row, 1) → ground (x, y, 1) metres: x along the rows away from the camera
    /// (0 below the camera), y across them to the left, row k at y = k·spacing.
    pub image_to_ground: Matrix3<f64>,
    pub ground_to_image: Matrix3<f64>,
    /// The rows' indices k (the rightmost row is 0), in the order of the input rows kept.
    pub row_index: Vec<i64>,
    /// Each kept row's distance from its place k·spacing, metres.
    pub row_residual_m: Vec<f64>,
    /// Each kept row's RMS distance from its line, pixels.
    pub row_rms_px: Vec<f64>,
    /// The vanishing point (col, row), pixels.
    pub vanishing_px: [f64; 2],
    /// The camera's height above the ground (metres) and its lateral position (y, metres).
    pub camera_height_m: f64,
    pub camera_y_m: f64,
    /// The focal length assumed, pixels.
    pub focal_px: f64,
    pub row_spacing_m: f64,
}

impl Rectification {
    /// Rectifies a `width` × `height` photograph whose rows are labelled as (row, col)
    /// polylines.
    pub fn new(
        rows: &[Vec<[f64; 2]>],
        width: u32,
        height: u32,
        opts: &RectifyOptions,
    ) -> Result<Self, Rejection> {
        let s = opts.row_spacing_m;
        if !(s.is_finite() && s > 0.0) {
            return Err(Rejection::Geometry(format!(
                "row spacing {s} m must be a positive length"
            )));
        }
        let long: Vec<&Vec<[f64; 2]>> = rows
            .iter()
            .filter(|r| row_scan_lines(r) >= opts.min_row_scan_lines as f64)
            .collect();
        if long.len() < opts.min_rows.max(2) {
            return Err(Rejection::TooFewRows {
                rows: long.len(),
                need: opts.min_rows.max(2),
                min_scan_lines: opts.min_row_scan_lines,
            });
        }
        let mut lines = Vec::with_capacity(long.len());
        for (i, pts) in long.iter().enumerate() {
            let l = RowLine::fit(pts)
                .ok_or_else(|| Rejection::Geometry(format!("row {i} has no extent to fit")))?;
            if l.rms_px > opts.straight_rms_px {
                return Err(Rejection::NotStraight {
                    row: i,
                    rms_px: l.rms_px,
                    limit_px: opts.straight_rms_px,
                });
            }
            lines.push(l);
        }
        let v = vanishing_point(&lines);
        for (i, l) in lines.iter().enumerate() {
            let miss = miss_px(l, &v);
            if miss > opts.concurrent_px {
                return Err(Rejection::NotConcurrent {
                    row: i,
                    miss_px: miss,
                    limit_px: opts.concurrent_px,
                });
            }
        }
        let f = opts
            .focal_px
            .unwrap_or(0.8 * width.max(height) as f64)
            .max(1.0);
        let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        let lowest = lines.iter().map(|l| l.top[0]).fold(f64::INFINITY, f64::min);
        let vp_row = if v.z.abs() > 1e-12 {
            v.y / v.z
        } else if v.y <= 0.0 {
            f64::NEG_INFINITY
        } else {
            f64::INFINITY
        };
        if vp_row.is_nan() || vp_row >= lowest {
            return Err(Rejection::NotAhead {
                vp_row,
                lowest_row: lowest,
            });
        }
        let h0 = unit_homography(&v, f, cx, cy)?;
        Self::scale_to_spacing(h0, &lines, &v, f, opts)
    }

    /// Fits the camera height and the rows' indices so that the rows lie at k·spacing.
    fn scale_to_spacing(
        h0: Matrix3<f64>,
        lines: &[RowLine],
        v: &Vector3<f64>,
        f: f64,
        opts: &RectifyOptions,
    ) -> Result<Self, Rejection> {
        let s = opts.row_spacing_m;
        // Each row's lateral position (camera height 1) at its nearest point.
        let mut gy = Vec::with_capacity(lines.len());
        for (i, l) in lines.iter().enumerate() {
            let g = h0 * Vector3::new(l.bottom[1], l.bottom[0], 1.0);
            if g.z <= 0.0 {
                return Err(Rejection::Geometry(format!(
                    "row {i} reaches above the horizon"
                )));
            }
            gy.push(g.y / g.z);
        }
        let (k, a, b) = even_fit(&gy, s, opts.evenness)?;
        let height = s / b;
        let residual: Vec<f64> = k
            .iter()
            .zip(&gy)
            .map(|(&x, &g)| (g - a - b * x as f64) * height)
            .collect();
        let worst = residual.iter().fold(0.0f64, |m, r| m.max(r.abs()));
        if worst > opts.evenness * s {
            return Err(Rejection::Uneven {
                worst_m: worst,
                limit_m: opts.evenness * s,
                spacing_m: s,
            });
        }
        // Metric ground: scale by the height, then shift so that row k sits at k·s.
        let shift = Matrix3::new(height, 0.0, 0.0, 0.0, height, -height * a, 0.0, 0.0, 1.0);
        let image_to_ground = shift * h0;
        let ground_to_image = image_to_ground
            .try_inverse()
            .ok_or_else(|| Rejection::Geometry("the rectification is singular".into()))?;
        Ok(Rectification {
            image_to_ground,
            ground_to_image,
            row_index: k,
            row_residual_m: residual,
            row_rms_px: lines.iter().map(|l| l.rms_px).collect(),
            vanishing_px: if v.z.abs() > 1e-12 {
                [v.x / v.z, v.y / v.z]
            } else {
                [f64::INFINITY, f64::INFINITY]
            },
            camera_height_m: height,
            camera_y_m: -height * a,
            focal_px: f,
            row_spacing_m: s,
        })
    }

    /// The ground point (x, y) metres of image point (row, col); `None` above the horizon.
    pub fn to_ground(&self, row: f64, col: f64) -> Option<[f64; 2]> {
        let g = self.image_to_ground * Vector3::new(col, row, 1.0);
        (g.z > 1e-12).then(|| [g.x / g.z, g.y / g.z])
    }

    /// The image point (row, col) of ground point (x, y); `None` behind the camera.
    pub fn to_image(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let p = self.ground_to_image * Vector3::new(x, y, 1.0);
        (p.z > 1e-12).then(|| [p.y / p.z, p.x / p.z])
    }

    /// The ground length (metres) one pixel spans at ground point (x, y): the longer of its
    /// row and column steps; infinite where the pixel reaches the horizon.
    pub fn ground_sampling_m(&self, x: f64, y: f64) -> f64 {
        let Some([r, c]) = self.to_image(x, y) else {
            return f64::INFINITY;
        };
        let step = |dr: f64, dc: f64| match self.to_ground(r + dr, c + dc) {
            Some(g) => (g[0] - x).hypot(g[1] - y),
            None => f64::INFINITY,
        };
        step(1.0, 0.0).max(step(0.0, 1.0))
    }
}

/// The rows' indices k and the line gy = a + b·k through their lateral positions `gy`
/// (camera height 1), the smallest gap taken as one spacing (a row missing from the labels
/// leaves a double gap). Rejects rows that fall on one index.
fn even_fit(gy: &[f64], s: f64, evenness: f64) -> Result<(Vec<i64>, f64, f64), Rejection> {
    let mut order: Vec<usize> = (0..gy.len()).collect();
    order.sort_by(|&a, &b| gy[a].total_cmp(&gy[b]));
    let unit = order
        .windows(2)
        .map(|w| gy[w[1]] - gy[w[0]])
        .fold(f64::INFINITY, f64::min);
    if unit.is_nan() || unit <= 1e-9 {
        return Err(Rejection::Geometry(
            "two labelled rows lie on the same line".into(),
        ));
    }
    let base = gy[order[0]];
    let k: Vec<i64> = gy
        .iter()
        .map(|&g| ((g - base) / unit).round() as i64)
        .collect();
    let mut sorted_k: Vec<i64> = order.iter().map(|&i| k[i]).collect();
    sorted_k.dedup();
    if sorted_k.len() != k.len() {
        return Err(Rejection::Uneven {
            worst_m: 0.5 * s,
            limit_m: evenness * s,
            spacing_m: s,
        });
    }
    let n = k.len() as f64;
    let mk = k.iter().sum::<i64>() as f64 / n;
    let mg = gy.iter().sum::<f64>() / n;
    let skk: f64 = k.iter().map(|&x| (x as f64 - mk).powi(2)).sum();
    let skg: f64 = k
        .iter()
        .zip(gy)
        .map(|(&x, &g)| (x as f64 - mk) * (g - mg))
        .sum();
    let b = skg / skk;
    Ok((k, mg - b * mk, b))
}

/// Scan lines a polyline spans.
fn row_scan_lines(points: &[[f64; 2]]) -> f64 {
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[0]), hi.max(p[0]))
        });
    if hi >= lo {
        hi - lo + 1.0
    } else {
        0.0
    }
}

/// Image (col, row, 1) → ground (x, y, 1) for a camera 1 m above the ground, for the
/// vanishing point `v` (homogeneous col, row, w) of a pinhole (focal `f`, principal point
/// (cx, cy)) with its x axis level.
fn unit_homography(v: &Vector3<f64>, f: f64, cx: f64, cy: f64) -> Result<Matrix3<f64>, Rejection> {
    let k_inv = Matrix3::new(1.0 / f, 0.0, -cx / f, 0.0, 1.0 / f, -cy / f, 0.0, 0.0, 1.0);
    // The rows' direction in the camera frame (x right, y down, z forward).
    let mut d = k_inv * v;
    if d.z < 0.0 || (d.z == 0.0 && d.y > 0.0) {
        d = -d;
    }
    let d = d.normalize();
    // Up: perpendicular to the rows and to the level camera x axis.
    let up = Vector3::x().cross(&d);
    if up.norm() < 1e-6 {
        return Err(Rejection::Geometry(
            "the rows run across the image (level with the camera's x axis)".into(),
        ));
    }
    let up = up.normalize();
    let left = up.cross(&d);
    let basis = Matrix3::from_rows(&[d.transpose(), left.transpose(), -up.transpose()]);
    Ok(basis * k_inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a level pinhole (f 300, 512×512) 1.2 m high, pitched 40° down, yawed 8° to
    /// the rows, 0.1 m left of row 0; rows 0.5 m apart from −3 to 3, as (row, col) polylines
    /// from 1 m to 12 m ahead.
    fn view() -> Vec<Vec<[f64; 2]>> {
        view_of(0.7, 0.14, 1.2, 0.1)
    }

    /// The rows seen by the level pinhole at `pitch` below the horizon and `yaw` to the rows
    /// (radians), `h` metres high and `y_cam` metres left of row 0.
    fn view_of(pitch: f64, yaw: f64, h: f64, y_cam: f64) -> Vec<Vec<[f64; 2]>> {
        let (f, c) = (300.0, 255.5);
        let project = |x: f64, y: f64| -> Option<[f64; 2]> {
            // World: x ahead, y left, z up; camera at (0, y_cam, h).
            let (dx, dy, dz) = (x, y - y_cam, -h);
            // Yaw about z, then pitch about the camera's level x axis.
            let (fx, fy) = (
                dx * yaw.cos() + dy * yaw.sin(),
                -dx * yaw.sin() + dy * yaw.cos(),
            );
            let right = -fy;
            let fwd = fx * pitch.cos() - dz * pitch.sin();
            let down = -fx * pitch.sin() - dz * pitch.cos();
            (fwd > 0.1).then(|| [c + f * down / fwd, c + f * right / fwd])
        };
        (-3..=3)
            .filter_map(|k| {
                let pts: Vec<[f64; 2]> = (0..200)
                    .filter_map(|i| project(1.0 + i as f64 * 0.055, k as f64 * 0.5))
                    .filter(|p| (0.0..511.0).contains(&p[0]) && (0.0..511.0).contains(&p[1]))
                    .collect();
                (pts.len() > 20).then_some(pts)
            })
            .collect()
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(32))]
        /// Any level view of three rows or more rectifies exactly: the camera's height and
        /// its place across the rows (modulo the spacing) recovered, every row at k·spacing.
        #[test]
        fn any_level_view_is_recovered(
            pitch in 0.35f64..1.2, yaw in -0.3f64..0.3, h in 0.5f64..2.5, y_cam in -1.0f64..1.0,
        ) {
            let rows = view_of(pitch, yaw, h, y_cam);
            proptest::prop_assume!(rows.len() >= 3);
            let r = Rectification::new(&rows, 512, 512, &opts()).unwrap();
            proptest::prop_assert!((r.camera_height_m - h).abs() < 1e-6 * h);
            let d = (r.camera_y_m - y_cam).rem_euclid(0.5);
            proptest::prop_assert!(d.min(0.5 - d) < 1e-6, "{} vs {y_cam}", r.camera_y_m);
            for (pts, &k) in rows.iter().zip(&r.row_index) {
                let g = r.to_ground(pts[0][0], pts[0][1]).unwrap();
                proptest::prop_assert!((g[1] - k as f64 * 0.5).abs() < 1e-6);
            }
        }
    }

    fn opts() -> RectifyOptions {
        RectifyOptions {
            focal_px: Some(300.0),
            min_row_scan_lines: 10,
            ..Default::default()
        }
    }

    #[test]
    fn recovers_an_exact_view() {
        let rows = view();
        assert!(rows.len() >= 4, "{}", rows.len());
        let r = Rectification::new(&rows, 512, 512, &opts()).unwrap();
        assert!(
            (r.camera_height_m - 1.2).abs() < 1e-6,
            "{}",
            r.camera_height_m
        );
        // The camera is 0.1 m left of a row: its y is 0.1 modulo the spacing.
        let y = r.camera_y_m.rem_euclid(0.5);
        assert!((y - 0.1).abs() < 1e-6, "{y}");
        for e in &r.row_residual_m {
            assert!(e.abs() < 1e-6);
        }
        // Image → ground → image round trip, and rows along x at k·spacing.
        for (pts, &k) in rows.iter().zip(&r.row_index) {
            for p in pts.iter().step_by(7) {
                let g = r.to_ground(p[0], p[1]).unwrap();
                assert!((g[1] - k as f64 * 0.5).abs() < 1e-6, "{g:?} {k}");
                let q = r.to_image(g[0], g[1]).unwrap();
                assert!((q[0] - p[0]).abs() < 1e-6 && (q[1] - p[1]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn rejections_name_their_reason() {
        let rows = view();
        let e = Rectification::new(&rows[..2], 512, 512, &opts()).unwrap_err();
        assert!(matches!(e, Rejection::TooFewRows { rows: 2, .. }), "{e}");
        // A bent row.
        let mut bent = rows.clone();
        let n = bent[1].len();
        for (i, p) in bent[1].iter_mut().enumerate() {
            p[1] += 0.002 * (i as f64 - n as f64 / 2.0).powi(2);
        }
        let e = Rectification::new(&bent, 512, 512, &opts()).unwrap_err();
        assert!(matches!(e, Rejection::NotStraight { row: 1, .. }), "{e}");
        assert!(e.to_string().contains("not straight"), "{e}");
        // A straight row turned away from the others' vanishing point.
        let mut turned = rows.clone();
        let bottom = turned[2].iter().fold(0.0f64, |m, p| m.max(p[0]));
        for p in turned[2].iter_mut() {
            p[1] += 0.08 * (bottom - p[0]);
        }
        let e = Rectification::new(&turned, 512, 512, &opts()).unwrap_err();
        assert!(matches!(e, Rejection::NotConcurrent { .. }), "{e}");
        // Rows converging downwards: the vanishing point below them.
        let flipped: Vec<Vec<[f64; 2]>> = rows
            .iter()
            .map(|r| r.iter().map(|p| [511.0 - p[0], p[1]]).collect())
            .collect();
        let e = Rectification::new(&flipped, 512, 512, &opts()).unwrap_err();
        assert!(matches!(e, Rejection::NotAhead { .. }), "{e}");
    }

    #[test]
    fn uneven_rows_are_rejected() {
        // Move one middle row a fifth of the spacing on the ground: rebuild its polyline
        // through the vanishing point from a shifted bottom point.
        let rows = view();
        let r = Rectification::new(&rows, 512, 512, &opts()).unwrap();
        let k = r.row_index[3] as f64 * 0.5 + 0.1;
        let shifted: Vec<[f64; 2]> = (0..100)
            .filter_map(|i| r.to_image(1.5 + i as f64 * 0.06, k))
            .filter(|p| (0.0..511.0).contains(&p[0]) && (0.0..511.0).contains(&p[1]))
            .collect();
        let mut uneven = rows.clone();
        uneven[3] = shifted;
        let e = Rectification::new(&uneven, 512, 512, &opts()).unwrap_err();
        match e {
            Rejection::Uneven { worst_m, .. } => assert!(worst_m > 0.075, "{worst_m}"),
            other => panic!("{other}"),
        }
    }
}
