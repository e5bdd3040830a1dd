//! The field: parallel rows of identical four-leaved plants on flat ground, plus weeds.
//!
//! Owns the world model the renderer samples: rows along world +X at y = i·spacing, a plant
//! every `plant_distance_m` along each (plant k of row i nominally at (k·distance, i·spacing)),
//! each plant's position error along and across its row (Gaussian, truncated at ±3σ so that a
//! lookup only needs a bounded window), and weeds (the same plant at uniformly random positions
//! around the camera, in a bucket grid). [`Field::plant_at`] answers "which plant covers this
//! ground point" in constant time. A curved field ([`SynthOptions::curvature_per_m`]) is the
//! same lattice bent into concentric circles ([`Bend`]): a world point is mapped to its arc
//! length and lateral position before the lookup.

use super::options::SynthOptions;
use super::rng::Rng;

/// Position errors are truncated at this many standard deviations.
const TRUNCATE_SD: f64 = 3.0;

/// ⌊v⌋ as an integer without a libm call (v within ±2^62).
#[inline]
pub(crate) fn floor_i(v: f64) -> i64 {
    let t = v as i64;
    t - ((t as f64) > v) as i64
}

/// ⌈v⌉ as an integer without a libm call (v within ±2^62).
#[inline]
pub(crate) fn ceil_i(v: f64) -> i64 {
    let t = v as i64;
    t + ((t as f64) < v) as i64
}

/// The plant model: four elliptic leaves around the stem, at 45° to the row, identical for
/// every plant (no scaling, no rotation, as in the paper).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantShape {
    /// Half the leaf length (semi-major axis), metres.
    half_length: f64,
    /// Half the leaf width (semi-minor axis), metres.
    half_width: f64,
}

impl PlantShape {
    pub fn new(leaf_length_m: f64, leaf_width_m: f64) -> Self {
        PlantShape {
            half_length: leaf_length_m / 2.0,
            half_width: leaf_width_m / 2.0,
        }
    }

    /// Largest distance of any leaf point from the stem, metres (the leaf length).
    #[inline]
    pub fn reach(&self) -> f64 {
        2.0 * self.half_length
    }

    /// Whether ground offset (dx, dy) from the stem lies on a leaf (or the stem). Returns the elliptic
    /// radius in [0, 1] of the point within its leaf (0 on the leaf's centre, 1 on its edge).
    #[inline]
    pub fn leaf_at(&self, dx: f64, dy: f64) -> Option<f64> {
        let reach = self.reach();
        if dx.abs() > reach || dy.abs() > reach {
            return None;
        }
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let u = (dx + dy) * s;
        let v = (dy - dx) * s;
        let (a, b) = (self.half_length, self.half_width);
        let e1 = ((u.abs() - a) / a).powi(2) + (v / b).powi(2);
        let e2 = ((v.abs() - a) / a).powi(2) + (u / b).powi(2);
        // the stem: a disc as wide as a leaf
        let e0 = (dx * dx + dy * dy) / (b * b);
        let e = e1.min(e2).min(e0);
        (e <= 1.0).then_some(e)
    }
}

/// Weeds bucketed in a uniform grid; each weed is listed in every cell its reach overlaps,
/// so a lookup reads one cell.
#[derive(Debug, Clone, PartialEq)]
struct WeedGrid {
    origin: [f64; 2],
    cell: f64,
    nx: usize,
    ny: usize,
    /// CSR: weeds of cell (ix, iy) are `items[start[iy*nx+ix] .. start[iy*nx+ix+1]]`.
    start: Vec<u32>,
    items: Vec<[f64; 2]>,
}

