//! The comb: crop rows are evenly spaced on the ground, so seen from their vanishing point
//! the peaks' u (lateral over depth in the pencil) form a comb, its period the rows' spacing
//! over the camera's height, about. The comb's period and phase are the peaks' strongest
//! Fourier component; each tooth with peaks in enough strips is a row, placed at the centre of
//! the peaks on it (real rows are not evenly spaced: tramlines, drilling units, a wandering
//! drill), and given its own line ([`super::own_line`]). Peaks between the teeth (weeds,
//! plant edges, shadows) are not rows.

use super::agreement::{SeenColumns, MIN_DEPTH_PX};
use super::fourier::fourier;
use super::StripsRows;
use crate::detect::types::{Method, Row};

/// Periods tried between `comb_min_period` and `comb_max_period`, geometrically spaced.
const COMB_PERIODS: usize = 160;

/// A peak is on a tooth within this fraction of the period.
const COMB_BAND: f64 = 0.2;

/// A tooth of the comb is a row when peaks lie on it in at least this many strips.
const MIN_STRIPS: usize = 7;

/// A tooth whose line leaves the points early (an outer row leaving the image by its side)
/// cannot have peaks in `MIN_STRIPS` strips: it needs only this share of the strips its line
/// crosses inside their points (below `MIN_DEPTH_PX`), rounded up, but at least
/// `MIN_STRIPS_FLOOR` and at most `MIN_STRIPS`.
const MIN_STRIPS_SHARE: f64 = 0.8;

/// The fewest strips a tooth ever needs to be a row, and a row's own line to be fitted.
pub(super) const MIN_STRIPS_FLOOR: usize = 6;

/// A row is placed at the weighted mean u of the peaks within the tooth's band of it,
/// re-centred this many times starting from its tooth.
const RECENTRE_ROUNDS: usize = 2;

/// Depth below the vanishing point (pixels) of the far point through which a row's line is
/// taken (the near one is the vanishing point itself, or `MIN_DEPTH_PX` for its own line).
pub(super) const LINE_DEPTH_PX: f64 = 100.0;

/// The most teeth a comb may have across the peaks.
const MAX_TEETH: i64 = 4096;

impl StripsRows {
    /// The peaks' comb seen from (a, p) ([`Self::comb`], with `self.sight.columns` filled for
    /// it); `None` when no peak lies below the point.
    pub(super) fn comb_at(&mut self, a: f64, p: f64) -> Option<(f64, f64, f64)> {
        self.see(a, p);
        (self.sight.columns.len() > 0).then(|| self.comb())
    }

    /// The strongest comb of the peaks' u in `self.sight.columns` (filled by `see`): (amplitude,
    /// period, phase), the amplitude their Fourier component's over their total weight.
    /// Periods from `comb_min_period` to `comb_max_period`.
    fn comb(&mut self) -> (f64, f64, f64) {
        let o = &self.opts;
        let c = &self.sight.columns;
        let total: f64 = c.w.iter().sum();
        let ratio = (o.comb_max_period / o.comb_min_period).powf(1.0 / (COMB_PERIODS - 1) as f64);
        let mut period = o.comb_min_period;
        let mut best = (0.0, period, 0.0);
        if total <= 0.0 {
            return best;
        }
        for _ in 0..COMB_PERIODS {
            let f = std::f64::consts::TAU / period;
            let (c, s) = fourier(&c.u, &c.w, f);
            let amp = c.hypot(s) / total;
            if amp > best.0 {
                best = (amp, period, s.atan2(c) / f);
            }
            period *= ratio;
        }
        best
    }

    /// The comb of the peaks' u seen from (a, p) and its teeth as rows into `rows`, each on
    /// its own line where it has one, else on its tooth's line through (a, p).
    pub(super) fn comb_rows(&mut self, a: f64, p: f64, rows: &mut Vec<Row>) {
        let Some((amp, period, phase)) = self.comb_at(a, p) else {
            return;
        };
        self.last.period = period;
        self.last.comb_strength = amp;
        if !self.comb_teeth(a, p, period, phase) {
            return;
        }
        let vp = self.to_ray(a, p);
        for &[m, _, support] in &self.teeth {
            let pencil = vp.cross(&self.to_ray(a + m * LINE_DEPTH_PX, p + LINE_DEPTH_PX));
            let n = match self.own_line(a, p, m, COMB_BAND * period) {
                Some(n) if n.dot(&pencil) < 0.0 => -n,
                Some(n) => n,
                None => pencil,
            };
            let norm = n.norm();
            if norm > 0.0 {
                rows.push(Row {
                    normal: n / norm,
                    method: Method::Strips,
                    support: support as u32,
                    width_rad: 0.0,
                });
            }
        }
    }

