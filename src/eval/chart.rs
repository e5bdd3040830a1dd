//! Charts as images, for the evaluation's figures (detection rate against plant distance, the
//! vanishing point's error and the failures per method beside the paper's), drawn with
//! `plotters` on its bitmap backend: axes with ticks, labels and a grid (numbers, or one
//! category per tick), a title, each series as a line with markers, as markers alone, or as
//! reference points (hollow triangles: published figures to compare against), and a legend.
//!
//! Text is drawn with an embedded font (DejaVu Sans cut down to Latin-1 and a few symbols,
//! `fonts/`, licence beside it) through plotters' `ab_glyph` backend, so charts render the
//! same on a machine without any system font.

use image::RgbImage;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::sync::OnceLock;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kind {
    /// A line through the points, each marked by a filled circle.
    #[default]
    Line,
    /// Filled circles only (points of different categories are not joined).
    Markers,
    /// Reference values (e.g. a paper's): hollow triangles, no line.
    Reference,
}

/// One series of (x, y) points.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub colour: [u8; 3],
    pub points: Vec<(f64, f64)>,
    pub kind: Kind,
}

/// A line chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// Axis ranges; `None` fits the data. The legend sits in the lower right corner, or in
    /// the upper right with categories: leave it room there.
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Names of the categories at x = 0, 1, 2, … (the x axis then shows these instead of
    /// numbers, and spans −0.5 to n − 0.5); empty for a numeric x axis.
    pub x_categories: Vec<String>,
    pub series: Vec<Series>,
}

/// Errors drawing a chart.
#[derive(Debug, thiserror::Error)]
pub enum ChartError {
    #[error("the embedded chart font is not a usable TrueType font: {0}")]
    Font(String),
    #[error("drawing the chart {title:?}: {problem}")]
    Draw { title: String, problem: String },
}

/// Size of a rendered chart, pixels.
pub const SIZE: (u32, u32) = (800, 520);
const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("fonts/DejaVuSans-subset.ttf");

