//! Line charts as PNG, for the evaluation's figures (detection rate against plant distance).
//!
//! Owns a small chart renderer on the `image` crate: axes with ticks and numeric labels, a
//! title, one polyline with markers per series, and a legend. Enough for the paper's figures
//! 8 and 9 without a plotting dependency.

use super::font::{draw_text, text_width};
use image::{Rgb, RgbImage};

/// One series of (x, y) points.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub colour: [u8; 3],
    pub points: Vec<(f64, f64)>,
}

/// A line chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// Axis ranges; `None` fits the data.
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    pub series: Vec<Series>,
}

const W: u32 = 640;
const H: u32 = 420;
const LEFT: i64 = 70;
const RIGHT: i64 = 20;
const TOP: i64 = 40;
const BOTTOM: i64 = 60;

fn put(img: &mut RgbImage, x: i64, y: i64, c: [u8; 3]) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, Rgb(c));
    }
}

/// Draws a line with Bresenham's algorithm, `thick` pixels wide.
fn line(img: &mut RgbImage, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: [u8; 3], thick: i64) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        for ox in 0..thick {
            for oy in 0..thick {
                put(img, x + ox - thick / 2, y + oy - thick / 2, c);
            }
        }
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// "Nice" tick step for a range, about 5 ticks.
fn tick_step(span: f64) -> f64 {
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let n = raw / mag;
    let nice = if n < 1.5 {
        1.0
    } else if n < 3.5 {
        2.0
    } else if n < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    format!("{v:.decimals$}")
}

impl Chart {
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let pts = self.series.iter().flat_map(|s| s.points.iter());
        let fit = |get: fn(&(f64, f64)) -> f64| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in pts.clone() {
                let v = get(p);
                if v.is_finite() {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            if !lo.is_finite() {
                (0.0, 1.0)
            } else if hi - lo < 1e-12 {
                (lo - 0.5, hi + 0.5)
            } else {
                (lo, hi)
            }
        };
        (
            self.x_range.unwrap_or_else(|| fit(|p| p.0)),
            self.y_range.unwrap_or_else(|| fit(|p| p.1)),
        )
    }

    /// Renders the chart.
    pub fn render(&self) -> RgbImage {
        let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
        let ((x0, x1), (y0, y1)) = self.ranges();
        let (pw, ph) = (W as i64 - LEFT - RIGHT, H as i64 - TOP - BOTTOM);
        let sx = |x: f64| LEFT + ((x - x0) / (x1 - x0) * pw as f64).round() as i64;
        let sy = |y: f64| TOP + ph - ((y - y0) / (y1 - y0) * ph as f64).round() as i64;
        let black = [0, 0, 0];
        let grey = [220, 220, 220];
        // grid and ticks
        let xs = tick_step(x1 - x0);
        let mut t = (x0 / xs).ceil() * xs;
        while t <= x1 + 1e-9 * xs {
            let x = sx(t);
            line(&mut img, (x, TOP), (x, TOP + ph), grey, 1);
            let label = fmt_tick(t, xs);
            let w = text_width(&label, 1) as i64;
            draw_text(&label, x - w / 2, TOP + ph + 8, 1, |a, b| {
                put(&mut img, a, b, black)
            });
            t += xs;
        }
        let ys = tick_step(y1 - y0);
        let mut t = (y0 / ys).ceil() * ys;
        while t <= y1 + 1e-9 * ys {
            let y = sy(t);
            line(&mut img, (LEFT, y), (LEFT + pw, y), grey, 1);
            let label = fmt_tick(t, ys);
            let w = text_width(&label, 1) as i64;
            draw_text(&label, LEFT - 8 - w, y - 3, 1, |a, b| {
                put(&mut img, a, b, black)
            });
            t += ys;
        }
        line(&mut img, (LEFT, TOP + ph), (LEFT + pw, TOP + ph), black, 1);
        line(&mut img, (LEFT, TOP), (LEFT, TOP + ph), black, 1);
        // labels
        let tw = text_width(&self.title, 2) as i64;
        draw_text(&self.title, (W as i64 - tw) / 2, 10, 2, |a, b| {
            put(&mut img, a, b, black)
        });
        let lw = text_width(&self.x_label, 1) as i64;
        draw_text(
            &self.x_label,
            LEFT + (pw - lw) / 2,
            H as i64 - 22,
            1,
            |a, b| put(&mut img, a, b, black),
        );
        draw_text(&self.y_label, 4, TOP - 14, 1, |a, b| {
            put(&mut img, a, b, black)
        });
        // series
        for (i, s) in self.series.iter().enumerate() {
            let pts: Vec<(i64, i64)> = s
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .map(|&(x, y)| (sx(x), sy(y)))
                .collect();
            for w in pts.windows(2) {
                line(&mut img, w[0], w[1], s.colour, 2);
            }
            for &(x, y) in &pts {
                for dx in -3..=3 {
                    for dy in -3..=3 {
                        put(&mut img, x + dx, y + dy, s.colour);
                    }
                }
            }
            // legend, top right
            let ly = TOP + 8 + i as i64 * 14;
            let lx = LEFT + pw - 130;
            line(&mut img, (lx, ly + 3), (lx + 20, ly + 3), s.colour, 3);
            draw_text(&s.label, lx + 26, ly, 1, |a, b| put(&mut img, a, b, black));
        }
        img
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_are_drawn_where_their_points_are() {
        let chart = Chart {
            title: "T".into(),
            x_label: "X".into(),
            y_label: "Y".into(),
            x_range: Some((0.0, 1.0)),
            y_range: Some((0.0, 1.0)),
            series: vec![Series {
                label: "a".into(),
                colour: [255, 0, 0],
                points: vec![(0.0, 0.0), (1.0, 1.0)],
            }],
        };
        let img = chart.render();
        let (pw, ph) = (W as i64 - LEFT - RIGHT, H as i64 - TOP - BOTTOM);
        // the midpoint of the diagonal is red
        let (mx, my) = (LEFT + pw / 2, TOP + ph / 2);
        assert_eq!(img.get_pixel(mx as u32, my as u32).0, [255, 0, 0]);
        // the opposite corner of the plot area is not
        assert_ne!(
            img.get_pixel((LEFT + pw - 5) as u32, (TOP + ph - 5) as u32)
                .0,
            [255, 0, 0]
        );
    }

    #[test]
    fn ticks_are_nice() {
        assert_eq!(tick_step(1.0), 0.2);
        assert_eq!(tick_step(100.0), 20.0);
        assert_eq!(fmt_tick(0.4, 0.2), "0.4");
    }
}
