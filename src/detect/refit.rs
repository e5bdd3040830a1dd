//! Precise refit of rows on the whole image (the last step of the paper's line fitting).
//!
//! Owns the final fit of each row's normal to every pixel near its great circle, not only the
//! thresholded points the Hough stage saw: each pixel's ray is weighted by its vegetation
//! value above the background times the solid angle it covers, so the fit is the intensity
//! centroid of the row on the sphere. The thresholded set alone biases a row by up to half a
//! pixel wherever the row runs along the pixel grid (its band's edges are quantised to whole
//! pixels); the soft, anti-aliased edges carry the missing sub-pixel information. Pixels are
//! visited by tiles: a tile is scanned only when its cone of rays meets the row's band.

use super::hough::fast_atan2;
use super::sections::{NearField, Sections, SECTION_BINS, SECTION_HUBER, SECTION_POWER};
use super::types::{DetectError, Detection, Row};
use crate::camera::OcamModel;
use crate::memory::prefetch;
use crate::sphere::{any_perpendicular, canonical, Fit, Scatter};
use multiversion::multiversion;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// `[detector.refit]`: the refit's option.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefitOptions {
    /// A curved row is published where it passes beside the robot: its cross-sections
    /// within this many metres ahead of and behind the camera's foot are fitted with a
    /// curvature, and where that is significant the row is turned about the vanishing point
    /// through its point there ([`Sections::near_foot`]; omnidirectional lenses, which see
    /// the row on both sides of the foot). About the reach the steering looks ahead; 0
    /// publishes each row's whole chord.
    pub near_reach_m: f64,
}

impl Default for RefitOptions {
    fn default() -> Self {
        RefitOptions { near_reach_m: 2.0 }
    }
}

impl RefitOptions {
    pub fn validate(&self) -> Result<(), DetectError> {
        let r = self.near_reach_m;
        if r.is_finite() && (0.0..=1000.0).contains(&r) {
            Ok(())
        } else {
            Err(DetectError::Options(format!(
                "refit.near_reach_m = {r} must be within 0..=1000"
            )))
        }
    }
}

/// Background level = median + this fraction of (threshold level − median); pixels below
/// it weigh nothing.
pub const BACKGROUND_FRACTION: f64 = 0.25;
/// A row's band is its Hough band widened by this many pixels, to take in the soft edges.
pub const MARGIN_PX: f64 = 1.5;
/// Pixel values are clipped at background + this fraction of (the row's median −
/// background), the median taken over the row's pixels above the background (mostly the
/// row's solid inside). A wide row's inside then weighs the same everywhere: the background
/// noise there (e.g. salt and pepper) no longer moves the centroid, while the anti-aliased
/// edges, which carry the sub-pixel position, keep their graded values.
pub const PLATEAU_CAP: f64 = 0.6;
/// A row's curvature near the robot counts when it is at least this many of its standard
/// deviations ([`Sections::near_foot`]).
pub const NEAR_MIN_SIGMA: f64 = 4.0;

/// What the refit measured of its rows, in buffers reused from image to image.
#[derive(Debug, Clone, Default)]
pub struct RowFits {
    /// Per row: the variance of its normal's component along the vanishing point (NaN where
    /// not estimated).
    pub along_var: Vec<f64>,
    /// The rows that bend near the robot ([`Sections::near_foot`]).
    pub feet: Vec<NearFoot>,
}

impl RowFits {
    pub fn with_capacity(rows: usize) -> Self {
        RowFits {
            along_var: Vec::with_capacity(rows),
            feet: Vec::with_capacity(rows),
        }
    }
}

/// A curved row's point beside the camera's foot, with the normal the refit gave the row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearFoot {
    pub normal: Vector3<f64>,
    /// Unit ray to the row's centre at the foot.
    pub foot: Vector3<f64>,
}

/// The curved rows of a refit (those with a foot, [`Sections::near_foot`]) turned about
/// `out`'s vanishing point through their point beside the robot: there the controller
/// steers. The vanishing point, found from the rows' whole chords, stays as it is.
pub fn turn_to_feet(out: &mut Detection, feet: &[NearFoot]) {
    let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
        return;
    };
    if feet.is_empty() {
        return;
    }
    for r in out.rows.iter_mut() {
        let turned = feet
            .iter()
            .find(|f| f.normal == r.normal)
            .and_then(|f| f.foot.cross(&vp).try_normalize(1e-9));
        if let Some(n) = turned {
            r.normal = canonical(&n);
        }
    }
}