/// Registers the embedded font with plotters once.
fn font() -> Result<(), ChartError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
                .map_err(|_| "ab_glyph could not parse it".to_string())
        })
        .clone()
        .map_err(ChartError::Font)
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
        let x = if self.x_categories.is_empty() {
            self.x_range.unwrap_or_else(|| fit(|p| p.0))
        } else {
            (-0.5, self.x_categories.len() as f64 - 0.5)
        };
        (x, self.y_range.unwrap_or_else(|| fit(|p| p.1)))
    }

    /// The x axis' tick label at `x`: the number, or the category at an integer position.
    fn x_tick(&self, x: f64) -> String {
        if self.x_categories.is_empty() {
            return format!("{x}");
        }
        let i = x.round();
        if (x - i).abs() > 1e-6 || i < 0.0 {
            return String::new();
        }
        self.x_categories
            .get(i as usize)
            .cloned()
            .unwrap_or_default()
    }

    /// Renders the chart.
    pub fn render(&self) -> Result<RgbImage, ChartError> {
        font()?;
        let (w, h) = SIZE;
        let mut buf = vec![0u8; (w * h * 3) as usize];
        self.draw(&mut buf).map_err(|problem| ChartError::Draw {
            title: self.title.clone(),
            problem,
        })?;
        Ok(RgbImage::from_raw(w, h, buf).expect("the buffer is w × h × 3"))
    }

    fn draw(&self, buf: &mut [u8]) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        let ((x0, x1), (y0, y1)) = self.ranges();
        // A little room around the data so that markers on the edges show whole (categories
        // have their room already).
        let mx = if self.x_categories.is_empty() {
            (x1 - x0) * 0.03
        } else {
            0.0
        };
        let my = (y1 - y0) * 0.03;
        let root = BitMapBackend::with_buffer(buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(e)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, (FONT, 24))
            .margin(14)
            .x_label_area_size(50)
            .y_label_area_size(64)
            .build_cartesian_2d(x0 - mx..x1 + mx, y0 - my..y1 + my)
            .map_err(e)?;
        let x_tick = |x: &f64| self.x_tick(*x);
        let mut mesh = chart.configure_mesh();
        if !self.x_categories.is_empty() {
            // One tick per category (plotters picks round numbers: ask for the half steps too,
            // and label only the integers).
            mesh.x_labels(2 * self.x_categories.len() + 1)
                .disable_x_mesh();
        }
        mesh.x_label_formatter(&x_tick)
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 17))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()
            .map_err(e)?;
        for s in &self.series {
            let colour = RGBColor(s.colour[0], s.colour[1], s.colour[2]);
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            match s.kind {
                Kind::Line => {
                    chart
                        .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                        .map_err(e)?
                        .label(&s.label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 22, y)], colour.stroke_width(3))
                        });
                    chart
                        .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, colour.filled())))
                        .map_err(e)?;
                }
                Kind::Markers => {
                    chart
                        .draw_series(pts.into_iter().map(|p| Circle::new(p, 6, colour.filled())))
                        .map_err(e)?
                        .label(&s.label)
                        .legend(move |(x, y)| Circle::new((x + 11, y), 6, colour.filled()));
                }
                Kind::Reference => {
                    let stroke = colour.stroke_width(2);
                    // A hollow triangle around the point, in pixels.
                    let outline = vec![(0, -10), (9, 6), (-9, 6), (0, -10)];
                    let legend_outline = outline.clone();
                    chart
                        .draw_series(pts.into_iter().map(|p| {
                            EmptyElement::at(p) + PathElement::new(outline.clone(), stroke)
                        }))
                        .map_err(e)?
                        .label(&s.label)
                        .legend(move |(x, y)| {
                            EmptyElement::at((x + 11, y))
                                + PathElement::new(legend_outline.clone(), stroke)
                        });
                }
            }
        }
        // Categories' charts leave room at the top for the legend (see `Chart::y_range`).
        let legend_at = if self.x_categories.is_empty() {
            SeriesLabelPosition::LowerRight
        } else {
            SeriesLabelPosition::UpperRight
        };
        chart
            .configure_series_labels()
            .position(legend_at)
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
        root.present().map_err(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart() -> Chart {
        Chart {
            title: "Detection rate".into(),
            x_label: "plant distance (m)".into(),
            y_label: "correct / found".into(),
            x_range: Some((0.0, 1.0)),
            y_range: Some((0.0, 1.0)),
            x_categories: Vec::new(),
            series: vec![Series {
                label: "hough".into(),
                colour: [255, 0, 0],
                points: vec![(0.0, 0.0), (0.5, 0.5), (1.0, 1.0)],
                kind: Kind::Line,
            }],
        }
    }

    #[test]
    fn series_are_drawn_where_their_points_are() {
        let img = chart().render().unwrap();
        assert_eq!(img.dimensions(), SIZE);
        let red = [255, 0, 0];
        // The line rises from lower left to upper right: its red pixels' mean position is
        // near the centre, and the upper-left and lower-right quarters have none of the line.
        let pts: Vec<(u32, u32)> = img
            .enumerate_pixels()
            .filter(|(_, _, p)| p.0 == red)
            .map(|(x, y, _)| (x, y))
            .collect();
        assert!(pts.len() > 300, "{} red pixels", pts.len());
        let (w, h) = SIZE;
        let in_plot = |&&(x, y): &&(u32, u32)| x > 100 && y > 60 && y < h - 60;
        let upper_left = pts
            .iter()
            .filter(in_plot)
            .filter(|&&(x, y)| x < w / 3 && y < h / 3)
            .count();
        assert_eq!(upper_left, 0);
        let mean_x = pts.iter().map(|p| p.0 as f64).sum::<f64>() / pts.len() as f64;
        assert!((mean_x - w as f64 / 2.0).abs() < w as f64 * 0.2, "{mean_x}");
    }

    #[test]
    fn text_is_drawn_with_the_embedded_font() {
        let img = chart().render().unwrap();
        let (w, h) = SIZE;
        let inked = |x0: u32, x1: u32, y0: u32, y1: u32| {
            (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&v| v < 160))
                .count()
        };
        // Only text lives above the plot (the title) and at the far left (the y label).
        assert!(inked(0, w, 0, 40) > 100, "no title drawn");
        assert!(inked(0, 30, 60, h - 60) > 50, "no y-axis label drawn");
    }

    #[test]
    fn empty_and_flat_data_still_render() {
        let mut c = chart();
        c.x_range = None;
        c.y_range = None;
        c.series[0].points = vec![(0.2, 0.7), (0.2, 0.7), (f64::NAN, 1.0)];
        assert!(c.render().is_ok());
        c.series.clear();
        assert!(c.render().is_ok());
    }

    #[test]
    fn reference_points_are_hollow_triangles_at_their_categories() {
        let c = Chart {
            title: "Failures".into(),
            x_label: "method".into(),
            y_label: "failures".into(),
            x_range: None,
            y_range: Some((0.0, 80.0)),
            x_categories: vec!["edge".into(), "hough".into(), "combined".into()],
            series: vec![
                Series {
                    label: "omnirow".into(),
                    colour: [0, 0, 255],
                    points: vec![(0.0, 10.0), (1.0, 20.0), (2.0, 30.0)],
                    kind: Kind::Markers,
                },
                Series {
                    label: "paper".into(),
                    colour: [0, 160, 0],
                    points: vec![(0.0, 40.0), (2.0, 40.0)],
                    kind: Kind::Reference,
                },
            ],
        };
        assert_eq!(c.x_tick(1.0), "hough");
        assert_eq!(c.x_tick(0.5), "");
        assert_eq!(c.x_tick(3.0), "");
        let img = c.render().unwrap();
        let (w, h) = SIZE;
        let at = |col: [u8; 3]| -> Vec<(u32, u32)> {
            img.enumerate_pixels()
                .filter(|(_, _, p)| p.0 == col)
                .map(|(x, y, _)| (x, y))
                .collect()
        };
        // The paper's points: two triangles at y = 40 (mid-height, below the legend in the
        // upper right), in the first and last thirds, none in the middle; hollow: their
        // centres are not inked.
        let green = at([0, 160, 0]);
        let mid: Vec<_> = green
            .iter()
            .filter(|p| p.1 > h / 3 && p.1 < 2 * h / 3)
            .collect();
        let left: Vec<_> = mid.iter().filter(|p| p.0 < w / 3).collect();
        assert!(
            left.len() > 20,
            "{} pixels of the first triangle",
            left.len()
        );
        assert!(mid.iter().any(|p| p.0 > 2 * w / 3));
        assert!(!mid.iter().any(|p| p.0 > 2 * w / 5 && p.0 < 3 * w / 5));
        let cx = left.iter().map(|p| p.0).sum::<u32>() / left.len() as u32;
        let cy = left.iter().map(|p| p.1).sum::<u32>() / left.len() as u32;
        assert_ne!(img.get_pixel(cx, cy).0, [0, 160, 0], "a filled triangle");
        // and the legend shows one at the top right
        assert!(green.iter().any(|p| p.0 > 2 * w / 3 && p.1 < h / 5));
        // The measured points are filled circles, not joined by a line: no blue between them.
        let blue = at([0, 0, 255]);
        assert!(blue.len() > 3 * 60, "{} blue pixels", blue.len());
        let between = blue
            .iter()
            .filter(|p| p.0 > 220 && p.0 < 2 * w / 5 && p.1 > h / 4 && p.1 < 3 * h / 4)
            .count();
        assert_eq!(between, 0);
        // The category names are written under the axis (ink below the plot at the first
        // category's tick, away from the axis title in the middle).
        let inked = |x0: u32, x1: u32| {
            (h - 70..h - 40)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&v| v < 160))
                .count()
        };
        assert!(inked(150, 250) > 30, "no category label");
    }
}
