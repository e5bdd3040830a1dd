//! Chains of 8-connected edge pixels, ordered along the chain, each pixel turned into a ray.
//!
//! The image is scanned in raster order; the first untraced edge pixel of a chain is followed
//! in both directions (4-neighbours before diagonal ones, so staircases are walked step by
//! step) and the two halves are joined into one ordered chain. Where a chain branches, the
//! walk continues along one branch and the others become chains of their own, so junctions
//! split chains. Chains shorter than a minimum length are dropped; every pixel of a kept
//! chain becomes a unit ray through the calibration.

use super::EdgeError;
use crate::camera::OcamModel;
use nalgebra::Vector3;

/// Parameters of the chain stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainParams {
    /// Chains with fewer pixels are dropped (before their pixels become rays). Default 20,
    /// the splitting stage's shortest section: a shorter chain cannot give a section, and
    /// noise makes many such chains.
    pub min_length: usize,
}

impl Default for ChainParams {
    fn default() -> Self {
        ChainParams { min_length: 20 }
    }
}

/// The chains of one image, in flat buffers (the caller keeps one and reuses it).
#[derive(Debug, Clone, Default)]
pub struct Chains {
    /// Pixels (row, column) of every chain, chain after chain, in order along each chain.
    pub pixels: Vec<[u32; 2]>,
    /// Unit ray of each pixel (same indexing as `pixels`).
    pub rays: Vec<Vector3<f64>>,
    /// Start and end (exclusive) of each chain in `pixels` and `rays`.
    pub ranges: Vec<(u32, u32)>,
}

impl Chains {
    pub fn clear(&mut self) {
        self.pixels.clear();
        self.rays.clear();
        self.ranges.clear();
    }

    /// Number of chains.
    pub fn len(&self) -> usize {
        self.ranges.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ranges.is_empty()
    }
}

/// What one tracing run found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChainResult {
    /// Chains traced, including those dropped as too short.
    pub traced: usize,
    /// Chains kept.
    pub kept: usize,
    /// Pixels in kept chains.
    pub pixels: usize,
}

/// Traces chains in edge images of one size, reusing its buffers.
#[derive(Debug, Clone)]
pub struct ChainTracer {
    params: ChainParams,
    width: usize,
    height: usize,
    /// Nonzero where a pixel has been traced in the current run; reset after each run by
    /// walking `touched`, so it never needs a full clear.
    visited: Vec<u8>,
    touched: Vec<u32>,
    half: Vec<u32>,
    /// The kept pixels' positions in the image (`locate`'s), before they become rays.
    located: Vec<[f64; 2]>,
}

impl ChainTracer {
    pub fn new(params: ChainParams, width: usize, height: usize) -> Result<Self, EdgeError> {
        if params.min_length < 2 {
            return Err(EdgeError::Options(format!(
                "chains: min_length = {} must be at least 2",
                params.min_length
            )));
        }
        Ok(ChainTracer {
            params,
            width,
            height,
            visited: vec![0; width * height],
            touched: Vec::new(),
            half: Vec::new(),
            located: Vec::new(),
        })
    }

    pub fn params(&self) -> &ChainParams {
        &self.params
    }

    /// Traces the chains of `edges` (nonzero = edge pixel) and turns their pixels into rays
    /// through `model` (which must describe images of the tracer's size).
    pub fn trace(
        &mut self,
        edges: &[u8],
        model: &OcamModel,
        out: &mut Chains,
    ) -> Result<ChainResult, EdgeError> {
        self.trace_located(edges, model, |r, c| [r as f64, c as f64], out)
    }

    /// As [`ChainTracer::trace`], with each pixel's ray taken at `locate(row, col)`, its
    /// (sub-pixel) position in the image.
    pub fn trace_located(
        &mut self,
        edges: &[u8],
        model: &OcamModel,
        locate: impl Fn(usize, usize) -> [f64; 2],
        out: &mut Chains,
    ) -> Result<ChainResult, EdgeError> {
        let (w, h) = (self.width, self.height);
        if edges.len() != w * h {
            return Err(EdgeError::Size {
                what: "edges",
                width: w,
                height: h,
                expected: w * h,
                actual: edges.len(),
            });
        }
        if (model.width as usize, model.height as usize) != (w, h) {
            return Err(EdgeError::Options(format!(
                "chains: calibration is {}x{} but edges are {w}x{h}",
                model.width, model.height
            )));
        }
        out.clear();
        self.touched.clear();
        let mut result = ChainResult::default();
        let min_len = self.params.min_length;
        // Scan eight bytes at a time; edge images are mostly empty.
        let mut base = 0usize;
        for chunk in edges.chunks(8) {
            let any = if chunk.len() == 8 {
                u64::from_ne_bytes(chunk.try_into().unwrap_or([0; 8])) != 0
            } else {
                chunk.iter().any(|&v| v != 0)
            };
            if any {
                for (k, &v) in chunk.iter().enumerate() {
                    let i = base + k;
                    if v != 0 && self.visited[i] == 0 {
                        let start = out.pixels.len();
                        self.trace_from(i, edges, out);
                        result.traced += 1;
                        let len = out.pixels.len() - start;
                        if len < min_len {
                            out.pixels.truncate(start);
                        } else {
                            out.ranges.push((start as u32, out.pixels.len() as u32));
                            result.kept += 1;
                            result.pixels += len;
                        }
                    }
                }
            }
            base += chunk.len();
        }
        for &i in &self.touched {
            self.visited[i as usize] = 0;
        }
        self.located.clear();
        self.located.extend(
            out.pixels
                .iter()
                .map(|p| locate(p[0] as usize, p[1] as usize)),
        );
        model.cam2world_many(&self.located, &mut out.rays);
        Ok(result)
    }