impl WeedGrid {
    fn new(weeds: &[[f64; 2]], centre: [f64; 2], half: f64, reach: f64) -> Self {
        let origin = [centre[0] - half - reach, centre[1] - half - reach];
        let span = 2.0 * (half + reach);
        let cell = (2.0 * reach).max(span / 1024.0);
        let n = ((span / cell).ceil() as usize).max(1);
        let (nx, ny) = (n, n);
        let cells_of = |p: &[f64; 2]| {
            let lo =
                |v: f64, o: f64| (((v - reach - o) / cell).floor().max(0.0) as usize).min(n - 1);
            let hi =
                |v: f64, o: f64| (((v + reach - o) / cell).floor().max(0.0) as usize).min(n - 1);
            (
                lo(p[0], origin[0])..=hi(p[0], origin[0]),
                lo(p[1], origin[1])..=hi(p[1], origin[1]),
            )
        };
        let mut count = vec![0u32; nx * ny + 1];
        for p in weeds {
            let (xs, ys) = cells_of(p);
            for iy in ys {
                for ix in xs.clone() {
                    count[iy * nx + ix + 1] += 1;
                }
            }
        }
        for i in 1..count.len() {
            count[i] += count[i - 1];
        }
        let start = count;
        let mut fill = start.clone();
        let mut items = vec![[0.0; 2]; start[nx * ny] as usize];
        for p in weeds {
            let (xs, ys) = cells_of(p);
            for iy in ys {
                for ix in xs.clone() {
                    let slot = &mut fill[iy * nx + ix];
                    items[*slot as usize] = *p;
                    *slot += 1;
                }
            }
        }
        WeedGrid {
            origin,
            cell,
            nx,
            ny,
            start,
            items,
        }
    }

    /// True when no weed reaches into the rectangle (checks at most 16 cells, else says false).
    #[inline]
    fn is_bare(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> bool {
        if self.items.is_empty() {
            return true;
        }
        let span_x = self.cell * self.nx as f64;
        let span_y = self.cell * self.ny as f64;
        let (ax0, ax1) = (x0 - self.origin[0], x1 - self.origin[0]);
        let (ay0, ay1) = (y0 - self.origin[1], y1 - self.origin[1]);
        if ax1 < 0.0 || ay1 < 0.0 || ax0 >= span_x || ay0 >= span_y {
            return true;
        }
        let inv = 1.0 / self.cell;
        let cx0 = floor_i(ax0 * inv).max(0) as usize;
        let cx1 = (floor_i(ax1 * inv).max(0) as usize).min(self.nx - 1);
        let cy0 = floor_i(ay0 * inv).max(0) as usize;
        let cy1 = (floor_i(ay1 * inv).max(0) as usize).min(self.ny - 1);
        if (cx1 - cx0 + 1) * (cy1 - cy0 + 1) > 16 {
            return false;
        }
        (cy0..=cy1).all(|cy| {
            (cx0..=cx1).all(|cx| {
                let i = cy * self.nx + cx;
                self.start[i] == self.start[i + 1]
            })
        })
    }

    #[inline]
    fn candidates(&self, x: f64, y: f64) -> &[[f64; 2]] {
        if self.items.is_empty() {
            return &[];
        }
        let fx = (x - self.origin[0]) / self.cell;
        let fy = (y - self.origin[1]) / self.cell;
        if !(fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64) {
            return &[];
        }
        let i = fy as usize * self.nx + fx as usize;
        &self.items[self.start[i] as usize..self.start[i + 1] as usize]
    }
}

/// The bend of a curved field: world (x, y) ↔ field (u, v), where `u` is the arc length along
/// row 0 and `v` the position across the rows (the straight field's coordinates). The rows are
/// circles about the centre (x0, r), r = 1/curvature (signed: positive to the left); at
/// x = x0 they run along +X, so there the field and the world agree to first order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bend {
    x0: f64,
    r: f64,
    abs_r: f64,
    sign: f64,
}

impl Bend {
    /// The bend of curvature `curvature_per_m` (not 0) whose rows run along +X at `x0`.
    pub fn new(curvature_per_m: f64, x0: f64) -> Self {
        let r = 1.0 / curvature_per_m;
        Bend {
            x0,
            r,
            abs_r: r.abs(),
            sign: r.signum(),
        }
    }

    /// Field coordinates (arc length along row 0, across the rows) of world point (x, y).
    #[inline]
    pub fn to_field(self, x: f64, y: f64) -> (f64, f64) {
        let dx = x - self.x0;
        let dy = self.sign * (self.r - y);
        (
            self.x0 + self.abs_r * dx.atan2(dy),
            self.r - self.sign * dx.hypot(dy),
        )
    }

    /// World point of field coordinates (u, v).
    #[inline]
    pub fn to_world(self, u: f64, v: f64) -> (f64, f64) {
        let (s, c) = ((u - self.x0) / self.abs_r).sin_cos();
        let rho = self.sign * (self.r - v);
        (self.x0 + rho * s, self.r - self.sign * rho * c)
    }

