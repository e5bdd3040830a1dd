//! Merging great-circle sections that describe the same row.
//!
//! Paper II-C: normals closer than a threshold describe the same row; the merged normal is
//! refitted by SVD over all their points. Sections are taken by decreasing length; a section
//! joins a row only if its normal lies within `max_angle_rad` of the normal of *every* section
//! already in that row (complete linkage: no two merged normals are ever farther apart than
//! the threshold) and the refitted great circle leaves the rows' points within
//! `max_residual_px` on average (RMS). The refit adds the sections' scatter matrices
//! ([`Scatter::merge`]), which is the same least-squares fit as over all the points and needs
//! no point buffer. Each row keeps its support: the number of points of its sections.

use super::EdgeError;
use crate::detect::types::{Method, Row};
use crate::sphere::Scatter;
use nalgebra::Vector3;

use super::split::Section;

/// Parameters of the merge stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MergeParams {
    /// Sections whose normals are closer than this angle (radians) may describe the same
    /// row. The two boundaries of a distant row are only a few hundredths of a radian apart,
    /// and merging them mixes two lines into one biased normal. Default
    /// [`REFERENCE_MAX_ANGLE_RAD`]; the detector scales it with the calibration's field of
    /// view ([`crate::detect::scale`]).
    pub max_angle_rad: f64,
    /// The merged great circle must fit all points with an RMS distance within this many
    /// pixels (converted with the calibration's angular pixel size). Default 1.5.
    pub max_residual_px: f64,
    /// Rows with less support (points) are dropped. Default 30.
    pub min_support: u32,
}

/// The merge angle (radians) at the reference angular resolution (the GC2450C's lenses).
pub const REFERENCE_MAX_ANGLE_RAD: f64 = 0.005;

impl Default for MergeParams {
    fn default() -> Self {
        MergeParams {
            max_angle_rad: REFERENCE_MAX_ANGLE_RAD,
            max_residual_px: 1.5,
            min_support: 30,
        }
    }
}

/// What one merge run did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MergeResult {
    /// Rows written.
    pub rows: usize,
    /// Rows dropped for too little support.
    pub dropped: usize,
}

#[derive(Debug, Clone, Copy)]
struct Cluster {
    scatter: Scatter,
    normal: Vector3<f64>,
    /// First member section (linked through `next`).
    head: u32,
}

/// Sentinel for "no section" / "no row".
pub const NONE: u32 = u32::MAX;

/// Merges sections into rows, reusing its buffers.
#[derive(Debug, Clone)]
pub struct Merger {
    params: MergeParams,
    cos_angle: f64,
    max_mean_sq: f64,
    order: Vec<u32>,
    clusters: Vec<Cluster>,
    next: Vec<u32>,
    cluster_of: Vec<u32>,
    row_of_cluster: Vec<u32>,
    assignment: Vec<u32>,
}

impl Merger {
    /// `pixel_angle_rad` is the angle one pixel subtends (to read `max_residual_px`).
    pub fn new(params: MergeParams, pixel_angle_rad: f64) -> Result<Self, EdgeError> {
        let max_angle = params.max_angle_rad;
        if !(0.0..std::f64::consts::FRAC_PI_2).contains(&max_angle) {
            return Err(EdgeError::Options(format!(
                "merge: max_angle_rad = {} must be in [0, pi/2)",
                max_angle
            )));
        }
        if !(params.max_residual_px > 0.0 && params.max_residual_px.is_finite()) {
            return Err(EdgeError::Options(format!(
                "merge: max_residual_px = {} must be > 0",
                params.max_residual_px
            )));
        }
        if !(pixel_angle_rad > 0.0 && pixel_angle_rad < 0.5) {
            return Err(EdgeError::Options(format!(
                "merge: angular pixel size {pixel_angle_rad} rad is not plausible"
            )));
        }
        let r = (params.max_residual_px * pixel_angle_rad).sin();
        Ok(Merger {
            params,
            cos_angle: max_angle.cos(),
            max_mean_sq: r * r,
            order: Vec::new(),
            clusters: Vec::new(),
            next: Vec::new(),
            cluster_of: Vec::new(),
            row_of_cluster: Vec::new(),
            assignment: Vec::new(),
        })
    }

    pub fn params(&self) -> &MergeParams {
        &self.params
    }

    /// For each section of the last run, the index of its row in the output, or [`NONE`]
    /// when its row was dropped.
    pub fn assignment(&self) -> &[u32] {
        &self.assignment
    }

