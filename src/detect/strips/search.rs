//! The search for the vanishing point whose pencil lines the strips' peaks up best (the
//! highest agreement) within the heading and tilt limits, or within a prior's window: a grid
//! `SEARCH_STEP_PX` apart (first every other point on the strongest peaks, then in full only
//! around that coarser grid's best), its best local maxima climbed by halving steps to 1 px, and of the summits
//! they reach the highest, or a nearby one that the comb prefers in a near tie.

use super::StripsRows;
use nalgebra::Vector3;
use rayon::ThreadPool;

/// Step of the search's grid of candidate vanishing points (pixels), halved down to 1 px
/// in the climb.
const SEARCH_STEP_PX: f64 = 8.0;

/// How many of the grid's best local maxima are climbed to 1 px.
const SEARCH_STARTS: usize = 3;

/// The grid is first evaluated at twice its step on the strongest peaks
/// ([`super::agreement::COARSE_PEAKS_SHARE`]), and then in full on all of them only within
/// one coarse step of that coarser grid's this many best local maxima.
const SEARCH_REGIONS: usize = 6;

/// The climbed summits near the highest are ranked by their agreement times the comb's
/// strength there (the peaks' strongest Fourier component in u, 0..1) to this power. Crop
/// rows are evenly spaced on the ground, so of two nearby summits that the agreement nearly
/// ties — the near field's big plants line up from a point above the rows' as well as from
/// theirs — the rows' own is the one from which the peaks form the stronger comb. The power is
/// small: the comb only breaks ties (a summit needs a comb 2× as strong to beat one 19 %
/// higher).
const SEARCH_COMB_POWER: f64 = 0.25;

/// How far from the highest summit (pixels) another may win by its comb: farther summits are
/// other structures (a hedge, tramlines seen from the side), whose lines can look evenly
/// spaced too.
const SEARCH_COMB_REACH_PX: f64 = 100.0;

/// The most candidates a search's grid may have.
const MAX_CANDIDATES: usize = 1_000_000;

/// The eight neighbours of a grid point, in steps.
const NEIGHBOURS: [(f64, f64); 8] = [
    (-1.0, -1.0),
    (0.0, -1.0),
    (1.0, -1.0),
    (-1.0, 0.0),
    (1.0, 0.0),
    (-1.0, 1.0),
    (0.0, 1.0),
    (1.0, 1.0),
];

/// The most rounds of halving steps [`StripsRows::agreement_near`] climbs (each moves the
/// point less than `SEARCH_STEP_PX` along each axis).
const CLIMB_ROUNDS: usize = 8;

impl StripsRows {
    /// The vanishing point whose pencil lines the strips' peaks up best: the grid over the
    /// window (or the prior's box within it, [`Self::set_window`]), then halving steps from
    /// its `SEARCH_STARTS` best points, and of the summits they reach the highest or a nearby
    /// one with a stronger comb ([`pick_summit`]). (along, below, agreement). With a prior,
    /// `None` also when the box's best lies on an edge the box adds to the window: the
    /// agreement still rises beyond it, so the rows' vanishing point is outside the prior's
    /// window.
    /// The candidates are evaluated on `pool`'s threads when there is one (the same answer).
    pub(super) fn search(&mut self, pool: Option<&ThreadPool>) -> Option<(f64, f64, f64)> {
        if self.peaks.len() < 4 {
            return None;
        }
        let full = self.window()?;
        let (bx, step, regions) = self.search_box(full)?;
        let (na, np) = grid_size(&bx, step);
        if na * np > MAX_CANDIDATES {
            return None;
        }
        let (a0, p0) = (bx[0], bx[2]);
        self.fill_grid([a0, p0, step], na, np, regions, pool);
        // the grid's best local maxima, each refined by halving steps
        self.grid_maxima(na, np, 1);
        self.starts.truncate(SEARCH_STARTS);
        if self.best_on_added_edge(&bx, &full, na, np) {
            return None;
        }
        // each start climbed, in place: (agreement, along, below)
        for k in 0..self.starts.len() {
            let (e, i, j) = self.starts[k];
            self.starts[k] = self.refine((e, a0 + i * step, p0 + j * step), step, pool);
        }
        let summits = std::mem::take(&mut self.starts);
        let best = pick_summit(&summits, SEARCH_COMB_POWER, SEARCH_COMB_REACH_PX, |a, p| {
            self.comb_at(a, p).map_or(0.0, |c| c.0.max(0.0))
        });
        self.starts = summits;
        best.filter(|b| b.0 > 0.0).map(|b| (b.1, b.2, b.0))
    }