    /// Walks from `start` in both directions and appends the ordered chain to `out.pixels`.
    fn trace_from(&mut self, start: usize, edges: &[u8], out: &mut Chains) {
        let w = self.width;
        self.mark(start);
        // First direction into `half`, second straight into the output, then join them.
        self.half.clear();
        let mut cur = start;
        while let Some(next) = self.step(cur, edges) {
            self.mark(next);
            self.half.push(next as u32);
            cur = next;
        }
        for &i in self.half.iter().rev() {
            let i = i as usize;
            out.pixels.push([(i / w) as u32, (i % w) as u32]);
        }
        out.pixels.push([(start / w) as u32, (start % w) as u32]);
        let mut cur = start;
        while let Some(next) = self.step(cur, edges) {
            self.mark(next);
            out.pixels.push([(next / w) as u32, (next % w) as u32]);
            cur = next;
        }
    }

    #[inline]
    fn mark(&mut self, i: usize) {
        self.visited[i] = 1;
        self.touched.push(i as u32);
    }

    /// The next untraced edge neighbour of pixel `i`: 4-neighbours first, then diagonals.
    #[inline]
    fn step(&self, i: usize, edges: &[u8]) -> Option<usize> {
        let (w, h) = (self.width as isize, self.height as isize);
        let (r, c) = ((i / self.width) as isize, (i % self.width) as isize);
        const ORDER: [(isize, isize); 8] = [
            (-1, 0),
            (0, -1),
            (0, 1),
            (1, 0),
            (-1, -1),
            (-1, 1),
            (1, -1),
            (1, 1),
        ];
        for (dr, dc) in ORDER {
            let (rr, cc) = (r + dr, c + dc);
            if rr < 0 || cc < 0 || rr >= h || cc >= w {
                continue;
            }
            let j = (rr * w + cc) as usize;
            if edges[j] != 0 && self.visited[j] == 0 {
                return Some(j);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;

    fn tracer(w: usize, h: usize, min_length: usize) -> ChainTracer {
        ChainTracer::new(ChainParams { min_length }, w, h).unwrap()
    }

    fn is_8_connected_path(p: &[[u32; 2]]) -> bool {
        p.windows(2).all(|q| {
            let dr = (q[0][0] as i64 - q[1][0] as i64).abs();
            let dc = (q[0][1] as i64 - q[1][1] as i64).abs();
            dr <= 1 && dc <= 1 && dr + dc > 0
        })
    }

    #[test]
    fn line_traced_in_order_from_the_middle() {
        let cal = ideal_fisheye(60, 80).unwrap();
        let (w, h) = (80, 60);
        let mut edges = vec![0u8; w * h];
        // A staircase whose raster-first pixel is its top-left end, and a horizontal line.
        for k in 0..30 {
            edges[(10 + k / 2) * w + 5 + k] = 255; // staircase
        }
        for c in 40..75 {
            edges[50 * w + c] = 255;
        }
        let mut ch = Chains::default();
        let mut t = tracer(w, h, 5);
        let r = t.trace(&edges, &cal.model, &mut ch).unwrap();
        assert_eq!(r.kept, 2, "{r:?}");
        assert_eq!(ch.len(), 2);
        assert_eq!(r.pixels, 30 + 35);
        for k in 0..ch.len() {
            let (a, b) = ch.ranges[k];
            assert!(is_8_connected_path(&ch.pixels[a as usize..b as usize]));
        }
        assert_eq!(ch.rays.len(), ch.pixels.len());
        for (p, ray) in ch.pixels.iter().zip(&ch.rays) {
            let back = cal.model.world2cam(ray).unwrap();
            assert!((back[0] - p[0] as f64).abs() < 1e-6 && (back[1] - p[1] as f64).abs() < 1e-6);
        }
    }

    #[test]
    fn chain_starting_mid_way_is_joined_in_order() {
        let cal = ideal_fisheye(40, 40).unwrap();
        let (w, h) = (40, 40);
        let mut edges = vec![0u8; w * h];
        // An upside-down V: its raster-first pixel is the apex in the middle.
        for k in 0..15 {
            edges[(5 + k) * w + 20 - k] = 255;
            edges[(5 + k) * w + 20 + k] = 255;
        }
        let mut ch = Chains::default();
        let mut t = tracer(w, h, 3);
        t.trace(&edges, &cal.model, &mut ch).unwrap();
        assert_eq!(ch.len(), 1);
        let (a, b) = ch.ranges[0];
        let p = &ch.pixels[a as usize..b as usize];
        assert_eq!(p.len(), 29);
        assert!(is_8_connected_path(p));
        assert_eq!(p[14], [5, 20]);
        // The tracer is reusable: the same image gives the same chains.
        let mut ch2 = Chains::default();
        t.trace(&edges, &cal.model, &mut ch2).unwrap();
        assert_eq!(ch.pixels, ch2.pixels);
    }

    #[test]
    fn junction_splits_and_short_chains_drop() {
        let cal = ideal_fisheye(40, 40).unwrap();
        let (w, h) = (40, 40);
        let mut edges = vec![0u8; w * h];
        for c in 2..38 {
            edges[20 * w + c] = 255; // horizontal
        }
        for r in 21..35 {
            edges[r * w + 20] = 255; // a branch down from the middle
        }
        edges[2 * w + 2] = 255; // isolated pixel
        let mut ch = Chains::default();
        let mut t = tracer(w, h, 5);
        let r = t.trace(&edges, &cal.model, &mut ch).unwrap();
        assert_eq!(r.traced, 3, "{r:?}");
        assert_eq!(r.kept, 2);
        assert_eq!(r.pixels, 36 + 14);
        let e = t.trace(&edges[1..], &cal.model, &mut ch).unwrap_err();
        assert!(e.to_string().contains("edges"));
    }
}