    /// The teeth of the comb (`period`, `phase`) of the peaks in `self.sight.columns`, seen from
    /// (a, p), that are rows, into `self.teeth` (u re-centred on its peaks, weight, number of
    /// peaks): in order across the image, or the `max_rows` heaviest when there are more.
    /// False when the comb has too many teeth across the peaks.
    fn comb_teeth(&mut self, a: f64, p: f64, period: f64, phase: f64) -> bool {
        let c = &self.sight.columns;
        let (u0, u1) = (c.u[0], c.u[c.len() - 1]);
        let k0 = ((u0 - phase) / period).floor() as i64;
        let k1 = ((u1 - phase) / period).ceil() as i64;
        if k1 - k0 > MAX_TEETH {
            return false;
        }
        self.teeth.clear();
        for k in k0..=k1 {
            let m = phase + k as f64 * period;
            let band = COMB_BAND * period;
            let on = c.within(m, band);
            let seen = distinct_strips(&c.strip[on.clone()]);
            if seen >= MIN_STRIPS || (seen >= MIN_STRIPS_FLOOR && seen >= self.need(a, p, m)) {
                let w: f64 = c.w[on.clone()].iter().sum();
                self.teeth.push([recentre(c, m, band), w, on.len() as f64]);
            }
        }
        if self.teeth.len() > self.opts.max_rows {
            self.teeth.sort_unstable_by(|x, y| y[1].total_cmp(&x[1]));
            self.teeth.truncate(self.opts.max_rows);
        }
        true
    }

    /// How many strips a tooth at `u` of the pencil through (a, p) needs peaks in to be a row:
    /// `MIN_STRIPS_SHARE` of the strips its line crosses inside their points (below
    /// `MIN_DEPTH_PX`), rounded up, within `MIN_STRIPS_FLOOR..=MIN_STRIPS`.
    fn need(&self, a: f64, p: f64, u: f64) -> usize {
        let crossed = self
            .spans
            .iter()
            .filter(|&&[sp, lo, hi]| {
                let d = sp - p;
                let x = a + u * d;
                d > MIN_DEPTH_PX && (lo..=hi).contains(&x)
            })
            .count();
        let share = (MIN_STRIPS_SHARE * crossed as f64).ceil() as usize;
        share.clamp(MIN_STRIPS_FLOOR, MIN_STRIPS)
    }
}

/// The tooth at `m` re-centred on its peaks: `RECENTRE_ROUNDS` times, the weighted mean u of
/// the peaks within `band` of it.
fn recentre(c: &SeenColumns, m: f64, band: f64) -> f64 {
    let mut at = m;
    for _ in 0..RECENTRE_ROUNDS {
        let on = c.within(at, band);
        let sw: f64 = c.w[on.clone()].iter().sum();
        if sw > 0.0 {
            let wu = c.w[on.clone()].iter().zip(&c.u[on]);
            at = wu.map(|(w, u)| w * u).sum::<f64>() / sw;
        }
    }
    at
}