/// The pixels a row's refit reads, reused from row to row: copied side by side as they are
/// collected (their rays, values and solid angles), so that each fit reads them in order
/// rather than gathering them from the image's tables, megabytes apart; and, where computed,
/// their angles along the row's starting great circle.
#[derive(Debug, Clone, Default)]
pub struct Candidates {
    rays: Vec<[f32; 3]>,
    values: Vec<u8>,
    solid: Vec<f32>,
    along: Vec<f32>,
    /// Scratch of the collection: the image-row stretches (first pixel, length) of the tiles
    /// the row's band meets.
    stretches: Vec<(u32, u32)>,
}

impl Candidates {
    pub fn with_capacity(pixels: usize) -> Self {
        Candidates {
            rays: Vec::with_capacity(pixels),
            values: Vec::with_capacity(pixels),
            solid: Vec::with_capacity(pixels),
            along: Vec::with_capacity(pixels),
            stretches: Vec::new(),
        }
    }

    fn len(&self) -> usize {
        self.rays.len()
    }

    fn clear(&mut self) {
        self.rays.clear();
        self.values.clear();
        self.solid.clear();
        self.along.clear();
    }

    fn truncate(&mut self, len: usize) {
        self.rays.truncate(len);
        self.values.truncate(len);
        self.solid.truncate(len);
    }
}

/// One row's fit.
#[derive(Debug, Clone, Copy)]
struct RowFit {
    normal: Option<Vector3<f64>>,
    along_var: f64,
    foot: Option<Vector3<f64>>,
}

impl Default for RowFit {
    fn default() -> Self {
        RowFit {
            normal: None,
            along_var: f64::NAN,
            foot: None,
        }
    }
}

/// A square of pixels with the cone that holds their rays.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tile {
    r0: u32,
    c0: u32,
    centre: [f32; 3],
    /// Angle (radians) from the centre ray to the farthest ray of the tile.
    radius: f32,
}

/// The tiles of a working image (built once per image size).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Tiles {
    size: usize,
    width: usize,
    height: usize,
    list: Vec<Tile>,
}

impl Tiles {
    /// Tiles of `size`×`size` pixels over an image whose valid pixels (`mask` ≠ 0) have `rays`.
    pub fn new(mask: &[u8], rays: &[[f32; 3]], width: usize, height: usize, size: usize) -> Self {
        let mut list = Vec::new();
        for r0 in (0..height).step_by(size) {
            for c0 in (0..width).step_by(size) {
                let mut sum = Vector3::<f64>::zeros();
                let mut any = false;
                for r in r0..(r0 + size).min(height) {
                    for c in c0..(c0 + size).min(width) {
                        let i = r * width + c;
                        if mask[i] != 0 {
                            let p = rays[i];
                            sum += Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                            any = true;
                        }
                    }
                }
                if !any || sum.norm() == 0.0 {
                    continue;
                }
                let centre = sum.normalize();
                let mut min_dot: f64 = 1.0;
                for r in r0..(r0 + size).min(height) {
                    for c in c0..(c0 + size).min(width) {
                        let i = r * width + c;
                        if mask[i] != 0 {
                            let p = rays[i];
                            let d =
                                centre.dot(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64));
                            min_dot = min_dot.min(d);
                        }
                    }
                }
                list.push(Tile {
                    r0: r0 as u32,
                    c0: c0 as u32,
                    centre: [centre.x as f32, centre.y as f32, centre.z as f32],
                    radius: (min_dot.clamp(-1.0, 1.0).acos() + 1e-4) as f32,
                });
            }
        }
        Tiles {
            size,
            width,
            height,
            list,
        }
    }
}

/// The working image as the refit reads it.
#[derive(Debug, Clone, Copy)]
pub struct RefitImage<'a> {
    /// Smoothed vegetation values.
    pub values: &'a [u8],
    pub mask: &'a [u8],
    pub rays: &'a [[f32; 3]],
    pub solid: &'a [f32],
    pub tiles: &'a Tiles,
    /// Angle (radians) covered by one pixel near the image centre.
    pub pixel_angle: f64,
    /// The camera model at the working resolution (to check which stretches of a row's band
    /// lie inside the mask).
    pub model: &'a OcamModel,
    /// Pixels at or below this level weigh nothing (the background).
    pub background: u8,
    /// Values are clipped at the background plus this fraction of a row's median above it
    /// ([`PLATEAU_CAP`]; 0: not clipped, for rows whose edges are one pixel sharp).
    pub plateau_cap: f64,
    /// Where the rows' near part is (the ground's normal, the reach in camera heights) for
    /// the near-field fit ([`Sections::near_foot`]); `None`: the whole row's fit always.
    pub near: Option<NearField>,
}