    /// The box searched (along from, to, below from, to), its grid's step and how many of the
    /// coarser grid's maxima are evaluated in full around (0: the whole grid): the `full`
    /// window on the search's grid, or the prior's box within it on a grid fine enough to have
    /// an inside. `None` when the prior's box misses the window.
    fn search_box(&self, full: [f64; 4]) -> Option<([f64; 4], f64, usize)> {
        let Some(b) = self.prior_box() else {
            return Some((full, SEARCH_STEP_PX, SEARCH_REGIONS));
        };
        let bx = [
            b[0].max(full[0]),
            b[1].min(full[1]),
            b[2].max(full[2]),
            b[3].min(full[3]),
        ];
        if bx[0] > bx[1] || bx[2] > bx[3] {
            return None;
        }
        // a small box: its whole grid
        let side = (bx[1] - bx[0]).min(bx[3] - bx[2]);
        Some((bx, (side / 8.0).clamp(1.0, SEARCH_STEP_PX), 0))
    }

    /// Whether the grid's best start (`self.starts`' first) lies on an edge of `bx` that
    /// the prior's box adds to the `full` window.
    fn best_on_added_edge(&self, bx: &[f64; 4], full: &[f64; 4], na: usize, np: usize) -> bool {
        let Some(&(_, i, j)) = self.starts.first() else {
            return false;
        };
        if bx == full {
            return false;
        }
        let (i, j) = (i as usize, j as usize);
        (i == 0 && bx[0] > full[0])
            || (i + 1 == na && bx[1] < full[1])
            || (j == 0 && bx[2] > full[2])
            || (j + 1 == np && bx[3] < full[3])
    }