/// How many different strips the peaks come from.
fn distinct_strips(on: &[u32]) -> usize {
    let mut n = 0;
    for (i, x) in on.iter().enumerate() {
        if on[..i].iter().all(|y| y != x) {
            n += 1;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn rows_spaced_unevenly_lie_on_their_own_peaks_not_on_the_comb() {
        // 0.5 m rows, each shifted by up to 0.09 m (under the comb's band of 0.2 period):
        // the comb's evenly spaced teeth miss them, the teeth re-centred on their peaks do
        // not
        let m = forward_camera();
        let shift = [0.0, 0.09, -0.07, 0.05, -0.09, 0.08, -0.04, 0.07, -0.08];
        let ys: Vec<f64> = (-4..=4)
            .zip(shift)
            .map(|(k, d)| 0.1 + k as f64 * 0.5 + d)
            .collect();
        let heading = 3f64.to_radians();
        let fld = field_at(300.0, 512.0, &m, &ys, heading);
        let (mut s, vp, rows) = detect(&fld, &m);
        vp.expect("a vanishing point");
        assert!(rows.len() >= 4, "{} rows", rows.len());
        for r in &rows {
            let e = nearest(&r.normal, &fld.normals);
            assert!(e < 4.0 / 300.0, "a row {e} rad from every true row");
        }
        // the true rows' u seen from the vanishing point found, 3 m ahead
        let [av, pv] = s.last().vanishing_px.unwrap();
        let cam_from_robot = m.robot_from_camera().inverse();
        let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), heading);
        let truth: Vec<f64> = ys
            .iter()
            .filter_map(|&y| {
                let r = cam_from_robot * (yaw * Vector3::new(3.0, y, -m.height_m));
                let [a, p] = s.to_virtual(&r)?;
                Some((a - av) / (p - pv))
            })
            .collect();
        let off = |u: f64| truth.iter().map(|t| (t - u).abs()).fold(f64::MAX, f64::min);
        // each row's tooth: re-centred on its peaks, and as the comb placed it
        let (_, period, phase) = s.comb_at(av, pv).unwrap();
        let (mut on_peaks, mut on_teeth) = (0.0f64, 0.0f64);
        for &[at, _, _] in &s.teeth {
            let tooth = phase + ((at - phase) / period).round() * period;
            on_peaks = on_peaks.max(off(at));
            on_teeth = on_teeth.max(off(tooth));
        }
        assert!(on_peaks < 0.03 * period, "a row {on_peaks} from its true u");
        assert!(
            on_teeth > 2.0 * on_peaks,
            "the comb's teeth alone were as close ({on_teeth}): the test shows nothing"
        );
    }

    #[test]
    fn rows_leaving_the_image_early_need_fewer_strips() {
        // the outer rows leave the image by their sides: their teeth cannot have peaks in
        // `MIN_STRIPS` strips, and need fewer
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.75, 0.1, -4f64.to_radians());
        let (s, vp, rows) = detect(&fld, &m);
        vp.expect("a vanishing point");
        for r in &rows {
            let e = nearest(&r.normal, &fld.normals);
            assert!(e < 2.5 / 300.0, "a row {e} rad off");
        }
        assert!(rows.len() >= 12, "{} rows", rows.len());
        let [a, p] = s.last().vanishing_px.unwrap();
        let fewer = s.teeth.iter().filter(|t| s.need(a, p, t[0]) < MIN_STRIPS);
        assert!(
            fewer.count() >= 2,
            "the outer rows need as many strips as the others"
        );
    }

    #[test]
    fn scattered_points_give_no_rows_between_the_teeth() {
        // rows plus uniform weeds: every published row is a true row
        let m = forward_camera();
        let mut fld = field(300.0, 512.0, &m, 0.6, 0.0, 0.0);
        let mut seed = 99u64;
        for _ in 0..6000 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let row = ((seed >> 33) % 512) as f64 - 256.0;
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let col = ((seed >> 33) % 512) as f64 - 256.0;
            let r = Vector3::new(row / 300.0, col / 300.0, -1.0).normalize();
            fld.rays.push([r.x as f32, r.y as f32, r.z as f32]);
            fld.weights.push(1.0);
            fld.pixel_rad.push(((-r.z).powf(1.5) / 300.0) as f32);
        }
        let (_, _, rows) = detect(&fld, &m);
        assert!(rows.len() >= 3);
        // each published row lies on a true row where that row is in the image
        let lines: Vec<_> = (-8..=8)
            .map(|k| centre_line(300.0, 512.0, &m, k as f64 * 0.6, 0.0, 40.0))
            .filter(|l| l.len() >= 2)
            .collect();
        for r in &rows {
            let off = lines
                .iter()
                .map(|l| off_line_px(&r.normal, l, 300.0))
                .fold(f64::MAX, f64::min);
            assert!(off < 2.5, "a row {off} px from every true row");
        }
    }

    #[test]
    fn distinct_strips_count_each_strip_once() {
        assert_eq!(distinct_strips(&[]), 0);
        assert_eq!(distinct_strips(&[3, 1, 3, 3, 2, 1]), 3);
    }
}