    /// Merges `sections` into rows written to `rows` (cleared first), by decreasing support.
    pub fn merge(
        &mut self,
        sections: &[Section],
        rows: &mut Vec<Row>,
    ) -> Result<MergeResult, EdgeError> {
        rows.clear();
        let n = sections.len();
        if n >= NONE as usize {
            return Err(EdgeError::Options(format!(
                "merge: {n} sections are too many"
            )));
        }
        self.order_by_length(sections);
        self.clusters.clear();
        self.next.clear();
        self.next.resize(n, NONE);
        self.cluster_of.clear();
        self.cluster_of.resize(n, NONE);
        for oi in 0..n {
            let si = self.order[oi] as usize;
            if !self.join(sections, si) {
                self.cluster_of[si] = self.clusters.len() as u32;
                self.clusters.push(Cluster {
                    scatter: sections[si].scatter,
                    normal: sections[si].normal,
                    head: si as u32,
                });
            }
        }
        let result = self.write_rows(rows);
        self.assignment.clear();
        for &c in &self.cluster_of {
            self.assignment.push(self.row_of_cluster[c as usize]);
        }
        Ok(result)
    }

    /// Puts the sections' indices in `order` by decreasing length, ties by index.
    fn order_by_length(&mut self, sections: &[Section]) {
        self.order.clear();
        self.order.extend(0..sections.len() as u32);
        self.order.sort_unstable_by(|&a, &b| {
            sections[b as usize]
                .len()
                .cmp(&sections[a as usize].len())
                .then(a.cmp(&b))
        });
    }

    /// Adds section `si` to the first cluster that takes it: its normal within the merge
    /// angle of the cluster's and of every member's, and the refitted great circle within
    /// the residual. False when no cluster takes it.
    fn join(&mut self, sections: &[Section], si: usize) -> bool {
        let s = &sections[si];
        for ci in 0..self.clusters.len() {
            let c = &self.clusters[ci];
            if c.normal.dot(&s.normal).abs() < self.cos_angle {
                continue;
            }
            if !self.near_every_member(sections, c.head, &s.normal) {
                continue;
            }
            let mut merged = c.scatter;
            merged.merge(&s.scatter);
            let Some(fit) = merged.fit() else { continue };
            if fit.mean_sq_residual > self.max_mean_sq {
                continue;
            }
            let c = &mut self.clusters[ci];
            c.scatter = merged;
            c.normal = fit.normal;
            self.next[si] = c.head;
            c.head = si as u32;
            self.cluster_of[si] = ci as u32;
            return true;
        }
        false
    }

    /// Complete linkage: whether `normal` lies within the merge angle of every member of the
    /// cluster whose first member is `head`.
    fn near_every_member(&self, sections: &[Section], head: u32, normal: &Vector3<f64>) -> bool {
        let mut m = head;
        while m != NONE {
            if sections[m as usize].normal.dot(normal).abs() < self.cos_angle {
                return false;
            }
            m = self.next[m as usize];
        }
        true
    }