/// Samples around a row's great circle at which its cross-section is checked.
const SECTION_SAMPLES: usize = 256;

impl RefitImage<'_> {
    /// Whether the ray `q` (unit) lands on a valid pixel: the pixel the model's inverse
    /// polynomial gives must be valid and its own ray within two pixels of `q` (which also
    /// rejects rays beyond the range the polynomial describes).
    fn valid(&self, q: &Vector3<f64>) -> bool {
        let t = self.tiles;
        let [r, c] = self.model.world2cam_invpol(q);
        if !(r > -0.5 && c > -0.5) {
            return false;
        }
        let (r, c) = ((r + 0.5) as usize, (c + 0.5) as usize);
        if r >= t.height || c >= t.width {
            return false;
        }
        let i = r * t.width + c;
        if self.mask[i] == 0 {
            return false;
        }
        let p = self.rays[i];
        let d = q.x * p[0] as f64 + q.y * p[1] as f64 + q.z * p[2] as f64;
        d > (2.0 * self.pixel_angle).cos()
    }

    /// Marks, at `SECTION_SAMPLES` angles s around the great circle of `n` (points
    /// e1 cos s + e2 sin s), whether the circle's cross-section lies inside the mask (its
    /// centre and both ends valid). The cross-section's half-width is `foot_band` + `margin`,
    /// or with a vanishing point `vp`, `foot_band`·sin(angle from `vp`) + `margin`.
    #[allow(clippy::too_many_arguments)]
    fn full_sections(
        &self,
        n: &Vector3<f64>,
        e1: &Vector3<f64>,
        e2: &Vector3<f64>,
        foot_band: f64,
        margin: f64,
        vp: Option<&Vector3<f64>>,
        out: &mut [bool; SECTION_SAMPLES],
    ) {
        for (k, o) in out.iter_mut().enumerate() {
            let s = k as f64 * std::f64::consts::TAU / SECTION_SAMPLES as f64;
            let q = e1 * s.cos() + e2 * s.sin();
            let band = match vp {
                Some(v) => foot_band * q.cross(v).norm() + margin,
                None => foot_band + margin,
            };
            let (sb, cb) = band.sin_cos();
            *o = self.valid(&q) && self.valid(&(q * cb + n * sb)) && self.valid(&(q * cb - n * sb));
        }
    }
}

/// Refits each row's normal on the image's pixels within its band (`bands[i]`, radians,
/// widened by the margin), weighted by their value above the image's background.
/// Rows whose refit fails keep their normal. Returns the number of rows refitted.
///
/// With the rows' vanishing point `vp` (an estimate is enough), the band is a wedge: a row
/// is a strip on the ground, so its image narrows towards the vanishing point as
/// sin(angle from it), and so does the gap to its neighbours, which all meet there. A band
/// of constant width would take in the neighbours' pixels near the vanishing point, and
/// pixels there move the fitted circle off the vanishing point (near its foot, pixels only
/// turn it about the vanishing point, which does no harm). The wedge keeps the row's
/// `bands[i]` at its foot (the point 90° from the vanishing point), narrows in proportion,
/// and keeps the pixel margin everywhere.
pub fn refit_rows(
    img: &RefitImage,
    rows: &mut [Row],
    bands: &[f64],
    vp: Option<&Vector3<f64>>,
    candidates: &mut Candidates,
    fits: &mut RowFits,
) -> Result<usize, DetectError> {
    if rows.len() != bands.len() {
        return Err(DetectError::Buffer(format!(
            "refit: {} rows but {} bands",
            rows.len(),
            bands.len()
        )));
    }
    let t = img.tiles;
    let n_px = t.width * t.height;
    if img.values.len() != n_px
        || img.mask.len() != n_px
        || img.rays.len() != n_px
        || img.solid.len() != n_px
    {
        return Err(DetectError::Buffer(format!(
            "refit: image {}x{} and its buffers disagree",
            t.height, t.width
        )));
    }
    let mut done = 0;
    fits.along_var.clear();
    fits.feet.clear();
    for (row, &foot_band) in rows.iter_mut().zip(bands) {
        let fit = refit_row(img, vp, foot_band, &row.normal, candidates);
        fits.along_var.push(fit.along_var);
        if let Some(n) = fit.normal {
            row.normal = canonical(&n);
            done += 1;
            if let Some(foot) = fit.foot {
                fits.feet.push(NearFoot {
                    normal: row.normal,
                    foot,
                });
            }
        }
    }
    Ok(done)
}

