//! Each row's own line: real rows do not all meet in one point (rows bend, rise and fall with
//! the ground; a drill wanders), and a row's line through a common point a few pixels off
//! misses its far field. A row is fitted its own straight line in the virtual image to the
//! straightened peaks on its tooth, each peak counting once (as every scan line of a labelled
//! row does), with the vanishing point as one more point weighing `OWN_LINE_ANCHOR` times all
//! of them: the far field, where the rows merge, follows the common point, and the near field
//! the row's own peaks. The line is then fitted again without the peaks far from it (a weed or
//! a neighbouring plant on the tooth's band).

use super::agreement::{MIN_DEPTH_PX, PEAK_SIGMA_PX};
use super::comb::{LINE_DEPTH_PX, MIN_STRIPS_FLOOR};
use super::peaks::Peak;
use super::StripsRows;
use nalgebra::Vector3;

/// The vanishing point's weight in a row's own line, as a share of the row's peaks.
const OWN_LINE_ANCHOR: f64 = 0.3;

/// The row's line is fitted again without the peaks farther from the first fit than this many
/// times a peak's position uncertainty.
const OWN_LINE_REJECT: f64 = 2.0;

impl StripsRows {
    /// The great circle (unnormalised normal) of the row on the tooth at `u` of the pencil
    /// through (a, p), `band` the tooth's half-width in u, fitted its own line:
    /// [`Self::line_fit`] over the peaks whose u lies within `band` of the tooth, then again
    /// without those farther than `OWN_LINE_REJECT` × `PEAK_SIGMA_PX` from that line. `None`
    /// when too few strips hold peaks: the row is then its tooth's line.
    pub(super) fn own_line(&self, a: f64, p: f64, u: f64, band: f64) -> Option<Vector3<f64>> {
        let on = |k: &Peak| {
            let d = k.p - p;
            d > MIN_DEPTH_PX && ((k.a - a) / d - u).abs() <= band
        };
        let (b0, b1) = self.line_fit(a, p, on)?;
        let lim = OWN_LINE_REJECT * PEAK_SIGMA_PX;
        let near = |k: &Peak| on(k) && (k.a - (b0 + b1 * (k.p - p))).abs() <= lim;
        let (c0, c1) = self.line_fit(a, p, near)?;
        let (d1, d2) = (MIN_DEPTH_PX, LINE_DEPTH_PX);
        let n = self
            .to_ray(c0 + c1 * d1, p + d1)
            .cross(&self.to_ray(c0 + c1 * d2, p + d2));
        (n.norm() > 0.0).then_some(n)
    }

    /// The line a = c₀ + c₁·d (d = depth below p) fitted by least squares to the peaks `on`
    /// (weight 1 each) and to the point (a, p) itself (d = 0, weight `OWN_LINE_ANCHOR` × their
    /// count): (c₀, c₁). `None` when they lie in fewer than `MIN_STRIPS_FLOOR` strips.
    fn line_fit(&self, a: f64, p: f64, on: impl Fn(&Peak) -> bool) -> Option<(f64, f64)> {
        let (mut n, mut sd, mut sa, mut strips) = (0.0, 0.0, 0.0, 0usize);
        let mut last = u32::MAX;
        for k in self.peaks.iter().filter(|k| on(k)) {
            n += 1.0;
            sd += k.p - p;
            sa += k.a;
            // the peaks are in the strips' order
            if k.strip != last {
                (last, strips) = (k.strip, strips + 1);
            }
        }
        if strips < MIN_STRIPS_FLOOR {
            return None;
        }
        let wv = OWN_LINE_ANCHOR * n;
        let (dm, am) = (sd / (n + wv), (sa + wv * a) / (n + wv));
        let (mut sdd, mut sda) = (wv * dm * dm, -wv * dm * (a - am));
        for k in self.peaks.iter().filter(|k| on(k)) {
            let dd = k.p - p - dm;
            sdd += dd * dd;
            sda += dd * (k.a - am);
        }
        if sdd <= 0.0 {
            return None;
        }
        let c1 = sda / sdd;
        Some((am - c1 * dm, c1))
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn a_row_turned_off_the_common_point_gets_its_own_line() {
        // five rows 0.5 m apart, the middle one laid 0.6° off the others (a drill that
        // wandered): it does not pass through their vanishing point
        let m = forward_camera();
        let mut fld = field_at(300.0, 512.0, &m, &[-1.0, -0.5, 0.5, 1.0], 0.0);
        let turned = field_at(300.0, 512.0, &m, &[0.0], 0.6f64.to_radians());
        fld.rays.extend(&turned.rays);
        fld.weights.extend(&turned.weights);
        fld.pixel_rad.extend(&turned.pixel_rad);
        // the row up to 10 m ahead, where the robot steers
        let line = centre_line(300.0, 512.0, &m, 0.0, 0.6f64.to_radians(), 10.0);
        let (_, vp, rows) = detect(&fld, &m);
        let vp = vp.expect("a vanishing point");
        assert_eq!(rows.len(), 5);
        let row = rows
            .iter()
            .min_by(|x, y| {
                let off = |n| off_line_px(n, &line, 300.0);
                off(&x.normal).total_cmp(&off(&y.normal))
            })
            .unwrap();
        // its far end is held near the common point by the anchor, its near field is its own
        let own = off_line_px(&row.normal, &line, 300.0);
        assert!(own < 2.5, "own line {own} px off");
        let through_vp = row.normal.dot(&vp).abs().asin() / (-vp.z).powi(2) * 300.0;
        assert!(through_vp > 0.5, "{through_vp} px from the vanishing point");
    }
}
