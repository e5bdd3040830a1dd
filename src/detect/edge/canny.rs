//! Canny edge detection on an 8-bit image (the vegetation or greyscale image), inside a mask.
//!
//! Owns the Gaussian smoothing (fixed-point, separable; skipped when `sigma` is 0 because the
//! input is already smoothed), Sobel gradients, non-maximum suppression along the quantised
//! gradient direction, and hysteresis between a low and a high threshold, given either as
//! absolute gradient magnitudes or as quantiles of the gradient magnitudes inside the mask.
//! Only pixels inside the mask can be edges. [`Canny`] owns every buffer; once warmed up on an
//! image size, `process` does not allocate.

use super::EdgeError;
use multiversion::multiversion;

/// How the hysteresis thresholds are given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThresholdMode {
    /// `low` and `high` are Sobel gradient magnitudes (0..≈1443 for 8-bit input).
    Absolute,
    /// `high` is the quantile (0..1) of gradient magnitudes over the masked pixels that is
    /// the high threshold; `low` is the low threshold as a fraction (0..1) of the high one.
    Quantile,
}

/// Parameters of the Canny stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CannyParams {
    /// Standard deviation (pixels) of the Gaussian smoothing; 0 skips it. Default 0: the
    /// detector hands the edge method its smoothed vegetation image (1.4 suits an unsmoothed
    /// image).
    pub sigma: f64,
    /// How `low` and `high` are read. Default [`ThresholdMode::Quantile`].
    pub mode: ThresholdMode,
    /// Low threshold (see [`ThresholdMode`]). Default 0.5 (half the high threshold).
    pub low: f64,
    /// High threshold (see [`ThresholdMode`]). Default 0.9 (the 90th percentile).
    pub high: f64,
    /// In quantile mode, the high threshold never falls below this magnitude, so that a
    /// flat image gives no edges. Default 40.
    pub min_high: f64,
}

impl Default for CannyParams {
    fn default() -> Self {
        CannyParams {
            sigma: 0.0,
            mode: ThresholdMode::Quantile,
            low: 0.5,
            high: 0.9,
            min_high: 40.0,
        }
    }
}

impl CannyParams {
    /// Checks that the numbers make sense.
    pub fn validate(&self) -> Result<(), EdgeError> {
        let bad = |m: String| Err(EdgeError::Options(format!("canny: {m}")));
        if !(self.sigma >= 0.0 && self.sigma <= 10.0) {
            return bad(format!("sigma = {} must be in 0..=10", self.sigma));
        }
        match self.mode {
            ThresholdMode::Absolute => {
                if !(self.low >= 0.0 && self.high >= self.low && self.high.is_finite()) {
                    return bad(format!(
                        "absolute thresholds need 0 <= low <= high, got low {} high {}",
                        self.low, self.high
                    ));
                }
            }
            ThresholdMode::Quantile => {
                if !(self.high > 0.0 && self.high < 1.0) {
                    return bad(format!("quantile high = {} must be in (0, 1)", self.high));
                }
                if !(self.low > 0.0 && self.low <= 1.0) {
                    return bad(format!("quantile low = {} must be in (0, 1]", self.low));
                }
                if !(self.min_high >= 0.0 && self.min_high.is_finite()) {
                    return bad(format!("min_high = {} must be >= 0", self.min_high));
                }
            }
        }
        Ok(())
    }
}

/// What one Canny run did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CannyResult {
    /// Low and high thresholds used (gradient magnitudes).
    pub low: u16,
    pub high: u16,
    /// Number of edge pixels written.
    pub edge_pixels: usize,
}

/// Magnitudes are stored in the low 14 bits, the quantised gradient direction in the top two.
const MAG_MASK: u16 = 0x3fff;
/// Largest Sobel L2 magnitude of 8-bit input: √2 · 4 · 255.
const MAX_MAG: usize = 1443;
/// Value of a weak (not yet connected) candidate in the edge buffer during hysteresis.
const WEAK: u8 = 1;
/// Value of an edge pixel in the output.
pub const EDGE: u8 = 255;

/// Canny edge detector owning its buffers (sized on first use, reused after).
#[derive(Debug, Clone)]
pub struct Canny {
    params: CannyParams,
    kernel: Vec<u16>,
    smooth: Vec<u8>,
    row: Vec<u8>,
    acc: Vec<u16>,
    /// Gradient magnitude (low 14 bits) and direction sector (top 2 bits).
    grad: Vec<u16>,
    hist: Vec<u32>,
    stack: Vec<u32>,
    /// Per row: the columns `lo..hi` holding every mask pixel of the row (empty: none).
    spans: Vec<(usize, usize)>,
}