    /// Distance of world point (x, y) from the centre.
    #[inline]
    fn radius(&self, x: f64, y: f64) -> f64 {
        (x - self.x0).hypot(self.r - y)
    }

    /// A box in field coordinates (u0, u1, v0, v1) holding the image of the world rectangle
    /// [x0, x1] × [y0, y1]; `None` when the rectangle holds the centre or reaches across the
    /// seam behind it (where the arc length jumps).
    fn field_box(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> Option<(f64, f64, f64, f64)> {
        let beyond = if self.sign > 0.0 {
            y1 >= self.r
        } else {
            y0 <= self.r
        };
        if beyond && x0 <= self.x0 && x1 >= self.x0 {
            return None;
        }
        // a convex set clear of the centre and the seam: its angles are extreme at corners,
        // its largest radius at a corner, its smallest at the point nearest the centre
        let (mut u0, mut u1, mut rmax) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for (x, y) in [(x0, y0), (x0, y1), (x1, y0), (x1, y1)] {
            let u = self.to_field(x, y).0;
            u0 = u0.min(u);
            u1 = u1.max(u);
            rmax = rmax.max(self.radius(x, y));
        }
        let rmin = self.radius(self.x0.clamp(x0, x1), self.r.clamp(y0, y1));
        let (v0, v1) = if self.sign > 0.0 {
            (self.r - rmax, self.r - rmin)
        } else {
            (self.r + rmin, self.r + rmax)
        };
        Some((u0, u1, v0, v1))
    }
}

/// The crop field: rows, plants with their position errors, and weeds.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    shape: PlantShape,
    row_spacing: f64,
    plant_distance: f64,
    inv_spacing: f64,
    inv_distance: f64,
    /// Row indices i in `row_min..=row_max` (rows at y = i·row_spacing).
    row_min: i64,
    row_max: i64,
    /// Plant indices k in `k_min..=k_max` (plants nominally at x = k·plant_distance).
    k_min: i64,
    k_max: i64,
    /// Per plant (row-major: row, then k) position error (along, across), metres; empty
    /// when there is no position noise.
    offsets: Vec<[f32; 2]>,
    /// Lookup half-windows: leaf reach plus the largest position error.
    window_x: f64,
    window_y: f64,
    weeds: WeedGrid,
    /// Weed stems (x, y), metres.
    weed_list: Vec<[f64; 2]>,
    /// The bend of a curved field (`None`: straight rows).
    bend: Option<Bend>,
    /// Plant indices of the empty stretch (no plant of any row), inclusive; empty range
    /// (1, 0) when there is none.
    gap: (i64, i64),
}

/// Which plant, if any, covers a ground point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cover {
    Soil,
    /// A leaf; `edge` is the elliptic radius in [0, 1] within the leaf.
    Plant {
        edge: f64,
    },
}