    /// The candidate vanishing points' window in the virtual image: the box around the
    /// directions within the heading and tilt limits.
    fn window(&self) -> Option<[f64; 4]> {
        let h = self.opts.max_heading_deg.to_radians();
        let t = self.max_tilt;
        let (mut a0, mut a1, mut p0, mut p1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (az, el) in [
            (-h, -t),
            (-h, 0.0),
            (-h, t),
            (0.0, -t),
            (0.0, t),
            (h, -t),
            (h, 0.0),
            (h, t),
        ] {
            let [a, p] = self.to_virtual(&self.axes.direction(az, el))?;
            a0 = a0.min(a);
            a1 = a1.max(a);
            p0 = p0.min(p);
            p1 = p1.max(p);
        }
        Some([a0, a1, p0, p1])
    }

    /// The prior's window (set by [`Self::set_window`]) as a box in the virtual image
    /// (along from, to, below from, to): around the projections of the directions `w` from
    /// its vanishing point. `None` without a prior or when the window leaves the image
    /// plane.
    fn prior_box(&self) -> Option<[f64; 4]> {
        let (vp, w) = self.prior?;
        let vp = if vp.z < 0.0 { vp } else { -vp };
        let e1 = crate::sphere::any_perpendicular(&vp);
        let e2 = vp.cross(&e1);
        let (sw, cw) = w.sin_cos();
        let [mut a0, mut p0] = self.to_virtual(&vp)?;
        let (mut a1, mut p1) = (a0, p0);
        for (x, y) in NEIGHBOURS {
            let n = (x * x + y * y).sqrt();
            let d = vp * cw + (e1 * x + e2 * y) * (sw / n);
            let [a, p] = self.to_virtual(&d)?;
            a0 = a0.min(a);
            a1 = a1.max(a);
            p0 = p0.min(p);
            p1 = p1.max(p);
        }
        Some([a0, a1, p0, p1])
    }

    /// Narrows the next searches to a prior's window (`vp` the expected vanishing point,
    /// sign free; `w` the window's half-angle, radians), or widens them again (`None`).
    pub fn set_window(&mut self, window: Option<(&Vector3<f64>, f64)>) {
        self.prior = window.map(|(vp, w)| (vp.normalize(), w));
    }

    /// The agreement on the grid of `na` × `np` candidates `step` apart from (a0, p0) (`at`:
    /// a0, p0, step) into `self.grid`. With `regions` > 0 only where it can hold the grid's
    /// best: every other candidate first (a grid twice as coarse) on the strongest peaks,
    /// then the full grid on all the peaks within one coarse step of that coarse grid's
    /// `regions` best local maxima; the candidates not evaluated there are NaN, and so neither a maximum nor higher than one. Each pass's
    /// candidates are evaluated at once on `pool`'s threads.
    fn fill_grid(
        &mut self,
        at: [f64; 3],
        na: usize,
        np: usize,
        regions: usize,
        pool: Option<&ThreadPool>,
    ) {
        self.grid.clear();
        self.grid.resize(na * np, f64::NAN);
        let stride = if regions == 0 { 1 } else { 2 };
        // the rows interleaved, so that the threads' contiguous shares see alike candidates
        let parts = pool.map_or(1, |p| p.current_num_threads()).max(1);
        let rows = np.div_ceil(stride);
        self.cells.clear();
        for phase in 0..parts.min(rows) {
            for r in (phase..rows).step_by(parts) {
                let j = r * stride;
                self.cells
                    .extend((0..na).step_by(stride).map(|i| j * na + i));
            }
        }
        if regions == 0 {
            self.evaluate_cells(at, na, pool, false);
            return;
        }
        self.keep_strong_peaks();
        self.evaluate_cells(at, na, pool, true);
        self.grid_maxima(na, np, 2);
        self.starts.truncate(regions);
        // the coarse grid's values were read on the strong peaks alone: all read again
        self.grid.fill(f64::NAN);
        self.cells.clear();
        for k in 0..self.starts.len() {
            let (_, ci, cj) = self.starts[k];
            let (ci, cj) = (ci as usize, cj as usize);
            for j in cj.saturating_sub(2)..(cj + 3).min(np) {
                for i in ci.saturating_sub(2)..(ci + 3).min(na) {
                    if self.grid[j * na + i].is_nan() {
                        // queued (no longer NaN, so queued once)
                        self.grid[j * na + i] = -1.0;
                        self.cells.push(j * na + i);
                    }
                }
            }
        }
        self.evaluate_cells(at, na, pool, false);
    }

    /// The agreement at each grid cell in `self.cells` (`at`: the grid's a0, p0 and step;
    /// `na` its columns) into `self.grid`, on the strong peaks alone with `strong`.
    fn evaluate_cells(&mut self, at: [f64; 3], na: usize, pool: Option<&ThreadPool>, strong: bool) {
        let [a0, p0, step] = at;
        self.cand.clear();
        self.cand.extend(
            self.cells
                .iter()
                .map(|&c| [a0 + (c % na) as f64 * step, p0 + (c / na) as f64 * step]),
        );
        self.agreements(pool, strong);
        for (&c, &v) in self.cells.iter().zip(&self.vals) {
            self.grid[c] = v;
        }
    }

    /// The local maxima (agreement, column, row) of the `na` × `np` grid read every
    /// `stride`-th point, into `self.starts`, best first.
    fn grid_maxima(&mut self, na: usize, np: usize, stride: usize) {
        self.starts.clear();
        for j in (0..np).step_by(stride) {
            for i in (0..na).step_by(stride) {
                let e = self.grid[j * na + i];
                if e > 0.0 && !self.higher_near(i, j, na, np, stride as i64, e) {
                    self.starts.push((e, i as f64, j as f64));
                }
            }
        }
        self.starts.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
    }

    /// Whether a grid neighbour `reach` cells from (i, j) (one of the eight directions) is
    /// higher than `e`.
    fn higher_near(&self, i: usize, j: usize, na: usize, np: usize, reach: i64, e: f64) -> bool {
        NEIGHBOURS.iter().any(|&(di, dj)| {
            let (x, y) = (i as i64 + di as i64 * reach, j as i64 + dj as i64 * reach);
            x >= 0
                && y >= 0
                && (x as usize) < na
                && (y as usize) < np
                && self.grid[y as usize * na + x as usize] > e
        })
    }

    /// A grid point (agreement, along, below) climbed by halving steps from `step` / 2
    /// down to 1 px; each step's eight neighbours evaluated at once on `pool`'s threads.
    fn refine(
        &mut self,
        mut here: (f64, f64, f64),
        step: f64,
        pool: Option<&ThreadPool>,
    ) -> (f64, f64, f64) {
        let mut st = 0.5 * step;
        while st >= 1.0 {
            let (_, ca, cp) = here;
            self.cand.clear();
            self.cand.extend(
                NEIGHBOURS
                    .iter()
                    .map(|&(da, dp)| [ca + da * st, cp + dp * st]),
            );
            self.agreements(pool, false);
            for (c, &e) in self.cand.iter().zip(&self.vals) {
                if e > here.0 {
                    here = (e, c[0], c[1]);
                }
            }
            st *= 0.5;
        }
        here
    }

    /// The agreement at the summit nearest a vanishing direction `dir` (sign free), on the
    /// last image's peaks as the search read them: climbed from its point in the virtual
    /// image by the search's own halving steps, again while the climb moves (at most
    /// `CLIMB_ROUNDS` rounds). Asks, after [`Self::find`], whether a vanishing point known
    /// from elsewhere (the labels') would have beaten the search's answer
    /// ([`super::StripsResult::agreement`]): higher and elsewhere, the search missed it;
    /// lower, or the search's own summit, the measure prefers the search's. Returns the
    /// agreement and the summit's distance from the search's answer (virtual image pixels;
    /// infinite without one). `None` before the first image, when the last image gave too
    /// few peaks (its points may then not have been read), or when the direction has no
    /// point in the virtual image. Leaves [`Self::last`] as it was.
    pub fn agreement_near(&mut self, dir: &Vector3<f64>) -> Option<(f64, f64)> {
        if self.last.peaks < 4 {
            return None;
        }
        let d = if dir.z < 0.0 { *dir } else { -*dir };
        let [mut a, mut p] = self.to_virtual(&d)?;
        let last = self.last;
        // the same points as the search's: the same peaks, at least four of them
        self.read_peaks(None);
        let mut here = (self.agreement(a, p), a, p);
        for _ in 0..CLIMB_ROUNDS {
            here = self.refine(here, SEARCH_STEP_PX, None);
            if (here.1, here.2) == (a, p) {
                break;
            }
            (a, p) = (here.1, here.2);
        }
        self.last = last;
        let away = last
            .vanishing_px
            .map_or(f64::INFINITY, |[va, vp]| (here.1 - va).hypot(here.2 - vp));
        Some((here.0, away))
    }
}

/// The `na` × `np` candidates of a grid `step` apart over the box `bx` (along from, to,
/// below from, to), both its ends included.
fn grid_size(bx: &[f64; 4], step: f64) -> (usize, usize) {
    let [a0, a1, p0, p1] = *bx;
    let na = ((a1 - a0) / step).ceil() as usize + 1;
    let np = ((p1 - p0) / step).ceil() as usize + 1;
    (na, np)
}

/// The search's answer among the climbed `summits` (agreement, along, below): the highest,
/// or one within `reach` of it whose agreement times `strength(along, below)` (0..1) to the
/// `power` is larger. With power 0, or one summit, the highest (the first of equals);
/// `strength` is read only for summits that could win. `None` without summits.
fn pick_summit(
    summits: &[(f64, f64, f64)],
    power: f64,
    reach: f64,
    mut strength: impl FnMut(f64, f64) -> f64,
) -> Option<(f64, f64, f64)> {
    let top = summits
        .iter()
        .copied()
        .reduce(|b, x| if x.0 > b.0 { x } else { b })?;
    if power == 0.0 || summits.len() < 2 {
        return Some(top);
    }
    let mut best = (top, top.0 * strength(top.1, top.2).powf(power));
    for &x in summits {
        // a strength is at most 1: a summit no higher than the best score cannot win
        let near = (x.1 - top.1).hypot(x.2 - top.2) <= reach;
        if x == top || !near || x.0 <= best.1 {
            continue;
        }
        let score = x.0 * strength(x.1, x.2).powf(power);
        if score > best.1 {
            best = (x, score);
        }
    }
    Some(best.0)
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;
    use super::super::StripsOptions;
    use super::*;
    use nalgebra::Rotation3;

    /// Two climbs to one summit end within this many pixels of each other.
    const SAME_SUMMIT_TEST_PX: f64 = 3.0;

    #[test]
    fn the_agreement_near_a_point_climbs_to_its_summit_and_leaves_the_result() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let ray = Vector3::new(0.0, 0.0, -1.0);
        assert_eq!(s.agreement_near(&ray), None, "no image yet");
        let mut rows = Vec::new();
        let vp = s
            .find(&fld.points(), &mut rows)
            .unwrap()
            .expect("a vanishing point");
        let found = s.last();
        // from the answer and from 5 px beside it: the search's own summit
        for (da, dp) in [(0.0, 0.0), (5.0, -4.0)] {
            let [a, p] = found.vanishing_px.unwrap();
            let start = s.to_ray(a + da, p + dp);
            let (e, away) = s.agreement_near(&start).unwrap();
            assert!(away <= SAME_SUMMIT_TEST_PX, "{away} px from the answer");
            assert!((e / found.agreement - 1.0).abs() < 0.02, "{e} {found:?}");
        }
        assert_eq!(s.last(), found, "the result stays the search's");
        // the point of a direction 20° above the rows': a lower summit of its own
        let up = Rotation3::from_axis_angle(&Vector3::x_axis(), 20f64.to_radians()) * vp;
        let (e, away) = s.agreement_near(&up).unwrap();
        assert!(e < 0.5 * found.agreement, "{e} {found:?}");
        assert!(away > 50.0, "{away}");
        // the next image starts from its own peaks: the same answer again
        s.find(&fld.points(), &mut rows).unwrap();
        assert_eq!(s.last(), found);
    }