/// Fixed-point scale of the Gaussian weights (they sum to 256).
const KSHIFT: u32 = 8;

impl Canny {
    /// A detector with the given parameters (checked).
    pub fn new(params: CannyParams) -> Result<Self, EdgeError> {
        params.validate()?;
        let kernel = gaussian_kernel(params.sigma);
        Ok(Canny {
            params,
            kernel,
            smooth: Vec::new(),
            row: Vec::new(),
            acc: Vec::new(),
            grad: Vec::new(),
            hist: vec![0; MAX_MAG + 1],
            stack: Vec::new(),
            spans: Vec::new(),
        })
    }

    pub fn params(&self) -> &CannyParams {
        &self.params
    }

    /// Sizes the buffers for a `width`×`height` image (done by `process` too).
    pub fn warm_up(&mut self, width: usize, height: usize) {
        let n = width * height;
        if self.params.sigma > 0.0 {
            self.smooth.resize(n, 0);
            self.row.resize(width, 0);
            self.acc.resize(width, 0);
        }
        self.grad.resize(n, 0);
        self.spans.resize(height, (0, 0));
        if self.stack.capacity() < n / 16 {
            self.stack.reserve(n / 16);
        }
    }

    /// Runs Canny on `input` (`width`×`height`, row-major, one byte per pixel). Pixels where
    /// `mask` is zero are never edges. `edges` receives [`EDGE`] at edge pixels, 0 elsewhere.
    pub fn process(
        &mut self,
        input: &[u8],
        width: usize,
        height: usize,
        mask: &[u8],
        edges: &mut [u8],
    ) -> Result<CannyResult, EdgeError> {
        let n = width * height;
        for (what, len) in [
            ("input", input.len()),
            ("mask", mask.len()),
            ("edges", edges.len()),
        ] {
            if len != n {
                return Err(EdgeError::Size {
                    what,
                    width,
                    height,
                    expected: n,
                    actual: len,
                });
            }
        }
        edges.fill(0);
        if width < 3 || height < 3 {
            return Ok(CannyResult::default());
        }
        self.warm_up(width, height);
        let src: &[u8] = if self.params.sigma > 0.0 {
            gaussian(
                input,
                width,
                height,
                &self.kernel,
                &mut self.acc,
                &mut self.row,
                &mut self.smooth,
            );
            &self.smooth
        } else {
            input
        };
        // Only the mask's extent is worked on (a lens's image circle leaves a third of the
        // frame black).
        for (r, span) in self.spans.iter_mut().enumerate() {
            *span = row_span(&mask[r * width..(r + 1) * width]);
        }
        sobel(src, width, height, &self.spans, &mut self.grad);
        let (low, high) = self.thresholds(width, height, mask);
        let edge_pixels = nms_hysteresis(
            &self.grad,
            width,
            height,
            mask,
            &self.spans,
            (low, high),
            edges,
            &mut self.stack,
        );
        Ok(CannyResult {
            low,
            high,
            edge_pixels,
        })
    }

    /// Sub-pixel position (row, column) of edge pixel (`row`, `col`) of the last run: the
    /// vertex of the parabola through the gradient magnitudes across the edge (along the
    /// quantised gradient direction), at most half a pixel from the pixel's centre. Without
    /// it the non-maximum suppression would put a step edge consistently half a pixel to
    /// one side, which biases the great circles fitted to the edges.
    pub fn subpixel(&self, row: usize, col: usize, width: usize) -> [f64; 2] {
        let (r, c) = (row as f64, col as f64);
        if row == 0 || col == 0 || col + 1 >= width || (row + 1) * width >= self.grad.len() {
            return [r, c];
        }
        let i = row * width + col;
        let g = self.grad[i];
        let (dr, dc): (isize, isize) = match g >> 14 {
            0 => (0, 1),
            1 => (1, 0),
            2 => (1, -1),
            _ => (1, 1),
        };
        let o = dr * width as isize + dc;
        let m = (g & MAG_MASK) as f64;
        let plus = (self.grad[(i as isize + o) as usize] & MAG_MASK) as f64;
        let minus = (self.grad[(i as isize - o) as usize] & MAG_MASK) as f64;
        let den = minus - 2.0 * m + plus;
        if den >= 0.0 {
            return [r, c];
        }
        let t = (0.5 * (minus - plus) / den).clamp(-0.5, 0.5);
        [r + t * dr as f64, c + t * dc as f64]
    }