    /// Writes the clusters with enough support to `rows` by decreasing support, ties by first
    /// appearance, and notes each cluster's row in `row_of_cluster` ([`NONE`] if dropped).
    fn write_rows(&mut self, rows: &mut Vec<Row>) -> MergeResult {
        self.order.clear();
        self.order.extend(0..self.clusters.len() as u32);
        let clusters = &self.clusters;
        self.order.sort_unstable_by(|&a, &b| {
            clusters[b as usize]
                .scatter
                .count()
                .cmp(&clusters[a as usize].scatter.count())
                .then(a.cmp(&b))
        });
        self.row_of_cluster.clear();
        self.row_of_cluster.resize(self.clusters.len(), NONE);
        let mut result = MergeResult::default();
        for &ci in &self.order {
            let c = &self.clusters[ci as usize];
            let support = c.scatter.count().min(u32::MAX as usize) as u32;
            if support < self.params.min_support {
                result.dropped += 1;
                continue;
            }
            self.row_of_cluster[ci as usize] = rows.len() as u32;
            rows.push(Row {
                normal: c.normal,
                method: Method::Edge,
                support,
                width_rad: 0.0,
            });
        }
        result.rows = rows.len();
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sphere::{any_perpendicular, axis_angle, from_phi_theta};
    use proptest::prelude::*;

    fn section_on(normal: &Vector3<f64>, t0: f64, n: usize, start: u32) -> Section {
        let u = any_perpendicular(normal);
        let v = normal.cross(&u);
        let mut scatter = Scatter::new();
        for i in 0..n {
            let t = t0 + 0.002 * i as f64;
            scatter.add(&(u * t.cos() + v * t.sin()), 1.0);
        }
        Section {
            chain: 0,
            start,
            end: start + n as u32,
            normal: scatter.fit().unwrap().normal,
            scatter,
            max_residual_rad: 0.0,
        }
    }

    fn merger(max_angle_rad: f64) -> Merger {
        Merger::new(
            MergeParams {
                max_angle_rad,
                max_residual_px: 1.5,
                min_support: 0,
            },
            0.0016,
        )
        .unwrap()
    }

    #[test]
    fn sections_of_one_circle_become_one_row_with_summed_support() {
        let n = from_phi_theta(1.2, 0.4);
        let secs = [
            section_on(&n, 0.0, 40, 0),
            section_on(&n, 1.0, 25, 40),
            section_on(&n, 2.5, 60, 65),
        ];
        let mut rows = Vec::new();
        let r = merger(0.02).merge(&secs, &mut rows).unwrap();
        assert_eq!(r.rows, 1);
        assert_eq!(rows[0].support, 125);
        assert_eq!(rows[0].method, Method::Edge);
        assert!(axis_angle(&rows[0].normal, &n) < 1e-9);
    }

    #[test]
    fn min_support_drops_rows() {
        let a = from_phi_theta(1.2, 0.4);
        let b = from_phi_theta(0.6, 2.0);
        let secs = [section_on(&a, 0.0, 40, 0), section_on(&b, 0.0, 20, 40)];
        let mut m = Merger::new(MergeParams::default(), 0.0016).unwrap();
        let mut rows = Vec::new();
        let r = m.merge(&secs, &mut rows).unwrap();
        assert_eq!((r.rows, r.dropped), (1, 1));
        assert_eq!(m.assignment(), &[0, NONE]);
    }

    proptest! {
        #[test]
        fn same_circle_merges_to_summed_support(
            phi in 0.1f64..3.0, theta in 0.0f64..6.2,
            lens in proptest::collection::vec(20usize..80, 1..6),
        ) {
            let n = from_phi_theta(phi, theta);
            let mut start = 0u32;
            let secs: Vec<Section> = lens.iter().enumerate().map(|(k, &l)| {
                let s = section_on(&n, k as f64 * 0.4, l, start);
                start += l as u32;
                s
            }).collect();
            let mut rows = Vec::new();
            merger(0.02).merge(&secs, &mut rows).unwrap();
            prop_assert_eq!(rows.len(), 1);
            prop_assert_eq!(rows[0].support as usize, lens.iter().sum::<usize>());
            prop_assert!(axis_angle(&rows[0].normal, &n) < 1e-8);
        }

        #[test]
        fn never_merges_normals_farther_apart_than_threshold(
            normals in proptest::collection::vec((0.1f64..3.0, 0.0f64..6.2, 0.0f64..0.08, 0.0f64..6.3), 1..25),
            thr in 0.005f64..0.05,
        ) {
            // Clusters of nearby normals (random offsets up to 0.08 rad from a few centres).
            let secs: Vec<Section> = normals.iter().enumerate().map(|(k, &(p, t, off, dir))| {
                let c = from_phi_theta(p, t);
                let u = any_perpendicular(&c);
                let v = c.cross(&u);
                let n = (c * off.cos() + (u * dir.cos() + v * dir.sin()) * off.sin()).normalize();
                section_on(&n, 0.0, 30, 30 * k as u32)
            }).collect();
            let mut m = Merger::new(MergeParams { max_angle_rad: thr, max_residual_px: 1e6, min_support: 0 }, 0.0016).unwrap();
            let mut rows = Vec::new();
            m.merge(&secs, &mut rows).unwrap();
            let a = m.assignment();
            let mut total = 0u32;
            for r in &rows { total += r.support; }
            prop_assert_eq!(total as usize, 30 * secs.len());
            for i in 0..secs.len() {
                for j in i + 1..secs.len() {
                    if a[i] == a[j] {
                        let d = axis_angle(&secs[i].normal, &secs[j].normal);
                        prop_assert!(d <= thr + 1e-12, "merged {} and {} at {} > {}", i, j, d, thr);
                    }
                }
            }
            // Support is conserved row by row.
            for (ri, r) in rows.iter().enumerate() {
                let s: usize = (0..secs.len()).filter(|&i| a[i] as usize == ri).map(|i| secs[i].len()).sum();
                prop_assert_eq!(s, r.support as usize);
            }
        }
    }
}
