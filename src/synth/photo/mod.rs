//! A ground textured from a real labelled photograph, for the renderer in place of the
//! synthetic plants.
//!
//! Owns [`PhotoGround`]: a perspective photograph of straight rows with its rows labelled,
//! rectified onto the ground ([`Rectification`]: rows along x at y = k·spacing), a rectangle
//! between two rows that the photograph sees sharply enough ([`Region`]), and that
//! rectangle as a mirrored, mip-mapped texture ([`MirrorTexture`]) giving the ground's colour
//! g(x, y) anywhere on the plane. Built once; sampling allocates nothing. The labels arrive as
//! plain (row, col) polylines: reading label files is the caller's (the CLI reads them with
//! `eval::real::labels`). docs/synth.md, "A ground from your own photographs", states the
//! assumptions and how well they hold.

mod rectify;
mod texture;

pub use rectify::{vanishing_point, Rectification, RectifyOptions, Rejection, RowLine};
pub use texture::MirrorTexture;

/// A decoded photograph: row-major pixels without padding, 1 (grey) or 3 (RGB) bytes each.
#[derive(Debug, Clone, Copy)]
pub struct Photo<'a> {
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub data: &'a [u8],
}

impl Photo<'_> {
    /// Bilinear colour at (row, col), clamped to the image.
    fn at(&self, row: f64, col: f64) -> [f32; 3] {
        let (w, h) = (self.width as usize, self.height as usize);
        let (r, c) = (
            row.clamp(0.0, h as f64 - 1.0),
            col.clamp(0.0, w as f64 - 1.0),
        );
        let (r0, c0) = (r.floor() as usize, c.floor() as usize);
        let (r1, c1) = ((r0 + 1).min(h - 1), (c0 + 1).min(w - 1));
        let (tr, tc) = ((r - r0 as f64) as f32, (c - c0 as f64) as f32);
        let px = |r: usize, c: usize, k: usize| {
            let k = if self.channels == 1 { 0 } else { k };
            self.data[(r * w + c) * self.channels + k] as f32
        };
        let mut out = [0.0; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let top = px(r0, c0, k) * (1.0 - tc) + px(r0, c1, k) * tc;
            let bot = px(r1, c0, k) * (1.0 - tc) + px(r1, c1, k) * tc;
            *o = top * (1.0 - tr) + bot * tr;
        }
        out
    }
}

/// How a photograph becomes a ground texture.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoOptions {
    pub rectify: RectifyOptions,
    /// The texture's rectangle must be sampled finer than this (metres per pixel, the longer
    /// of a pixel's two sides on the ground) everywhere.
    pub max_sampling_m: f64,
    /// The rectangle must be at least this long along the rows, metres.
    pub min_length_m: f64,
    /// It is cut to at most this length, metres.
    pub max_length_m: f64,
    /// Texel size, metres.
    pub texel_m: f64,
    /// The rectangle keeps this many pixels from the photograph's edges.
    pub margin_px: f64,
    /// The rectangle spans at most this many row spacings across (1: the strip between the
    /// two rows nearest the camera; wider shows more of the photograph, with the plants'
    /// lean away from the camera displacing the outer rows).
    pub max_band_spacings: usize,
}

impl Default for PhotoOptions {
    fn default() -> Self {
        PhotoOptions {
            rectify: RectifyOptions::default(),
            max_sampling_m: 0.02,
            min_length_m: 1.0,
            max_length_m: 10.0,
            texel_m: 0.005,
            margin_px: 2.0,
            max_band_spacings: 1,
        }
    }
}

/// The rectangle of the ground a texture is cut from: x along the rows, y across them (its
/// sides along the rows lie on rows, so that mirroring keeps rows at k·spacing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    pub x: [f64; 2],
    pub y: [f64; 2],
    /// The coarsest ground sampling inside it, metres per pixel.
    pub worst_sampling_m: f64,
}

/// The ground of a labelled photograph, rectified and tiled.
#[derive(Clone, PartialEq)]
pub struct PhotoGround {
    rect: Rectification,
    region: Region,
    texture: MirrorTexture,
}

impl std::fmt::Debug for PhotoGround {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PhotoGround")
            .field("rect", &self.rect)
            .field("region", &self.region)
            .field("texels", &self.texture.size())
            .finish()
    }
}