impl Field {
    /// Builds the field of `opts`, drawing the position errors and the weeds from `seed`.
    /// `camera_xy` is the camera's ground position (the weeds are scattered around it).
    pub fn new(opts: &SynthOptions, seed: u64, camera_xy: [f64; 2]) -> Self {
        let shape = PlantShape::new(opts.leaf_length_m, opts.leaf_width_m);
        let s = opts.row_spacing_m;
        let pd = opts.plant_distance_m;
        let bend =
            (opts.curvature_per_m != 0.0).then(|| Bend::new(opts.curvature_per_m, opts.along_m));
        // a curved field keeps its rows clear of the centre
        let half_width = match bend {
            Some(b) => opts.field_half_width_m.min(0.8 * b.abs_r),
            None => opts.field_half_width_m,
        };
        let row_min = (-half_width / s).ceil() as i64;
        let row_max = (half_width / s).floor() as i64;
        let k_min = (-opts.field_half_length_m / pd).ceil() as i64;
        let mut k_max = (opts.field_half_length_m / pd).floor() as i64;
        if let Some(end) = opts.rows_end_m {
            k_max = k_max.min((end / pd).floor() as i64).max(k_min - 1);
        }
        let gap = match opts.gap_m {
            Some([a, b]) => ((a / pd).ceil() as i64, (b / pd).floor() as i64),
            None => (1, 0),
        };
        let noisy = opts.along_sd_m > 0.0 || opts.across_sd_m > 0.0;
        let mut offsets = Vec::new();
        let (mut max_x, mut max_y) = (0.0f64, 0.0f64);
        if noisy {
            let n = ((row_max - row_min + 1) * (k_max - k_min + 1)) as usize;
            offsets.reserve_exact(n);
            let mut rng = Rng::stream(seed, 1);
            let (sx, sy) = (opts.along_sd_m, opts.across_sd_m);
            for _ in 0..n {
                // A pair of standard normals, redrawn until both lie within the truncation.
                let (zx, zy) = loop {
                    let (a, b) = rng.normal_pair();
                    if a.abs() <= TRUNCATE_SD && b.abs() <= TRUNCATE_SD {
                        break (a, b);
                    }
                };
                let (ox, oy) = ((zx * sx) as f32, (zy * sy) as f32);
                max_x = max_x.max((ox as f64).abs());
                max_y = max_y.max((oy as f64).abs());
                offsets.push([ox, oy]);
            }
        }
        let reach = shape.reach();
        let mut rng = Rng::stream(seed, 2);
        let half = opts.weed_area_half_m;
        let weeds: Vec<[f64; 2]> = (0..opts.weeds)
            .map(|_| {
                [
                    camera_xy[0] + rng.range(-half, half),
                    camera_xy[1] + rng.range(-half, half),
                ]
            })
            .collect();
        Field {
            shape,
            row_spacing: s,
            plant_distance: pd,
            inv_spacing: 1.0 / s,
            inv_distance: 1.0 / pd,
            row_min,
            row_max,
            k_min,
            k_max,
            offsets,
            window_x: reach + max_x + 1e-9,
            window_y: reach + max_y + 1e-9,
            weeds: WeedGrid::new(&weeds, camera_xy, half, reach),
            weed_list: weeds,
            bend,
            gap,
        }
    }

    /// Indices of the rows, lowest to highest; row i runs along y = i·row_spacing.
    pub fn rows(&self) -> std::ops::RangeInclusive<i64> {
        self.row_min..=self.row_max
    }

    /// Indices of the plants along each row; plant k sits nominally at x = k·plant_distance.
    pub fn plant_indices(&self) -> std::ops::RangeInclusive<i64> {
        self.k_min..=self.k_max
    }

    pub fn row_spacing(&self) -> f64 {
        self.row_spacing
    }

    pub fn plant_distance(&self) -> f64 {
        self.plant_distance
    }

    pub fn shape(&self) -> &PlantShape {
        &self.shape
    }

    /// Stems (x, y) of the weeds, metres.
    pub fn weeds(&self) -> &[[f64; 2]] {
        &self.weed_list
    }

    /// Whether plant index `k` lies in the empty stretch.
    #[inline]
    fn in_gap(&self, k: i64) -> bool {
        k >= self.gap.0 && k <= self.gap.1
    }

    /// Whether some plant grows within `reach` metres along the rows of arc position `u`
    /// (the empty stretch and the rows' ends considered, position errors not).
    pub fn crop_within(&self, u: f64, reach: f64) -> bool {
        let lo = ceil_i((u - reach) * self.inv_distance).max(self.k_min);
        let hi = floor_i((u + reach) * self.inv_distance).min(self.k_max);
        lo <= hi && !(lo >= self.gap.0 && hi <= self.gap.1)
    }

    /// Arc position along the rows where the last plant grows, metres.
    pub fn rows_end(&self) -> f64 {
        self.k_max as f64 * self.plant_distance
    }

    /// The bend of a curved field (`None`: straight rows).
    pub fn bend(&self) -> Option<&Bend> {
        self.bend.as_ref()
    }

    /// Ground position (x, y) of plant k of row i, position error included.
    pub fn plant_position(&self, row: i64, k: i64) -> [f64; 2] {
        let [u, v] = self.stem_field(row, k);
        match &self.bend {
            Some(b) => b.to_world(u, v).into(),
            None => [u, v],
        }
    }

    /// Field position (u, v) of plant k of row i (the straight field's).
    #[inline]
    fn stem_field(&self, row: i64, k: i64) -> [f64; 2] {
        let (ox, oy) = self.offset(row, k);
        [
            k as f64 * self.plant_distance + ox,
            row as f64 * self.row_spacing + oy,
        ]
    }