/// One row's fit (`refit_rows`) from the normal `start`: its normal (`None` when no fit
/// succeeded), the variance along `vp` where estimated, and the near-field foot where the row
/// bends ([`Sections::near_foot`]). The row's cross-sections are fitted
/// ([`super::sections`]); where they are degenerate, the plain pixel centroid.
fn refit_row(
    img: &RefitImage,
    vp: Option<&Vector3<f64>>,
    foot_band: f64,
    start: &Vector3<f64>,
    cands: &mut Candidates,
) -> RowFit {
    let margin = MARGIN_PX * img.pixel_angle;
    // The band the pixels are collected in is widened by a fraction of a pixel's slack,
    // which the fit may move the normal by.
    let slack = 2.0 * img.pixel_angle;
    collect_candidates(img, start, foot_band + slack, margin + slack, vp, cands);
    // Only the stretches of the row whose whole cross-section (the band on both sides of
    // the great circle) lies inside the valid mask: where a mask edge (the annulus of a
    // catadioptric lens, the sky line) crosses a wide row obliquely, the part of the row it
    // cuts off on one side would otherwise pull the fitted centre line towards the other.
    keep_full_sections(cands, img, start, foot_band, margin, vp);
    let candidates = &*cands;
    let (s_band, s_foot, s_margin) = band_sines(foot_band, margin);
    let band = Band {
        s_band,
        s_foot,
        s_margin,
        wedge: vp.map(|v| [v.x as f32, v.y as f32, v.z as f32]),
        cap: plateau_cap(&candidates.values, img.background, img.plateau_cap),
    };
    let mut out = RowFit::default();
    let sec = section_step(img, &band, candidates, &candidates.along, start, vp);
    if let Some(sf) = sec.fit {
        out.normal = Some(canonical(&sf.normal));
        out.foot = img
            .near
            .as_ref()
            .and_then(|nf| sec.sections.near_foot(&sf.normal, nf));
        if vp.is_some() {
            out.along_var = sf.along_var;
        }
        return out;
    }
    // Noise only matters for the variance along the vanishing point.
    if let Some(PixelFit {
        fit,
        scatter,
        noise,
    }) = pixel_fit(img, &band, candidates, start, vp.is_some())
    {
        if fit.degeneracy < 0.5 {
            out.normal = Some(fit.normal);
            if let Some(v) = vp {
                let lambda = fit.mean_sq_residual * fit.weight;
                out.along_var = along_variance(&fit.normal, v, &scatter, lambda, &noise);
            }
        }
    }
    out
}

/// A row's band as its pixels are read: half-width `s_band` (sine of the angle), or with a
/// vanishing point the wedge `s_foot`·(sine of the angle from it) + `s_margin`; values above
/// `cap` clipped to it.
struct Band {
    s_band: f32,
    s_foot: f32,
    s_margin: f32,
    wedge: Option<[f32; 3]>,
    cap: u8,
}

/// A candidate inside a row's band as [`Band::pixels`] gives it.
#[derive(Debug, Clone, Copy)]
struct InBand {
    /// Position among the candidates.
    k: usize,
    ray: [f32; 3],
    /// Signed offset n·p from the circle.
    d: f32,
    /// Value above the background (clipped at the band's cap) times solid angle.
    w: f64,
    value: u8,
    solid: f32,
}

impl Band {
    /// The signed offset n·p of the candidate `k` from the circle of `nf` and its weight
    /// (value above the background times solid angle), or `None` outside the band.
    #[inline]
    fn read(&self, img: &RefitImage, c: &Candidates, nf: &[f32; 3], k: usize) -> Option<InBand> {
        let p = c.rays[k];
        let ds = nf[0] * p[0] + nf[1] * p[1] + nf[2] * p[2];
        let d = ds.abs();
        if d >= self.s_band {
            return None;
        }
        if let Some(vf) = &self.wedge {
            let a = vf[0] * p[0] + vf[1] * p[1] + vf[2] * p[2];
            if d >= self.s_foot * (1.0 - a * a).max(0.0).sqrt() + self.s_margin {
                return None;
            }
        }
        let (value, solid) = (c.values[k], c.solid[k]);
        let w = (value.min(self.cap) - img.background) as f64 * solid as f64;
        Some(InBand {
            k,
            ray: p,
            d: ds,
            w,
            value,
            solid,
        })
    }
}