impl PhotoGround {
    /// Rectifies `photo` through its labelled rows ((row, col) polylines) and cuts the
    /// texture; the rejection says why a photograph cannot serve.
    pub fn new(
        photo: &Photo,
        rows: &[Vec<[f64; 2]>],
        opts: &PhotoOptions,
    ) -> Result<Self, Rejection> {
        let expected = photo.width as usize * photo.height as usize * photo.channels;
        if !matches!(photo.channels, 1 | 3) || photo.data.len() != expected || expected == 0 {
            return Err(Rejection::Geometry(format!(
                "the photograph's buffer holds {} bytes, {}x{} with {} channels needs {expected}",
                photo.data.len(),
                photo.width,
                photo.height,
                photo.channels
            )));
        }
        if !(opts.texel_m.is_finite() && opts.texel_m >= 1e-4) {
            return Err(Rejection::Geometry(format!(
                "texel size {} m must be at least 0.1 mm",
                opts.texel_m
            )));
        }
        let rect = Rectification::new(rows, photo.width, photo.height, &opts.rectify)?;
        let region = usable_region(&rect, photo.width, photo.height, opts)?;
        // Texels fit the band across exactly, so that the mirror seams lie on its rows.
        let across = region.y[1] - region.y[0];
        let nrows = (across / opts.texel_m).round().max(1.0) as usize;
        let tau = across / nrows as f64;
        let cols = ((region.x[1] - region.x[0]) / tau).round().max(1.0) as usize;
        // Each texel: the mean of 2×2 points of the photograph inside it.
        let texture = MirrorTexture::new([region.x[0], region.y[0]], cols, nrows, tau, |x, y| {
            let mut acc = [0.0f32; 3];
            for (dx, dy) in [(-0.25, -0.25), (-0.25, 0.25), (0.25, -0.25), (0.25, 0.25)] {
                if let Some([r, c]) = rect.to_image(x + dx * tau, y + dy * tau) {
                    let p = photo.at(r, c);
                    for k in 0..3 {
                        acc[k] += 0.25 * p[k];
                    }
                }
            }
            acc.map(|v| (v + 0.5).clamp(0.0, 255.0) as u8)
        });
        Ok(PhotoGround {
            rect,
            region,
            texture,
        })
    }

    pub fn rectification(&self) -> &Rectification {
        &self.rect
    }

    pub fn region(&self) -> &Region {
        &self.region
    }

    pub fn row_spacing_m(&self) -> f64 {
        self.rect.row_spacing_m
    }

    /// The texture's finest texel size, metres.
    pub fn texel_m(&self) -> f64 {
        self.texture.texel_m()
    }

    /// Texels of the texture (along x, across y).
    pub fn texels(&self) -> (usize, usize) {
        self.texture.size()
    }

    /// The ground's colour (linear 0..255 RGB) at (x, y) metres, averaged over about `size`
    /// metres.
    #[inline]
    pub fn colour(&self, x: f64, y: f64, size: f64) -> [f32; 3] {
        self.texture.sample(x, y, size)
    }
}

/// What one band across the rows offers along x: its longest stretch in view and sampled
/// finely enough (start, length, coarsest sampling), and, for the rejection's message, the
/// longest stretch in view and the finest sampling met.
struct BandRun {
    sharp: Option<(f64, f64, f64)>,
    in_view_m: f64,
    finest_m: f64,
}