    /// The smoothed image of the last run (empty when `sigma` is 0).
    pub fn smoothed(&self) -> &[u8] {
        &self.smooth
    }

    fn thresholds(&mut self, width: usize, height: usize, mask: &[u8]) -> (u16, u16) {
        let o = &self.params;
        match o.mode {
            ThresholdMode::Absolute => {
                let low = o.low.round().clamp(1.0, MAX_MAG as f64) as u16;
                let high = o.high.round().clamp(1.0, MAX_MAG as f64) as u16;
                (low, high.max(low))
            }
            ThresholdMode::Quantile => {
                // Histogram over every third row of the masked interior: plenty for a
                // quantile, a third of the cost.
                self.hist.fill(0);
                let mut total = 0u64;
                for r in (1..height - 1).step_by(3) {
                    let (lo, hi) = self.spans[r];
                    let g = &self.grad[r * width + lo..r * width + hi];
                    let m = &mask[r * width + lo..r * width + hi];
                    for (&gv, &mv) in g.iter().zip(m) {
                        if mv != 0 {
                            self.hist[(gv & MAG_MASK) as usize] += 1;
                            total += 1;
                        }
                    }
                }
                if total == 0 {
                    return (u16::MAX, u16::MAX);
                }
                let target = (o.high * total as f64).ceil() as u64;
                let mut seen = 0u64;
                let mut q = MAX_MAG;
                for (v, &c) in self.hist.iter().enumerate() {
                    seen += c as u64;
                    if seen >= target {
                        q = v;
                        break;
                    }
                }
                let high = (q as f64).max(o.min_high).max(1.0);
                let low = (high * o.low).round().max(1.0);
                (low as u16, high.round() as u16)
            }
        }
    }
}