    #[test]
    fn the_coarse_grid_finds_the_full_grids_best_for_a_third_of_the_work() {
        let (m, fld) = weedy_field();
        let (mut s, vp, _) = detect(&fld, &m);
        vp.expect("a vanishing point");
        // the search's peaks and window
        s.read_peaks(None);
        let bx = s.window().unwrap();
        let (na, np) = grid_size(&bx, SEARCH_STEP_PX);
        let mut best = |regions: usize| {
            let before = s.last.evaluated;
            s.fill_grid([bx[0], bx[2], SEARCH_STEP_PX], na, np, regions, None);
            s.grid_maxima(na, np, 1);
            (s.starts[0], s.last.evaluated - before)
        };
        let (full, n_full) = best(0);
        let (coarse, n) = best(SEARCH_REGIONS);
        assert_eq!(coarse, full);
        assert!(3 * n < n_full, "{n} candidates evaluated against {n_full}");
    }

    #[test]
    fn the_search_on_threads_is_the_search_on_one() {
        let (m, fld) = weedy_field();
        let pts = fld.points();
        let mut rows = Vec::new();
        let mut one = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let want = one
            .find(&pts, &mut rows)
            .unwrap()
            .expect("a vanishing point");
        let (want_rows, want_last) = (rows.clone(), one.last());
        let want_grid = one.grid.clone();
        for n in [2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
            let got = s.find_on(&pts, &mut rows, Some(&pool)).unwrap();
            assert_eq!(got, Some(want), "{n} threads");
            assert_eq!(rows, want_rows, "{n} threads");
            assert_eq!(s.last(), want_last, "{n} threads");
            // every candidate the same to the bit, the unevaluated ones too
            let bits = |g: &[f64]| g.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&s.grid), bits(&want_grid), "{n} threads");
        }
    }

    #[test]
    fn the_comb_breaks_only_near_ties_and_only_nearby() {
        // (agreement, along, below); the comb's strength by position
        let summits = [(1.0, 0.0, 0.0), (0.95, 30.0, -40.0), (0.97, 300.0, 0.0)];
        let comb = |a: f64, _p: f64| if a == 0.0 { 0.5 } else { 1.0 };
        let pick = |power, reach| pick_summit(&summits, power, reach, comb).unwrap();
        // the agreement alone: the highest
        assert_eq!(pick(0.0, 100.0), summits[0]);
        // 0.95 × 1 > 1 × 0.5^0.25 = 0.84: the nearby summit with the stronger comb wins
        assert_eq!(pick(SEARCH_COMB_POWER, SEARCH_COMB_REACH_PX), summits[1]);
        // out of reach it cannot, however strong its comb
        assert_eq!(pick(SEARCH_COMB_POWER, 40.0), summits[0]);
        // a summit far below the highest never wins: 0.5 × 1 < 1 × 0.5^0.25
        let low = [(1.0, 0.0, 0.0), (0.5, 10.0, 0.0)];
        assert_eq!(pick_summit(&low, 0.25, 100.0, comb).unwrap(), low[0]);
        // its comb is not even read: a strength is at most 1
        let mut read = vec![];
        pick_summit(&low, 0.25, 100.0, |a, p| {
            read.push((a, p));
            comb(a, p)
        });
        assert_eq!(read, [(0.0, 0.0)]);
        // one summit, or none
        assert_eq!(pick_summit(&low[..1], 0.25, 100.0, comb), Some(low[0]));
        assert_eq!(pick_summit(&[], 0.25, 100.0, comb), None);
    }

    #[test]
    fn a_window_narrows_the_search_and_a_window_beside_the_rows_finds_nothing() {
        let (m, weedy) = weedy_field();
        let search = |window: Option<(&Vector3<f64>, f64)>| {
            let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
            s.set_window(window);
            let mut rows = Vec::new();
            let vp = s
                .find(&weedy.points(), &mut rows)
                .unwrap()
                .expect("a vanishing point");
            (vp, s.last().evaluated)
        };
        let (vp_full, n_full) = search(None);
        let w = 2f64.to_radians();
        let (vp, n) = search(Some((&vp_full, w)));
        // the same summit, found on a finer grid: within the last step's pixel
        assert!(vp.dot(&vp_full).abs().min(1.0).acos() < 1.5 / 300.0);
        assert!(5 * n < n_full, "{n} candidates evaluated against {n_full}");
        // a window 8° to the side: the agreement rises towards its edge, so no answer
        let side = m.robot_from_camera().inverse()
            * (Rotation3::from_axis_angle(&Vector3::z_axis(), 13f64.to_radians()) * Vector3::x());
        let fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        s.set_window(Some((&side, w)));
        let mut rows = Vec::new();
        let got = s.find(&fld.points(), &mut rows).unwrap();
        assert!(
            got.is_none() && rows.is_empty(),
            "{got:?}, {} rows",
            rows.len()
        );
        // widened again: the full search's answer on the same points
        s.set_window(None);
        let again = s.find(&fld.points(), &mut rows).unwrap();
        let full = StripsRows::new(StripsOptions::default(), 15.0, &m)
            .unwrap()
            .find(&fld.points(), &mut rows)
            .unwrap()
            .expect("a vanishing point");
        assert!(again.is_some_and(|v| v.dot(&full).abs() > 1.0 - 1e-9));
        assert!(full.dot(&vp_full).abs().min(1.0).acos() < 2.5 / 300.0);
    }
}