impl Band {
    /// The candidates inside the band of `n`, as [`Band::read`] gives them.
    fn pixels<'a>(
        &'a self,
        img: &'a RefitImage,
        candidates: &'a Candidates,
        n: &Vector3<f64>,
    ) -> impl Iterator<Item = InBand> + 'a {
        let nf = to_f32(n);
        (0..candidates.len()).filter_map(move |k| self.read(img, candidates, &nf, k))
    }
}

/// The sines a band of half-width `foot_band` + `margin` (radians), or the wedge
/// `foot_band`·sin + `margin`, is tested with: (`s_band`, `s_foot`, `s_margin`) of [`Band`]
/// and [`PixelTest`].
fn band_sines(foot_band: f64, margin: f64) -> (f32, f32, f32) {
    (
        (foot_band + margin).min(1.5).sin() as f32,
        foot_band.min(1.5).sin() as f32,
        margin.sin() as f32,
    )
}

/// A ray in double precision.
fn ray64(p: [f32; 3]) -> Vector3<f64> {
    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

fn to_f32(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// The row's cross-sections about `n` and their fit, started from their mass-weighted fit
/// (`fit` is `None` when either is degenerate).
struct SectionStep {
    sections: Sections,
    fit: Option<super::sections::SectionFit>,
}

/// The cross-sections of the row about `n` (each candidate at its angle `along` the
/// circle) and their fit.
fn section_step(
    img: &RefitImage,
    band: &Band,
    candidates: &Candidates,
    along: &[f32],
    n: &Vector3<f64>,
    vp: Option<&Vector3<f64>>,
) -> SectionStep {
    let mut sections = Sections::new(n, SECTION_BINS);
    for InBand { k, d, w, .. } in band.pixels(img, candidates, n) {
        sections.add(along[k], d, w);
    }
    let fit = sections
        .mass_fit()
        .filter(|f| f.degeneracy < 0.5)
        .and_then(|f| sections.fit(&f.normal, vp, SECTION_HUBER, SECTION_POWER));
    SectionStep { sections, fit }
}

/// The plain pixel fit about `n`: the smallest eigenvector of the weighted scatter, with its
/// matrix, and (with `track`) Σ solid²·(n·p)²·p·pᵀ over the graded pixels (below the cap),
/// whose noise moves the fit: for the variance of the normal.
fn pixel_fit(
    img: &RefitImage,
    band: &Band,
    candidates: &Candidates,
    n: &Vector3<f64>,
    track: bool,
) -> Option<PixelFit> {
    let mut sc = Scatter::new();
    let mut noise = [0f64; 6];
    for c in band.pixels(img, candidates, n) {
        let pv = ray64(c.ray);
        sc.add(&pv, c.w);
        if track && c.value < band.cap {
            let k = (c.solid as f64 * c.d.abs() as f64).powi(2);
            let (x, y, z) = (pv.x, pv.y, pv.z);
            noise[0] += k * x * x;
            noise[1] += k * x * y;
            noise[2] += k * x * z;
            noise[3] += k * y * y;
            noise[4] += k * y * z;
            noise[5] += k * z * z;
        }
    }
    Some(PixelFit {
        fit: sc.fit()?,
        scatter: sc.matrix(),
        noise: nalgebra::Matrix3::new(
            noise[0], noise[1], noise[2], noise[1], noise[3], noise[4], noise[2], noise[4],
            noise[5],
        ),
    })
}

/// [`pixel_fit`]'s circle with its scatter matrix and the noise matrix.
struct PixelFit {
    fit: Fit,
    scatter: nalgebra::Matrix3<f64>,
    noise: nalgebra::Matrix3<f64>,
}

/// The variance (up to the image's noise variance per unit value) of the component along
/// `v` of the normal `n` fitted as the smallest eigenvector of the scatter `s` (eigenvalue
/// `lambda`), when the pixel weights carry independent noise whose effect on the scatter's
/// product with `n` has the covariance `noise` (Σ solid²·(n·p)²·p·pᵀ): first-order
/// perturbation of the eigenvector, δn = −(S − λ)⁻¹ δS n in the tangent plane of `n`.
/// NaN when `v` is (nearly) `n` or the tangent system is singular.
fn along_variance(
    n: &Vector3<f64>,
    v: &Vector3<f64>,
    s: &nalgebra::Matrix3<f64>,
    lambda: f64,
    noise: &nalgebra::Matrix3<f64>,
) -> f64 {
    let ev = v - n * n.dot(v);
    if ev.norm() < 1e-6 {
        return f64::NAN;
    }
    let ev = ev.normalize();
    let ef = n.cross(&ev);
    let t = |m: &nalgebra::Matrix3<f64>| {
        nalgebra::Matrix2::new(
            ef.dot(&(m * ef)),
            ef.dot(&(m * ev)),
            ev.dot(&(m * ef)),
            ev.dot(&(m * ev)),
        )
    };
    let a = t(s) - nalgebra::Matrix2::identity() * lambda;
    let Some(ai) = a.try_inverse() else {
        return f64::NAN;
    };
    let c = ai * t(noise) * ai;
    c[(1, 1)]
}

/// The level at which a row's pixel values are clipped: `background` + `fraction` × (the
/// median of the candidates' `values` − `background`); 255 (no clipping) when `fraction` is 0
/// or there are no candidates.
fn plateau_cap(values: &[u8], background: u8, fraction: f64) -> u8 {
    if fraction <= 0.0 || values.is_empty() {
        return 255;
    }
    let mut hist = [0u32; 256];
    for &v in values {
        hist[v as usize] += 1;
    }
    let half = values.len() as u32 / 2;
    let mut acc = 0u32;
    let mut median = 255u8;
    for (v, &c) in hist.iter().enumerate() {
        acc += c;
        if acc > half {
            median = v as u8;
            break;
        }
    }
    let cap = background as f64 + fraction * (median as f64 - background as f64).max(0.0);
    // At least one level above the background, so that every candidate keeps some weight.
    cap.round().clamp(background as f64 + 1.0, 255.0) as u8
}

/// The angle of ray `p` along a great circle whose frame is (f1, f2): atan2(f2·p, f1·p).
#[inline]
fn angle_along(f1: &[f32; 3], f2: &[f32; 3], p: [f32; 3]) -> f32 {
    fast_atan2(
        f2[0] * p[0] + f2[1] * p[1] + f2[2] * p[2],
        f1[0] * p[0] + f1[1] * p[1] + f1[2] * p[2],
    )
}

/// Keeps among the candidates (whose angles along the great circle of `n` are in `along`)
/// only the pixels on stretches of the circle whose whole cross-section (see
/// [`RefitImage::full_sections`]) lies inside the mask. The angle along the circle is the
/// same for a pixel and its mirror image across the circle, so a stretch is kept or dropped
/// whole.
fn keep_full_sections(
    cands: &mut Candidates,
    img: &RefitImage,
    n: &Vector3<f64>,
    foot_band: f64,
    margin: f64,
    vp: Option<&Vector3<f64>>,
) {
    let f1 = any_perpendicular(n);
    let f2 = n.cross(&f1);
    let mut sections = [true; SECTION_SAMPLES];
    img.full_sections(n, &f1, &f2, foot_band, margin, vp, &mut sections);
    if sections.iter().all(|&k| k) {
        return;
    }
    let ks = SECTION_SAMPLES as f32 / std::f32::consts::TAU;
    let mut kept = 0;
    for k in 0..cands.len() {
        let a = cands.along[k];
        if sections[((a * ks + 0.5) as i32).rem_euclid(SECTION_SAMPLES as i32) as usize] {
            cands.rays[kept] = cands.rays[k];
            cands.values[kept] = cands.values[k];
            cands.solid[kept] = cands.solid[k];
            cands.along[kept] = a;
            kept += 1;
        }
    }
    cands.truncate(kept);
    cands.along.truncate(kept);
}

/// Which pixels [`collect_candidates`] keeps: above the background, within the band of the
/// circle `nf` (half-width sine `s_band`) and, with a `wedge`, within `s_foot`·(sine of the
/// angle from `vf`) + `s_margin` of it.
struct PixelTest {
    nf: [f32; 3],
    vf: [f32; 3],
    wedge: bool,
    background: u8,
    s_band: f32,
    s_foot: f32,
    s_margin: f32,
}

/// The pixels of an image row's stretch [`collect_pixels`] tests at once.
const STRETCH: usize = 16;

impl PixelTest {
    #[inline(always)]
    fn passes(&self, p: [f32; 3], value: u8) -> bool {
        let (nf, vf) = (self.nf, self.vf);
        let d = (nf[0] * p[0] + nf[1] * p[1] + nf[2] * p[2]).abs();
        let a = vf[0] * p[0] + vf[1] * p[1] + vf[2] * p[2];
        let in_wedge =
            !self.wedge | (d < self.s_foot * (1.0 - a * a).max(0.0).sqrt() + self.s_margin);
        (value > self.background) & (d < self.s_band) & in_wedge
    }
}

/// Writes into `out` the image-row stretches (first pixel, length) of the tiles whose cone of
/// rays meets the band of `nf` (half-width `foot_band` + `margin`, or with a vanishing point
/// `vf` the wedge `foot_band`·sin(angle from `vf`) + `margin`, radians), in the tiles' order.
fn band_stretches(
    t: &Tiles,
    nf: &[f32; 3],
    vf: Option<&[f32; 3]>,
    foot_band: f64,
    margin: f64,
    out: &mut Vec<(u32, u32)>,
) {
    out.clear();
    let (foot, margin) = (foot_band as f32, margin as f32);
    for tile in &t.list {
        let ct = tile.centre;
        let d = (nf[0] * ct[0] + nf[1] * ct[1] + nf[2] * ct[2]).abs();
        // The widest the band gets over the tile.
        let band = if let Some(vf) = vf {
            let a = vf[0] * ct[0] + vf[1] * ct[1] + vf[2] * ct[2];
            let c = ((1.0 - a * a).max(0.0).sqrt() + tile.radius).min(1.0);
            foot * c + margin
        } else {
            foot + margin
        };
        let reach = (band + tile.radius).min(std::f32::consts::FRAC_PI_2);
        if d > reach.sin() {
            continue;
        }
        let (r0, c0) = (tile.r0 as usize, tile.c0 as usize);
        let cols = ((c0 + t.size).min(t.width) - c0) as u32;
        for r in r0..(r0 + t.size).min(t.height) {
            out.push(((r * t.width + c0) as u32, cols));
        }
    }
}

/// Appends to `cands` the pixels `lo..lo + len` that pass `test`. Each run of up to [`STRETCH`]
/// pixels is tested first, all lanes alike (so that the tests vectorise), then every
/// pixel is written and the end moves past the ones kept: at a plant's edge whether a
/// pixel is in changes from pixel to pixel, and branches on it mispredicted. Compiled also
/// for AVX2, chosen at run time (the same tests).
#[multiversion(targets("x86_64+avx2"))]
fn collect_pixels(
    test: &PixelTest,
    img: &RefitImage,
    lo: usize,
    len: usize,
    cands: &mut Candidates,
) {
    for at in (lo..lo + len).step_by(STRETCH) {
        let m = (lo + len - at).min(STRETCH);
        let (rays, values) = (&img.rays[at..at + m], &img.values[at..at + m]);
        let (mask, solid) = (&img.mask[at..at + m], &img.solid[at..at + m]);
        let mut keep = [false; STRETCH];
        for (kp, ((p, &v), &k)) in keep.iter_mut().zip(rays.iter().zip(values).zip(mask)) {
            *kp = test.passes(*p, v & k);
        }
        let start = cands.len();
        cands.rays.resize(start + m, [0.0; 3]);
        cands.values.resize(start + m, 0);
        cands.solid.resize(start + m, 0.0);
        let mut end = start;
        for j in 0..m {
            cands.rays[end] = rays[j];
            cands.values[end] = values[j];
            cands.solid[end] = solid[j];
            end += keep[j] as usize;
        }
        cands.truncate(end);
    }
}

/// How many stretches ahead [`collect_candidates`] asks for the next one's pixels.
const PREFETCH_AHEAD: usize = 4;

/// Writes into `cands` the pixels above the background within the band of `n`: half-width
/// `foot_band` + `margin`, or with a vanishing point `vp` the wedge `foot_band`·sin(angle
/// from `vp`) + `margin`; with `along`, also their angles along the great circle of `n`,
/// atan2(f2·p, f1·p) in the circle's own frame (f1 = `any_perpendicular(n)`, f2 = n × f1,
/// the frame [`Sections::new`] gives the same normal), taken while their rays are at hand.
/// Tiles whose cone of rays misses the band are skipped whole.
#[allow(clippy::too_many_arguments)]
fn collect_candidates(
    img: &RefitImage,
    n: &Vector3<f64>,
    foot_band: f64,
    margin: f64,
    vp: Option<&Vector3<f64>>,
    cands: &mut Candidates,
) {
    cands.clear();
    let wedge = vp.is_some();
    let f1 = any_perpendicular(n);
    let (f1, f2) = (to_f32(&f1), to_f32(&n.cross(&f1)));
    let background = img.background;
    let t = img.tiles;
    let nf = to_f32(n);
    let vf = vp.map_or([0f32; 3], to_f32);
    let (s_band, s_foot, s_margin) = band_sines(foot_band, margin);
    let test = PixelTest {
        nf,
        vf,
        wedge,
        background,
        s_band,
        s_foot,
        s_margin,
    };
    band_stretches(
        t,
        &nf,
        vp.map(|_| &vf),
        foot_band,
        margin,
        &mut cands.stretches,
    );
    // Each stretch lies an image row from the last, too far apart for the hardware's
    // prefetchers: the stretch a few ahead is asked for explicitly.
    let stretches = std::mem::take(&mut cands.stretches);
    let ahead = |(lo, cols): (u32, u32)| {
        let (lo, cols) = (lo as usize, cols as usize);
        prefetch(&img.values[lo..lo + cols]);
        prefetch(&img.mask[lo..lo + cols]);
        prefetch(&img.rays[lo..lo + cols]);
        prefetch(&img.solid[lo..lo + cols]);
    };
    for &s in stretches.iter().take(PREFETCH_AHEAD) {
        ahead(s);
    }
    for (k, &(lo, cols)) in stretches.iter().enumerate() {
        if let Some(&s) = stretches.get(k + PREFETCH_AHEAD) {
            ahead(s);
        }
        let (lo, cols) = (lo as usize, cols as usize);
        // A stretch of background (between plants) costs no rays' reads.
        let (vals, mask) = (&img.values[lo..lo + cols], &img.mask[lo..lo + cols]);
        if vals.iter().zip(mask).fold(0u8, |m, (&v, &k)| m.max(v & k)) <= background {
            continue;
        }
        collect_pixels(&test, img, lo, cols, cands);
    }
    cands.stretches = stretches;
    cands
        .along
        .extend(cands.rays.iter().map(|&p| angle_along(&f1, &f2, p)));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::detect::mask::{build_mask, MaskOptions};
    use crate::detect::Method;
    use crate::sphere::axis_angle;

    #[test]
    fn a_bad_reach_is_named() {
        for r in [-1.0, f64::NAN, 1e9] {
            let e = RefitOptions { near_reach_m: r }.validate().unwrap_err();
            assert!(e.to_string().contains("refit.near_reach_m"), "{e}");
        }
        assert!(RefitOptions::default().validate().is_ok());
    }

    #[test]
    fn refit_finds_the_intensity_centre_of_an_antialiased_row() {
        // A row drawn with sub-pixel precision (coverage-weighted edges) in an ideal fisheye.
        let cal = ideal_fisheye(200, 240).unwrap();
        let (mut mask, mut rays, mut solid) = (Vec::new(), Vec::new(), Vec::new());
        build_mask(
            &cal,
            &MaskOptions::default(),
            15.0,
            &mut mask,
            &mut rays,
            &mut solid,
        )
        .unwrap();
        let truth = Vector3::new(0.05, 1.0, 0.3).normalize();
        let half = 0.03; // radians
        let mut values = vec![0u8; 200 * 240];
        for (i, v) in values.iter_mut().enumerate() {
            if mask[i] == 0 {
                continue;
            }
            let (r, c) = ((i / 240) as f64, (i % 240) as f64);
            // coverage by 8x8 supersampling
            let mut cover = 0;
            for a in 0..8 {
                for b in 0..8 {
                    let p = cal
                        .model
                        .cam2world(r - 0.4375 + a as f64 / 8.0, c - 0.4375 + b as f64 / 8.0);
                    if truth.dot(&p).abs() < half {
                        cover += 1;
                    }
                }
            }
            *v = (cover * 200 / 64) as u8;
        }
        let tiles = Tiles::new(&mask, &rays, 240, 200, 16);
        let img = RefitImage {
            values: &values,
            mask: &mask,
            rays: &rays,
            solid: &solid,
            tiles: &tiles,
            pixel_angle: 0.0135,
            model: &cal.model,
            background: 10,
            // The row's edges here are one pixel sharp (no smoothing), where clipping the
            // plateau would cut into them: the plain intensity centroid.
            plateau_cap: 0.0,
            near: None,
        };
        // start 5 mrad off
        let start = (truth + Vector3::new(0.0, 0.0, 0.005)).normalize();
        let mut rows = [Row {
            normal: start,
            method: Method::Hough,
            support: 100,
            width_rad: 0.0,
        }];
        let mut cand = Candidates::default();
        let n = refit_rows(
            &img,
            &mut rows,
            &[0.05],
            None,
            &mut cand,
            &mut RowFits::default(),
        )
        .unwrap();
        assert_eq!(n, 1);
        let err = axis_angle(&rows[0].normal, &truth);
        assert!(
            err < 2e-4,
            "error {err} rad (start {})",
            axis_angle(&start, &truth)
        );
        assert!(refit_rows(
            &img,
            &mut rows,
            &[],
            None,
            &mut cand,
            &mut RowFits::default(),
        )
        .is_err());
    }
}