/// Scans band `y` (metres across) along x from the camera's foot in 1 cm steps.
fn band_run(
    rect: &Rectification,
    y: [f64; 2],
    width: u32,
    height: u32,
    opts: &PhotoOptions,
) -> BandRun {
    let m = opts.margin_px;
    let inside = |x: f64, y: f64| {
        rect.to_image(x, y).is_some_and(|[r, c]| {
            r >= m && c >= m && r <= height as f64 - 1.0 - m && c <= width as f64 - 1.0 - m
        })
    };
    let dx = 0.01;
    let steps = (60.0 * rect.camera_height_m / dx).clamp(100.0, 20_000.0) as usize;
    let mut out = BandRun {
        sharp: None,
        in_view_m: 0.0,
        finest_m: f64::INFINITY,
    };
    let (mut run_view, mut run_sharp) = (0usize, None::<(usize, f64)>);
    for i in 0..steps {
        let x = i as f64 * dx;
        if !(inside(x, y[0]) && inside(x, y[1])) {
            run_view = 0;
            run_sharp = None;
            continue;
        }
        run_view += 1;
        out.in_view_m = out.in_view_m.max(run_view as f64 * dx);
        let gsd = rect
            .ground_sampling_m(x, y[0])
            .max(rect.ground_sampling_m(x, y[1]));
        out.finest_m = out.finest_m.min(gsd);
        if gsd > opts.max_sampling_m {
            run_sharp = None;
            continue;
        }
        let run = run_sharp.get_or_insert((i, 0.0));
        run.1 = run.1.max(gsd);
        let (start, worst) = *run;
        let length = ((i - start) as f64 * dx).min(opts.max_length_m);
        if out.sharp.is_none_or(|b| length > b.1) {
            out.sharp = Some((start as f64 * dx, length, worst));
        }
    }
    out
}