    /// The query (x, y, reach) in field coordinates: the reach widened where the bend
    /// stretches arc length (nearer the centre than row 0).
    #[inline]
    fn field_query(&self, x: f64, y: f64, reach: f64) -> (f64, f64, f64) {
        match &self.bend {
            None => (x, y, reach),
            Some(b) => {
                let (u, v) = b.to_field(x, y);
                let rho = b.radius(x, y);
                let stretch = b.abs_r / (rho - reach).max(1e-3 * b.abs_r);
                (u, v, reach * stretch.max(1.0))
            }
        }
    }

    #[inline]
    fn offset(&self, row: i64, k: i64) -> (f64, f64) {
        if self.offsets.is_empty() {
            return (0.0, 0.0);
        }
        let per_row = (self.k_max - self.k_min + 1) as usize;
        let o = self.offsets[(row - self.row_min) as usize * per_row + (k - self.k_min) as usize];
        (o[0] as f64, o[1] as f64)
    }

    /// Whether any plant's stem may lie within `reach` metres of (x, y) along each axis
    /// (the window [`plants_near`](Self::plants_near) would visit is not empty).
    pub fn any_plant_near(&self, x: f64, y: f64, reach: f64) -> bool {
        let (x, y, reach) = self.field_query(x, y, reach);
        let (lo, hi) = self.window(x, y, reach);
        lo[0] <= hi[0] && lo[1] <= hi[1]
    }

    /// The (row, plant) index window of [`plants_near`](Self::plants_near): lowest, highest.
    fn window(&self, x: f64, y: f64, reach: f64) -> ([i64; 2], [i64; 2]) {
        let (ex, ey) = (
            self.window_x - self.shape.reach(),
            self.window_y - self.shape.reach(),
        );
        (
            [
                ceil_i((y - reach - ey) * self.inv_spacing).max(self.row_min),
                ceil_i((x - reach - ex) * self.inv_distance).max(self.k_min),
            ],
            [
                floor_i((y + reach + ey) * self.inv_spacing).min(self.row_max),
                floor_i((x + reach + ex) * self.inv_distance).min(self.k_max),
            ],
        )
    }

    /// Calls `f(row, k, stem)` for every plant whose stem (position error included) may lie
    /// within `reach` metres of (x, y) along each axis: another renderer's leaf reach.
    pub fn plants_near(&self, x: f64, y: f64, reach: f64, mut f: impl FnMut(i64, i64, [f64; 2])) {
        let (x, y, reach) = self.field_query(x, y, reach);
        let (lo, hi) = self.window(x, y, reach);
        for i in lo[0]..=hi[0] {
            for k in lo[1]..=hi[1] {
                if self.in_gap(k) {
                    continue;
                }
                f(i, k, self.plant_position(i, k));
            }
        }
    }