/// Gaussian weights in fixed point summing to 2^KSHIFT, radius at most ⌈3σ⌉ (and 30), taps
/// that round to zero trimmed.
fn gaussian_kernel(sigma: f64) -> Vec<u16> {
    if sigma <= 0.0 {
        return vec![1 << KSHIFT];
    }
    let radius = ((3.0 * sigma).ceil() as usize).clamp(1, 30);
    let w: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let x = i as f64 - radius as f64;
            (-x * x / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = w.iter().sum();
    let scale = (1u32 << KSHIFT) as f64;
    let mut k: Vec<i64> = w.iter().map(|v| (v / sum * scale).round() as i64).collect();
    while k.len() > 1 && k[0] == 0 {
        k.remove(0);
        k.pop();
    }
    // Put the rounding error on the centre tap so the weights sum exactly to 2^KSHIFT.
    let s: i64 = k.iter().sum();
    let centre = k.len() / 2;
    k[centre] = (k[centre] + (1i64 << KSHIFT) - s).max(0);
    k.iter().map(|&v| v as u16).collect()
}

/// Separable Gaussian with replicated borders, in 16-bit fixed point (so that it vectorises
/// on plain SSE2): for each output row a vertical pass into `row` (rounded to 8 bits), then a
/// horizontal pass into `out`.
#[multiversion(targets("x86_64+avx2"))]
fn gaussian(
    input: &[u8],
    width: usize,
    height: usize,
    kernel: &[u16],
    acc: &mut [u16],
    row: &mut [u8],
    out: &mut [u8],
) {
    let radius = kernel.len() / 2;
    let acc = &mut acc[..width];
    let row = &mut row[..width];
    let half = 1u16 << (KSHIFT - 1);
    for r in 0..height {
        acc.fill(half);
        for (k, &wk) in kernel.iter().enumerate() {
            let rr =
                (r as isize + k as isize - radius as isize).clamp(0, height as isize - 1) as usize;
            let src = &input[rr * width..(rr + 1) * width];
            for (a, &v) in acc.iter_mut().zip(src) {
                *a = a.wrapping_add(wk.wrapping_mul(v as u16));
            }
        }
        for (d, &a) in row.iter_mut().zip(acc.iter()) {
            *d = (a >> KSHIFT) as u8;
        }
        let dst = &mut out[r * width..(r + 1) * width];
        if width > 2 * radius {
            let inner = width - 2 * radius;
            let a = &mut acc[..inner];
            a.fill(half);
            for (k, &wk) in kernel.iter().enumerate() {
                for (x, &v) in a.iter_mut().zip(&row[k..k + inner]) {
                    *x = x.wrapping_add(wk.wrapping_mul(v as u16));
                }
            }
            for (d, &x) in dst[radius..radius + inner].iter_mut().zip(a.iter()) {
                *d = (x >> KSHIFT) as u8;
            }
        }
        let edge_cols =
            (0..radius.min(width)).chain(width.saturating_sub(radius).max(radius)..width);
        for c in edge_cols {
            let mut a = half as u32;
            for (k, &wk) in kernel.iter().enumerate() {
                let cc = (c as isize + k as isize - radius as isize).clamp(0, width as isize - 1);
                a += wk as u32 * row[cc as usize] as u32;
            }
            dst[c] = (a >> KSHIFT) as u8;
        }
    }
}

/// The columns `lo..hi` from the first to the last nonzero byte of a mask row ((0, 0) when
/// the row is all zero), scanning eight bytes at a time.
fn row_span(m: &[u8]) -> (usize, usize) {
    let word = |c: &[u8]| u64::from_ne_bytes(c.try_into().unwrap_or([0; 8])) != 0;
    let mut lo = None;
    for (k, c) in m.chunks(8).enumerate() {
        let any = if c.len() == 8 {
            word(c)
        } else {
            c.iter().any(|&v| v != 0)
        };
        if any {
            lo = c.iter().position(|&v| v != 0).map(|p| 8 * k + p);
            break;
        }
    }
    let Some(lo) = lo else {
        return (0, 0);
    };
    let hi = m.iter().rposition(|&v| v != 0).map_or(lo + 1, |p| p + 1);
    (lo, hi)
}

/// Sobel gradients: L2 magnitude in the low 14 bits and the direction sector in the top two
/// (0: across columns, 1: across rows, 2: the anti-diagonal, 3: the diagonal). The border
/// is zero. Computed only within one pixel of the mask (`spans`, per row), which is all that
/// non-maximum suppression inside the mask reads; elsewhere `grad` keeps older values.
#[multiversion(targets("x86_64+avx2"))]
fn sobel(src: &[u8], width: usize, height: usize, spans: &[(usize, usize)], grad: &mut [u16]) {
    grad[..width].fill(0);
    grad[(height - 1) * width..].fill(0);
    for r in 1..height - 1 {
        let out = &mut grad[r * width..(r + 1) * width];
        out[0] = 0;
        out[width - 1] = 0;
        // Columns within one pixel of a mask pixel in this row or its neighbours.
        let (mut lo, mut hi) = (usize::MAX, 0usize);
        for &(a, b) in &spans[r - 1..=r + 1] {
            if b > a {
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        if hi == 0 {
            continue;
        }
        let lo = lo.saturating_sub(1).max(1);
        let hi = (hi + 1).min(width - 1);
        if hi <= lo {
            continue;
        }
        let n = hi - lo;
        let a = &src[(r - 1) * width..r * width];
        let b = &src[r * width..(r + 1) * width];
        let c = &src[(r + 1) * width..(r + 2) * width];
        let (a0, a1, a2) = (&a[lo - 1..hi - 1], &a[lo..hi], &a[lo + 1..hi + 1]);
        let (b0, b2) = (&b[lo - 1..hi - 1], &b[lo + 1..hi + 1]);
        let (c0, c1, c2) = (&c[lo - 1..hi - 1], &c[lo..hi], &c[lo + 1..hi + 1]);
        let o = &mut out[lo..hi];
        for i in 0..n {
            let gx = (a2[i] as i16 + 2 * b2[i] as i16 + c2[i] as i16)
                - (a0[i] as i16 + 2 * b0[i] as i16 + c0[i] as i16);
            let gy = (c0[i] as i16 + 2 * c1[i] as i16 + c2[i] as i16)
                - (a0[i] as i16 + 2 * a1[i] as i16 + a2[i] as i16);
            let (fx, fy) = (gx as f32, gy as f32);
            let mag = floor_root(fx * fx + fy * fy);
            let (ax, ay) = (fx.abs(), fy.abs());
            // Branch-free sector so that the loop vectorises.
            let horizontal = (ay < TAN_22_5 * ax) as u16;
            let vertical = (ay > TAN_67_5 * ax) as u16;
            let same_sign = ((gx ^ gy) >= 0) as u16;
            let diag = 2 + same_sign;
            let not_hv = 1 - (horizontal | vertical);
            let sector = vertical + not_hv * diag;
            o[i] = mag | (sector << 14);
        }
    }
}

/// ⌊√v⌋ for a whole number v ≤ 2·1020² (a Sobel gradient's squared length), the same as
/// `v.sqrt() as u16`, but through the float's bits, which vectorises (the saturating
/// conversion runs lane by lane). Adding 1.5·2²³ leaves no fraction
/// bits, so it rounds to the nearest whole number; the square root of a whole number below
/// 2²² is whole or at least 3.4·10⁻⁴ from one, so the root less 0.49985 rounds to its floor
/// (a test checks every Sobel gradient).
#[inline(always)]
fn floor_root(v: f32) -> u16 {
    let shifted = v.sqrt() - 0.499_85 + 12_582_912.0;
    shifted.to_bits().wrapping_sub(0x4b40_0000) as u16
}

const TAN_22_5: f32 = 0.414_213_57;
const TAN_67_5: f32 = 2.414_213_6;

/// Non-maximum suppression inside the mask, then hysteresis. Returns the number of edges.
#[multiversion(targets("x86_64+avx2"))]
#[allow(clippy::too_many_arguments)]
fn nms_hysteresis(
    grad: &[u16],
    width: usize,
    height: usize,
    mask: &[u8],
    spans: &[(usize, usize)],
    thresholds: (u16, u16),
    edges: &mut [u8],
    stack: &mut Vec<u32>,
) -> usize {
    stack.clear();
    for (r, &span) in spans.iter().enumerate().take(height - 1).skip(1) {
        let (lo, hi) = nms_columns(span, width);
        if hi <= lo {
            continue;
        }
        let row = r * width;
        let out = &mut edges[row + lo..row + hi];
        suppress_row(
            grad,
            width,
            r,
            (lo, hi),
            &mask[row + lo..row + hi],
            thresholds,
            out,
        );
        push_seeds(out, row + lo, stack);
    }
    connect_weak(edges, width, stack);
    clear_weak(edges, width, height, spans)
}

/// The columns of a row's mask span that non-maximum suppression visits: never the border.
#[inline(always)]
fn nms_columns((lo, hi): (usize, usize), width: usize) -> (usize, usize) {
    (lo.max(1), hi.min(width - 1))
}

/// Non-maximum suppression of row `r`'s columns `lo..hi` (`mask` and `out` are those
/// columns): [`EDGE`] where the pixel is a local maximum across the edge reaching `high`,
/// [`WEAK`] where it reaches only `low`, 0 elsewhere.
#[inline(always)]
fn suppress_row(
    grad: &[u16],
    width: usize,
    r: usize,
    (lo, hi): (usize, usize),
    mask: &[u8],
    (low, high): (u16, u16),
    out: &mut [u8],
) {
    let row = r * width;
    // Rows above, at and below, shifted so that index i is the pixel (r, lo + i) and its
    // neighbours; each sector picks its pair, all in straight slices so that it vectorises.
    let up = &grad[row - width..row];
    let mid = &grad[row..row + width];
    let dn = &grad[row + width..row + 2 * width];
    let (l, c, rt) = (lo - 1..hi - 1, lo..hi, lo + 1..hi + 1);
    let (ul, uc, ur) = (&up[l.clone()], &up[c.clone()], &up[rt.clone()]);
    let (ml, mc, mr) = (&mid[l.clone()], &mid[c.clone()], &mid[rt.clone()]);
    let (dl, dc, dr) = (&dn[l], &dn[c.clone()], &dn[rt]);
    for i in 0..hi - lo {
        let g = mc[i];
        let m = g & MAG_MASK;
        let sector = g >> 14;
        // Sector 0: left/right; 1: up/down; 2: up-right/down-left; 3: up-left/down-right.
        // Selected with bit masks rather than a match so that the loop vectorises.
        let e0 = 0u16.wrapping_sub((sector == 0) as u16);
        let e1 = 0u16.wrapping_sub((sector == 1) as u16);
        let e2 = 0u16.wrapping_sub((sector == 2) as u16);
        let e3 = 0u16.wrapping_sub((sector == 3) as u16);
        let n1 = ((mr[i] & e0) | (dc[i] & e1) | (dl[i] & e2) | (dr[i] & e3)) & MAG_MASK;
        let n2 = ((ml[i] & e0) | (uc[i] & e1) | (ur[i] & e2) | (ul[i] & e3)) & MAG_MASK;
        let keep = (m >= low) & (mask[i] != 0) & (m > n1) & (m >= n2);
        let strong = m >= high;
        // EDGE (255) when strong, WEAK (1) otherwise, 0 when not kept.
        out[i] = (keep as u8) * (WEAK + (strong as u8) * (EDGE - WEAK));
    }
}

/// Pushes the indices of the strong pixels of `out` (a row's span starting at image index
/// `start`) onto `stack` in index order, while the row is in the cache, a block of the row
/// at a time from a bit mask of its strong pixels.
#[inline(always)]
fn push_seeds(out: &[u8], start: usize, stack: &mut Vec<u32>) {
    const BLOCK: usize = 32;
    for (b, block) in out.chunks(BLOCK).enumerate() {
        let mut bits = block
            .iter()
            .enumerate()
            .fold(0u32, |a, (k, &v)| a | ((v == EDGE) as u32) << k);
        let first = (start + b * BLOCK) as u32;
        while bits != 0 {
            stack.push(first + bits.trailing_zeros());
            bits &= bits - 1;
        }
    }
}

/// Hysteresis: every weak pixel 8-connected to a seed on `stack` becomes an edge.
#[inline(always)]
fn connect_weak(edges: &mut [u8], width: usize, stack: &mut Vec<u32>) {
    let w = width as isize;
    let nb: [isize; 8] = [-w - 1, -w, -w + 1, -1, 1, w - 1, w, w + 1];
    while let Some(i) = stack.pop() {
        for o in nb {
            let j = (i as isize + o) as usize;
            if edges[j] == WEAK {
                edges[j] = EDGE;
                stack.push(j as u32);
            }
        }
    }
}

/// Clears the weak pixels left unconnected and returns the number of edges. Only the rows'
/// spans can hold any (the rest was cleared at the start); counted per row in 32-bit lanes,
/// which vectorise four wide.
#[inline(always)]
fn clear_weak(edges: &mut [u8], width: usize, height: usize, spans: &[(usize, usize)]) -> usize {
    let mut count = 0usize;
    for (r, &span) in spans.iter().enumerate().take(height - 1).skip(1) {
        let (lo, hi) = nms_columns(span, width);
        if hi <= lo {
            continue;
        }
        let row = &mut edges[r * width + lo..r * width + hi];
        let mut n = 0u32;
        for e in row.iter_mut() {
            let is_edge = *e == EDGE;
            *e = if is_edge { EDGE } else { 0 };
            n += is_edge as u32;
        }
        count += n as usize;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disc(width: usize, height: usize, cx: f64, cy: f64, r: f64) -> Vec<u8> {
        let mut img = vec![0u8; width * height];
        for y in 0..height {
            for x in 0..width {
                let d = ((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)).sqrt();
                img[y * width + x] = if d < r { 200 } else { 20 };
            }
        }
        img
    }

    /// Non-maximum suppression and hysteresis written out pixel by pixel on the gradients
    /// of `c`'s last run: a pixel inside the mask (not on the border) is a candidate when its
    /// magnitude reaches `low` and its neighbours across the edge do not beat it; edges are
    /// the candidates 8-connected to one reaching `high`.
    fn reference_edges(c: &Canny, w: usize, h: usize, mask: &[u8], low: u16, high: u16) -> Vec<u8> {
        let mag = |r: usize, col: usize| c.grad[r * w + col] & MAG_MASK;
        let mut kept = vec![0u8; w * h];
        for r in 1..h - 1 {
            for col in 1..w - 1 {
                let i = r * w + col;
                let m = mag(r, col);
                let ((r1, c1), (r2, c2)) = match c.grad[i] >> 14 {
                    0 => ((r, col + 1), (r, col - 1)),
                    1 => ((r + 1, col), (r - 1, col)),
                    2 => ((r + 1, col - 1), (r - 1, col + 1)),
                    _ => ((r + 1, col + 1), (r - 1, col - 1)),
                };
                if mask[i] != 0 && m >= low && m > mag(r1, c1) && m >= mag(r2, c2) {
                    kept[i] = if m >= high { EDGE } else { WEAK };
                }
            }
        }
        let mut todo: Vec<usize> = (0..w * h).filter(|&i| kept[i] == EDGE).collect();
        while let Some(i) = todo.pop() {
            let (r, col) = (i / w, i % w);
            for rr in r - 1..=r + 1 {
                for cc in col - 1..=col + 1 {
                    let j = rr * w + cc;
                    if kept[j] == WEAK {
                        kept[j] = EDGE;
                        todo.push(j);
                    }
                }
            }
        }
        kept.iter()
            .map(|&v| if v == EDGE { EDGE } else { 0 })
            .collect()
    }

    proptest::proptest! {
        #[test]
        fn edges_are_those_of_the_pixel_by_pixel_definition(
            seed in 0u64..1_000_000,
            w in 3usize..90,
            h in 3usize..40,
            blobs in 1usize..12,
            quantile in proptest::bool::ANY,
        ) {
            // Blobs of random brightness on noise, inside a random disc of a mask.
            let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
            let mut next = move || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state
            };
            let mut img: Vec<u8> = (0..w * h).map(|_| (next() % 40) as u8).collect();
            for _ in 0..blobs {
                let (cx, cy) = ((next() % w as u64) as f64, (next() % h as u64) as f64);
                let (r, v) = (1.0 + (next() % 12) as f64, 60 + (next() % 190) as u8);
                for y in 0..h {
                    for x in 0..w {
                        if (x as f64 - cx).hypot(y as f64 - cy) < r {
                            img[y * w + x] = v;
                        }
                    }
                }
            }
            let (mx, my, mr) = ((next() % w as u64) as f64, (next() % h as u64) as f64, (next() % 60) as f64);
            let mask: Vec<u8> = (0..w * h)
                .map(|i| (((i % w) as f64 - mx).hypot((i / w) as f64 - my) < mr) as u8 * 255)
                .collect();
            let options = if quantile {
                CannyParams { sigma: 1.0, ..Default::default() }
            } else {
                CannyParams {
                    sigma: 0.0,
                    mode: ThresholdMode::Absolute,
                    low: (next() % 200) as f64,
                    high: 200.0 + (next() % 400) as f64,
                    min_high: 0.0,
                }
            };
            let mut c = Canny::new(options).unwrap();
            let mut edges = vec![0u8; w * h];
            let res = c.process(&img, w, h, &mask, &mut edges).unwrap();
            let want = reference_edges(&c, w, h, &mask, res.low, res.high);
            proptest::prop_assert_eq!(res.edge_pixels, want.iter().filter(|&&v| v == EDGE).count());
            proptest::prop_assert!(edges == want);
        }
    }

    #[test]
    fn floor_root_is_the_square_roots_floor_for_every_sobel_gradient() {
        // Sobel's components lie within ±4·255.
        for gx in 0..=1020i32 {
            for gy in 0..=gx {
                let v = (gx * gx + gy * gy) as f32;
                assert_eq!(floor_root(v), v.sqrt() as u16, "gx {gx} gy {gy}");
            }
        }
    }

    #[test]
    fn kernel_sums_to_one() {
        for s in [0.5, 1.0, 1.4, 2.0, 3.3] {
            let k = gaussian_kernel(s);
            assert_eq!(
                k.iter().map(|&v| v as u32).sum::<u32>(),
                1 << KSHIFT,
                "sigma {s}"
            );
            assert_eq!(k.len() % 2, 1);
        }
    }

    #[test]
    fn flat_image_smooths_to_itself_and_has_no_edges() {
        let (w, h) = (40, 30);
        let img = vec![77u8; w * h];
        let mask = vec![1u8; w * h];
        let mut edges = vec![9u8; w * h];
        let mut c = Canny::new(CannyParams {
            sigma: 1.4,
            ..Default::default()
        })
        .unwrap();
        let r = c.process(&img, w, h, &mask, &mut edges).unwrap();
        assert_eq!(r.edge_pixels, 0);
        assert!(edges.iter().all(|&e| e == 0));
        assert!(c.smoothed().iter().all(|&v| v == 77));
    }

    #[test]
    fn circle_edge_is_thin_and_on_the_boundary() {
        let (w, h) = (120, 100);
        let (cx, cy, rad) = (60.0, 50.0, 30.0);
        let img = disc(w, h, cx, cy, rad);
        let mask = vec![1u8; w * h];
        let mut edges = vec![0u8; w * h];
        let mut c = Canny::new(CannyParams {
            sigma: 1.4,
            mode: ThresholdMode::Absolute,
            low: 50.0,
            high: 150.0,
            ..Default::default()
        })
        .unwrap();
        let r = c.process(&img, w, h, &mask, &mut edges).unwrap();
        // Circumference ~188 pixels; a thin 8-connected ring has about that many.
        assert!(
            (150..260).contains(&r.edge_pixels),
            "{} edge pixels",
            r.edge_pixels
        );
        for y in 0..h {
            for x in 0..w {
                if edges[y * w + x] != 0 {
                    let d = ((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)).sqrt();
                    assert!((d - rad).abs() < 1.6, "edge at ({y},{x}) d={d}");
                }
            }
        }
        // Every direction around the circle is covered (no gaps wider than a few degrees).
        let mut seen = [false; 72];
        for y in 0..h {
            for x in 0..w {
                if edges[y * w + x] != 0 {
                    let a = (y as f64 - cy).atan2(x as f64 - cx).to_degrees() + 180.0;
                    seen[((a / 5.0) as usize).min(71)] = true;
                }
            }
        }
        assert!(seen.iter().all(|&s| s), "gaps in the ring");
    }

    #[test]
    fn mask_removes_edges_and_quantile_mode_adapts() {
        let (w, h) = (120, 100);
        let img = disc(w, h, 60.0, 50.0, 30.0);
        let mut mask = vec![1u8; w * h];
        for y in 0..h {
            for x in 0..60 {
                mask[y * w + x] = 0;
            }
        }
        let mut edges = vec![0u8; w * h];
        let mut c = Canny::new(CannyParams {
            sigma: 1.4,
            ..Default::default()
        })
        .unwrap();
        let r = c.process(&img, w, h, &mask, &mut edges).unwrap();
        assert!(r.edge_pixels > 60, "{r:?}");
        for y in 0..h {
            for x in 0..60 {
                assert_eq!(edges[y * w + x], 0);
            }
        }
        // The same image brighter by a factor keeps its edges in quantile mode.
        let bright: Vec<u8> = img.iter().map(|&v| (v as u32 * 5 / 4) as u8).collect();
        let mut e2 = vec![0u8; w * h];
        let r2 = c.process(&bright, w, h, &mask, &mut e2).unwrap();
        assert!(r2.high > r.high);
        assert_eq!(r2.edge_pixels, r.edge_pixels);
    }

    #[test]
    fn subpixel_edges_are_centred_on_a_blurred_step() {
        // A vertical step at column 20.5 (between 20 and 21), and one at 30.25 rendered by
        // area coverage: sub-pixel positions land within a tenth of a pixel of the step.
        let (w, h) = (50, 20);
        for step in [20.5f64, 30.25, 14.8] {
            let mut img = vec![0u8; w * h];
            for r in 0..h {
                for c in 0..w {
                    let cover = (c as f64 + 0.5 - step).clamp(0.0, 1.0);
                    img[r * w + c] = (40.0 + 160.0 * cover).round() as u8;
                }
            }
            let mask = vec![1u8; w * h];
            let mut edges = vec![0u8; w * h];
            let mut c = Canny::new(CannyParams {
                sigma: 1.2,
                ..Default::default()
            })
            .unwrap();
            c.process(&img, w, h, &mask, &mut edges).unwrap();
            let mut n = 0;
            for r in 2..h - 2 {
                for col in 0..w {
                    if edges[r * w + col] != 0 {
                        let p = c.subpixel(r, col, w);
                        assert_eq!(p[0], r as f64);
                        assert!((p[1] - step).abs() < 0.1, "step {step}: edge at {p:?}");
                        n += 1;
                    }
                }
            }
            assert_eq!(n, h - 4, "one edge pixel per row");
        }
    }

    #[test]
    fn presmoothed_input_and_size_errors() {
        let (w, h) = (50, 40);
        let img = disc(w, h, 25.0, 20.0, 10.0);
        let mask = vec![1u8; w * h];
        let mut edges = vec![0u8; w * h];
        let mut c = Canny::new(CannyParams {
            sigma: 0.0,
            mode: ThresholdMode::Absolute,
            low: 100.0,
            high: 300.0,
            ..Default::default()
        })
        .unwrap();
        let r = c.process(&img, w, h, &mask, &mut edges).unwrap();
        assert!(r.edge_pixels > 40);
        let e = c.process(&img[1..], w, h, &mask, &mut edges).unwrap_err();
        assert!(e.to_string().contains("input"), "{e}");
        let e = c.process(&img, w, h, &mask[1..], &mut edges).unwrap_err();
        assert!(e.to_string().contains("mask"), "{e}");
        assert!(Canny::new(CannyParams {
            high: 1.5,
            ..Default::default()
        })
        .is_err());
    }
}