/// The band of ground the texture is cut from: between two rows (its sides on rows, so that
/// mirroring makes every row symmetric about its labelled line), at most
/// `max_band_spacings` wide, in view at least `min_length_m` along the rows sampled finer
/// than `max_sampling_m` (cut to `max_length_m`); of those, the one nearest the camera's
/// lateral position (least parallax from the plants' height), then the largest.
fn usable_region(
    rect: &Rectification,
    width: u32,
    height: u32,
    opts: &PhotoOptions,
) -> Result<Region, Rejection> {
    let s = rect.row_spacing_m;
    let (k_lo, k_hi) = rect
        .row_index
        .iter()
        .fold((i64::MAX, i64::MIN), |(a, b), &k| (a.min(k), b.max(k)));
    let cam = rect.camera_y_m;
    let (mut best, mut in_view, mut finest) = (None::<(f64, f64, Region)>, 0.0f64, f64::INFINITY);
    for lo in k_lo..k_hi {
        for hi in lo + 1..=k_hi.min(lo + opts.max_band_spacings.max(1) as i64) {
            let y = [lo as f64 * s, hi as f64 * s];
            let run = band_run(rect, y, width, height, opts);
            in_view = in_view.max(run.in_view_m);
            finest = finest.min(run.finest_m);
            let Some((x0, length, worst)) = run.sharp.filter(|r| r.1 >= opts.min_length_m) else {
                continue;
            };
            let away = (y[0] - cam).max(cam - y[1]).max(0.0);
            let area = length * (y[1] - y[0]);
            let better =
                best.is_none_or(|(a, b, _)| away < a - 1e-9 || (away <= a + 1e-9 && area > b));
            if better {
                let region = Region {
                    x: [x0, x0 + length],
                    y,
                    worst_sampling_m: worst,
                };
                best = Some((away, area, region));
            }
        }
    }
    match best {
        Some((_, _, r)) => Ok(r),
        None if in_view < opts.min_length_m => Err(Rejection::Geometry(format!(
            "the photograph sees at most {in_view:.2} m of ground between two rows (at least {} m needed)",
            opts.min_length_m
        ))),
        None => Err(Rejection::Resolution {
            min_length_m: opts.min_length_m,
            rows: (k_hi - k_lo + 1) as usize,
            limit_m: opts.max_sampling_m,
            best_m: finest,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Calibration;
    use crate::synth::{GroundTruth, Renderer, Scene, Style, SynthOptions};
    use nalgebra::Vector3;
    use std::sync::Arc;

    fn pinhole() -> Calibration {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config/calib/pinhole_512_f300.toml");
        Calibration::load(&path).unwrap()
    }

    /// A photograph of the synthetic field through the forward pinhole (300 px focal length,
    /// 43° below the horizon), 1 m high, yawed 6° to the rows, 0.2 m left of row 0.
    fn field() -> SynthOptions {
        SynthOptions {
            yaw_deg: 6.0,
            lateral_m: 0.2,
            plant_distance_m: 0.05,
            leaf_length_m: 0.06,
            leaf_width_m: 0.025,
            style: Style::Colour,
            field_half_length_m: 40.0,
            field_half_width_m: 40.0,
            ..Default::default()
        }
    }

    fn render(cal: &Calibration, scene: &Scene) -> Vec<u8> {
        let mut r = Renderer::new(cal).unwrap().with_threads(2);
        let mut out = vec![0u8; r.buffer_len(scene.options.style)];
        r.render_into(scene, &mut out).unwrap();
        out
    }

    /// The rows' centre lines in the image from the scene's pose: (row, col) polylines, as a
    /// labeller would draw them.
    fn labels(cal: &Calibration, scene: &Scene) -> Vec<Vec<[f64; 2]>> {
        let s = scene.options.row_spacing_m;
        (-8..=8)
            .map(|k| {
                (0..400)
                    .filter_map(|i| {
                        let p = Vector3::new(0.3 + i as f64 * 0.05, k as f64 * s, 0.0);
                        cal.ray_to_pixel_in_fov(&scene.pose.direction_to(&p)?)
                    })
                    .collect::<Vec<_>>()
            })
            .filter(|pts| pts.len() >= 2)
            .collect()
    }

    fn photo_ground(focal_px: f64) -> (Calibration, Scene, Vec<u8>, PhotoGround) {
        let cal = pinhole();
        let scene = Scene::new(&field(), 1, &cal.mounting).unwrap();
        let img = render(&cal, &scene);
        let opts = PhotoOptions {
            rectify: RectifyOptions {
                focal_px: Some(focal_px),
                ..Default::default()
            },
            ..Default::default()
        };
        let photo = Photo {
            width: 512,
            height: 512,
            channels: 3,
            data: &img,
        };
        let ground = PhotoGround::new(&photo, &labels(&cal, &scene), &opts).unwrap();
        (cal, scene, img, ground)
    }

    /// Mean absolute difference (grey levels) of two RGB images over the pixels whose ground
    /// point lies inside `region` shrunk by 5 cm, and the number of such pixels.
    fn diff_in_region(a: &[u8], b: &[u8], rect: &Rectification, region: &Region) -> (f64, usize) {
        let (mut sum, mut n) = (0.0, 0usize);
        for r in 0..512 {
            for c in 0..512 {
                let Some([x, y]) = rect.to_ground(r as f64, c as f64) else {
                    continue;
                };
                let inside = x > region.x[0] + 0.05
                    && x < region.x[1] - 0.05
                    && y > region.y[0] + 0.05
                    && y < region.y[1] - 0.05;
                if inside {
                    let i = (r * 512 + c) * 3;
                    for k in 0..3 {
                        sum += (a[i + k] as f64 - b[i + k] as f64).abs() / 3.0;
                    }
                    n += 1;
                }
            }
        }
        (sum / n.max(1) as f64, n)
    }

    #[test]
    fn round_trip_through_a_pinhole_gives_the_known_truth() {
        let (cal, scene, img, ground) = photo_ground(300.0);
        let rect = ground.rectification();
        let s = 0.5;
        // The camera's height and lateral position (modulo the spacing), recovered.
        assert!((rect.camera_height_m - 1.0).abs() < 0.01, "{rect:?}");
        let y = rect.camera_y_m.rem_euclid(s);
        assert!((y - 0.2).abs() < 0.01, "camera y {y}");
        let worst = rect
            .row_residual_m
            .iter()
            .fold(0.0f64, |m, e| m.max(e.abs()));
        assert!(worst < 0.005, "{:?}", rect.row_residual_m);
        // Rows parallel at k·spacing: every ideal row point inside the region maps there.
        let shift = rect.camera_y_m - 0.2;
        let region = *ground.region();
        let mut checked = 0;
        for k in -8..=8 {
            for i in 0..200 {
                let p = Vector3::new(region.x[0] + i as f64 * 0.05, k as f64 * s, 0.0);
                if p.x > region.x[1] {
                    break;
                }
                let Some(px) = scene
                    .pose
                    .direction_to(&p)
                    .and_then(|d| cal.ray_to_pixel_in_fov(&d))
                else {
                    continue;
                };
                let g = rect.to_ground(px[0], px[1]).unwrap();
                assert!((g[1] - shift - p.y).abs() < 0.01, "{g:?} vs {p:?}");
                assert!((g[0] - p.x).abs() < 0.02 * p.x, "{g:?} vs {p:?}");
                checked += 1;
            }
        }
        assert!(checked > 50, "{checked}");
        // Re-imaged through the same pinhole from the recovered pose: the same picture
        // where the texture comes from, and the same truth.
        let again = SynthOptions {
            lateral_m: rect.camera_y_m,
            height_m: rect.camera_height_m,
            ..field()
        };
        let arc = Arc::new(ground.clone());
        let re = Scene::new(&again, 1, &cal.mounting)
            .unwrap()
            .with_photo_ground(arc.clone())
            .unwrap();
        let (same, n) = diff_in_region(&img, &render(&cal, &re), rect, &region);
        assert!(n > 5000, "{n}");
        let half = SynthOptions {
            lateral_m: rect.camera_y_m + s / 2.0,
            ..again.clone()
        };
        let off = Scene::new(&half, 1, &cal.mounting)
            .unwrap()
            .with_photo_ground(arc)
            .unwrap();
        let (shifted, _) = diff_in_region(&img, &render(&cal, &off), rect, &region);
        println!(
            "round trip: height {:.4} m, camera y {y:.4} m, worst row residual {worst:.5} m, region {region:?}, re-imaged difference {same:.1} grey levels (half a spacing off: {shifted:.1})",
            rect.camera_height_m
        );
        assert!(same < 10.0 && shifted > 2.0 * same, "{same} {shifted}");
        let (t0, t1) = (
            GroundTruth::of_scene(&scene, &cal),
            GroundTruth::of_scene(&re, &cal),
        );
        assert_eq!(t0.row_normals.len(), t1.row_normals.len());
        for (a, b) in t0.row_normals.iter().zip(&t1.row_normals) {
            let angle = Vector3::from(*a).angle(&Vector3::from(*b));
            assert!(angle < 0.01, "{angle}");
        }
    }

    #[test]
    fn a_wrong_focal_length_keeps_the_rows_and_scales_along_them() {
        // Guessing the focal length 1.5x too long: the rows stay straight and parallel, their
        // spacing stays even within the tolerance, the along-row scale is off.
        for f in [200.0, 450.0] {
            let (cal, scene, _, ground) = photo_ground(f);
            let rect = ground.rectification();
            let on_row = |x: f64| {
                let p = Vector3::new(x, 0.0, 0.0);
                let px = cal
                    .ray_to_pixel_in_fov(&scene.pose.direction_to(&p).unwrap())
                    .unwrap();
                rect.to_ground(px[0], px[1]).unwrap()
            };
            let (a, b) = (on_row(2.0), on_row(3.0));
            let along = (b[0] - a[0]).hypot(b[1] - a[1]);
            let worst = rect
                .row_residual_m
                .iter()
                .fold(0.0f64, |m, e| m.max(e.abs()));
            println!(
                "focal {f} px (true 300): 1 m along a row measures {along:.3} m, height {:.3} m, worst row residual {worst:.4} m",
                rect.camera_height_m
            );
            assert!((along - 1.0).abs() > 0.05, "{along}");
            assert!(worst < 0.075);
        }
    }

    #[test]
    fn no_sharp_stretch_is_a_resolution_rejection() {
        let cal = pinhole();
        let scene = Scene::new(&field(), 1, &cal.mounting).unwrap();
        let img = render(&cal, &scene);
        let photo = Photo {
            width: 512,
            height: 512,
            channels: 3,
            data: &img,
        };
        let opts = PhotoOptions {
            rectify: RectifyOptions {
                focal_px: Some(300.0),
                ..Default::default()
            },
            max_sampling_m: 0.002,
            ..Default::default()
        };
        let e = PhotoGround::new(&photo, &labels(&cal, &scene), &opts).unwrap_err();
        assert!(matches!(e, Rejection::Resolution { .. }), "{e}");
        assert!(e.to_string().contains("too little resolution"), "{e}");
        let e = PhotoGround::new(
            &Photo {
                data: &img[1..],
                ..photo
            },
            &[],
            &opts,
        )
        .unwrap_err();
        assert!(e.to_string().contains("bytes"), "{e}");
    }
}