    /// True when no plant or weed reaches into the ground rectangle [x0, x1] × [y0, y1].
    /// (Conservative: may say false for a bare rectangle, never true for a covered one.)
    #[inline]
    pub fn is_bare(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> bool {
        let rows_bare = match &self.bend {
            None => self.rows_bare(x0, x1, y0, y1),
            Some(b) => match b.field_box(x0, x1, y0, y1) {
                Some((u0, u1, v0, v1)) => self.rows_bare(u0, u1, v0, v1),
                None => false,
            },
        };
        rows_bare && self.weeds.is_bare(x0, x1, y0, y1)
    }

    /// True when no plant reaches into the field rectangle [u0, u1] × [v0, v1].
    #[inline]
    fn rows_bare(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> bool {
        let i_lo = ceil_i((y0 - self.window_y) * self.inv_spacing).max(self.row_min);
        let i_hi = floor_i((y1 + self.window_y) * self.inv_spacing).min(self.row_max);
        if i_lo <= i_hi {
            let k_lo = ceil_i((x0 - self.window_x) * self.inv_distance).max(self.k_min);
            let k_hi = floor_i((x1 + self.window_x) * self.inv_distance).min(self.k_max);
            if k_lo <= k_hi && !(k_lo >= self.gap.0 && k_hi <= self.gap.1) {
                return false;
            }
        }
        true
    }

    /// What covers ground point (x, y).
    #[inline]
    pub fn cover_at(&self, x: f64, y: f64) -> Cover {
        let (u, v) = match &self.bend {
            Some(b) => b.to_field(x, y),
            None => (x, y),
        };
        if let Some(c) = self.plant_cover(u, v) {
            return c;
        }
        for w in self.weeds.candidates(x, y) {
            if let Some(edge) = self.shape.leaf_at(x - w[0], y - w[1]) {
                return Cover::Plant { edge };
            }
        }
        Cover::Soil
    }

    /// The plant covering field point (x, y), if any.
    #[inline]
    fn plant_cover(&self, x: f64, y: f64) -> Option<Cover> {
        let s = self.row_spacing;
        let pd = self.plant_distance;
        let i_lo = ceil_i((y - self.window_y) * self.inv_spacing).max(self.row_min);
        let i_hi = floor_i((y + self.window_y) * self.inv_spacing).min(self.row_max);
        if i_lo <= i_hi {
            let k_lo = ceil_i((x - self.window_x) * self.inv_distance).max(self.k_min);
            let k_hi = floor_i((x + self.window_x) * self.inv_distance).min(self.k_max);
            for i in i_lo..=i_hi {
                let yi = i as f64 * s;
                for k in k_lo..=k_hi {
                    if self.in_gap(k) {
                        continue;
                    }
                    let (ox, oy) = self.offset(i, k);
                    if let Some(edge) = self.shape.leaf_at(x - (k as f64 * pd + ox), y - (yi + oy))
                    {
                        return Some(Cover::Plant { edge });
                    }
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The bend maps field and world coordinates onto each other, keeps row 0's
        /// tangent along +X at x0 and puts row i on a circle of radius r − i·s about the
        /// centre; the box of a world rectangle holds the field images of its points.
        #[test]
        fn bend_round_trips_and_boxes_hold_their_points(
            k in prop_oneof![-0.2f64..-0.005, 0.005f64..0.2], x0 in -50.0f64..50.0,
            u in -20.0f64..20.0, v in -2.0f64..2.0, w in 0.01f64..1.0,
        ) {
            // arcs shorter than half a turn
            prop_assume!(u.abs() < 3.0 / k.abs());
            let b = Bend::new(k, x0);
            let (x, y) = b.to_world(x0 + u, v);
            let (u2, v2) = b.to_field(x, y);
            prop_assert!((u2 - x0 - u).abs() < 1e-9 && (v2 - v).abs() < 1e-9);
            prop_assert!(((x - x0).hypot(1.0 / k - y) - (1.0 / k - v).abs()).abs() < 1e-9);
            let (xa, ya) = b.to_world(x0 + 1e-4, 0.0);
            prop_assert!((ya / (xa - x0)).abs() < 1e-3);
            if let Some((u0, u1, v0, v1)) = b.field_box(x, x + w, y, y + w) {
                for (fx, fy) in [(0.5, 0.5), (0.0, 1.0), (0.3, 0.0), (1.0, 0.7)] {
                    let (pu, pv) = b.to_field(x + fx * w, y + fy * w);
                    prop_assert!(pu >= u0 - 1e-9 && pu <= u1 + 1e-9 && pv >= v0 - 1e-9 && pv <= v1 + 1e-9);
                }
            }
        }
    }

    #[test]
    fn curved_field_puts_the_stems_on_circles_and_finds_them() {
        let opts = SynthOptions {
            curvature_per_m: 0.05,
            along_m: 3.0,
            field_half_length_m: 20.0,
            field_half_width_m: 30.0,
            ..Default::default()
        };
        let f = Field::new(&opts, 1, [3.0, 0.0]);
        // rows kept clear of the centre 20 m to the left: |y| <= 16 m
        assert_eq!(f.rows(), -32..=32);
        for (i, k) in [(0, 20), (3, -40), (-5, 100)] {
            let p = f.plant_position(i, k);
            let r = (p[0] - 3.0).hypot(20.0 - p[1]);
            assert!((r - (20.0 - i as f64 * 0.5)).abs() < 1e-9, "{r}");
            assert!(matches!(f.cover_at(p[0], p[1]), Cover::Plant { .. }));
            assert!(!f.is_bare(p[0] - 0.01, p[0] + 0.01, p[1] - 0.01, p[1] + 0.01));
        }
        // 4 m ahead row 0 has bent 0.4 m to the left (row −1 to y ≈ −0.11): its straight
        // line is soil there
        let p = f.plant_position(0, 47);
        assert!(
            (p[0] - 7.0).abs() < 0.1 && (p[1] - 0.4).abs() < 0.02,
            "{p:?}"
        );
        assert!(matches!(f.cover_at(7.0, 0.0), Cover::Soil));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The windowed lookup agrees with checking every plant and weed of the field.
        #[test]
        fn lookup_matches_brute_force(
            seed in 0u64..1000, along in 0.0f64..0.05, across in 0.0f64..0.05,
            pd in 0.02f64..0.3, spacing in 0.1f64..0.8, weeds in 0usize..40,
            qx in -2.0f64..2.0, qy in -2.0f64..2.0,
        ) {
            let opts = SynthOptions {
                along_sd_m: along, across_sd_m: across, plant_distance_m: pd,
                row_spacing_m: spacing, weeds, weed_area_half_m: 1.5,
                field_half_length_m: 3.0, field_half_width_m: 3.0, ..Default::default()
            };
            let f = Field::new(&opts, seed, [0.1, -0.2]);
            let mut rng = super::Rng::new(seed);
            for _ in 0..200 {
                let (x, y) = (qx + rng.range(-0.3, 0.3), qy + rng.range(-0.3, 0.3));
                let mut brute = false;
                for i in f.rows() {
                    for k in f.plant_indices() {
                        let p = f.plant_position(i, k);
                        brute |= f.shape.leaf_at(x - p[0], y - p[1]).is_some();
                    }
                }
                for w in f.weeds() {
                    brute |= f.shape.leaf_at(x - w[0], y - w[1]).is_some();
                }
                let fast = matches!(f.cover_at(x, y), Cover::Plant { .. });
                prop_assert_eq!(fast, brute, "at ({}, {})", x, y);
                if brute {
                    let r = 0.01;
                    prop_assert!(!f.is_bare(x - r, x + r, y - r, y + r));
                }
            }
        }
    }

    #[test]
    fn plant_has_four_leaves_and_a_stem() {
        let p = PlantShape::new(0.04, 0.015);
        assert!(p.leaf_at(0.0, 0.0).is_some());
        let d = 0.02 * std::f64::consts::FRAC_1_SQRT_2;
        // leaf centres along the four diagonals
        for (sx, sy) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
            let e = p.leaf_at(sx * d, sy * d).unwrap();
            assert!(e < 1e-9);
        }
        // between the leaves (along the row axis, beyond the stem) is soil
        assert!(p.leaf_at(0.03, 0.0).is_none());
        assert!(p.leaf_at(0.0, -0.03).is_none());
        // beyond the tips
        assert!(p.leaf_at(0.03, 0.03).is_none());
    }

    #[test]
    fn plants_sit_on_rows_and_weeds_are_found() {
        let opts = SynthOptions {
            weeds: 50,
            weed_area_half_m: 2.0,
            ..Default::default()
        };
        let f = Field::new(&opts, 3, [0.0, 0.0]);
        // stem of plant 4 in row -2
        assert_eq!(f.cover_at(4.0 * 0.15, -1.0), Cover::Plant { edge: 0.0 });
        // half-way between plants and between rows: soil, unless a weed is there
        let weed = f.weeds.items[0];
        assert!(matches!(f.cover_at(weed[0], weed[1]), Cover::Plant { .. }));
        assert!(f.weeds.items.len() >= 50);
        // outside the field: no plants
        assert_eq!(f.cover_at(151.0, 0.0), Cover::Soil);
        assert_eq!(f.cover_at(0.0, 150.5), Cover::Soil);
    }

    #[test]
    fn position_noise_is_bounded_and_moves_plants() {
        let opts = SynthOptions {
            along_sd_m: 0.01,
            across_sd_m: 0.02,
            field_half_length_m: 10.0,
            field_half_width_m: 5.0,
            ..Default::default()
        };
        let f = Field::new(&opts, 9, [0.0, 0.0]);
        let mut sum_y2 = 0.0;
        let mut n = 0.0;
        for i in f.rows() {
            for k in f.plant_indices() {
                let p = f.plant_position(i, k);
                let (dx, dy) = (p[0] - k as f64 * 0.15, p[1] - i as f64 * 0.5);
                assert!(dx.abs() <= 0.03 + 1e-6 && dy.abs() <= 0.06 + 1e-6);
                sum_y2 += dy * dy;
                n += 1.0;
                // the displaced stem is found
                assert!(matches!(f.cover_at(p[0], p[1]), Cover::Plant { .. }));
            }
        }
        let sd = (sum_y2 / n).sqrt();
        assert!((sd - 0.02).abs() < 0.002, "{sd}");
    }
}
