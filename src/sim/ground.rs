//! What the camera sees: a [`Ground`] renders the view from a camera pose given relative to
//! the rows, and says where the rows are. [`SyntheticGround`] is the synthetic field of
//! [`crate::synth`] (the synthetic drive's look: Bayer frames, RGB where the image has an odd
//! side, a plant every 5 cm), or with [`SyntheticGround::with_photo_ground`] its ground
//! textured from a photograph of real rows (straight rows, no gap, no end).
//!
//! Owns [`RowFrame`], the conversion between world poses and row-relative ones: the rows
//! are straight along world +X through y = i·spacing, or for curvature c concentric circles
//! bending left when c > 0 with row 0 of radius 1/|c| running along +X at the origin (the
//! synthetic field's bend, [`crate::synth::SynthOptions::curvature_per_m`], anchored at arc
//! length 0). Row-relative coordinates are (arc length along row 0, position across the
//! rows, yaw relative to the rows' tangent there), what the synthetic renderer takes as
//! `along_m`, `lateral_m` and `yaw_deg`.

use super::robot::Pose2;
use super::SimError;
use crate::camera::Calibration;
use crate::frame::PixelFormat;
use crate::synth::photo::PhotoGround;
use crate::synth::{Renderer, Scene, Style, SynthOptions};
use std::sync::Arc;

/// A pose relative to the rows.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RowPose {
    /// Arc length along row 0 (world x for straight rows), metres.
    pub along_m: f64,
    /// Position across the rows (row i at i·spacing), metres, positive left.
    pub lateral_m: f64,
    /// Yaw relative to the rows' tangent, radians, counter-clockwise.
    pub yaw_rad: f64,
}

/// World ↔ row-relative coordinates of a field of curvature `curvature_per_m` (0: straight).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowFrame {
    pub curvature_per_m: f64,
}

impl RowFrame {
    /// The row-relative pose of world pose `p`.
    pub fn to_rows(&self, p: &Pose2) -> RowPose {
        let c = self.curvature_per_m;
        let (along, lateral) = if c == 0.0 {
            (p.x, p.y)
        } else {
            let r = 1.0 / c;
            let sign = r.signum();
            let dy = sign * (r - p.y);
            (r.abs() * p.x.atan2(dy), r - sign * p.x.hypot(dy))
        };
        RowPose {
            along_m: along,
            lateral_m: lateral,
            yaw_rad: wrap(p.theta - c * along),
        }
    }

    /// The world pose of row-relative pose `q`.
    pub fn to_world(&self, q: &RowPose) -> Pose2 {
        let c = self.curvature_per_m;
        let (x, y) = if c == 0.0 {
            (q.along_m, q.lateral_m)
        } else {
            let r = 1.0 / c;
            let sign = r.signum();
            let (s, co) = (q.along_m / r.abs()).sin_cos();
            let rho = sign * (r - q.lateral_m);
            (rho * s, r - sign * rho * co)
        };
        Pose2 {
            x,
            y,
            theta: q.yaw_rad + c * q.along_m,
        }
    }
}

/// An angle wrapped into (−π, π].
pub fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let w = a - t * (a / t).round();
    if w <= -std::f64::consts::PI {
        w + t
    } else {
        w
    }
}

/// A field the camera looks at.
pub trait Ground {
    /// Renders the camera's view from `camera` (the camera's centre's foot point and the
    /// robot's yaw, relative to the rows) into `buf` (resized as needed); the image's
    /// width, height and pixel format.
    fn render(
        &mut self,
        camera: &RowPose,
        buf: &mut Vec<u8>,
    ) -> Result<(u32, u32, PixelFormat), SimError>;
    /// Distance between neighbouring rows, metres (row i runs at i·spacing across).
    fn row_spacing_m(&self) -> f64;
    /// Curvature of row 0, 1/m (0: straight rows).
    fn curvature_per_m(&self) -> f64;
    /// Where the rows end, metres along, when they do.
    fn rows_end_m(&self) -> Option<f64>;
    /// Whether some plant grows within `reach_m` along the rows of `along_m`.
    fn crop_within(&self, along_m: f64, reach_m: f64) -> bool;
}

/// The synthetic field's layout for the loop: curvature, an empty stretch, the rows' end.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticFieldOptions {
    pub curvature_per_m: f64,
    /// No plant from .0 to .1 metres along.
    pub gap_m: Option<[f64; 2]>,
    pub rows_end_m: Option<f64>,
    /// The field reaches this far along (plus a margin), metres.
    pub length_m: f64,
    pub seed: u64,
    /// The frames' look; `None`: Bayer (the GC2450C's raw frames) where both image sides are
    /// even, grey (the paper's) otherwise.
    pub style: Option<Style>,
}

/// The synthetic field, rendered through a calibration.
pub struct SyntheticGround {
    renderer: Renderer,
    base: SynthOptions,
    mounting: crate::camera::Mounting,
    seed: u64,
    field: crate::synth::Field,
    photo: Option<Arc<PhotoGround>>,
}

impl SyntheticGround {
    /// The renderer for `cal` (heavy, once) and the field of `o`.
    pub fn new(cal: &Calibration, o: &SyntheticFieldOptions) -> Result<Self, SimError> {
        let renderer = Renderer::new(cal)?;
        let (w, h) = renderer.size();
        if o.style == Some(Style::Bayer) && (w % 2 != 0 || h % 2 != 0) {
            return Err(SimError::Options(format!(
                "Bayer frames need even sides (2×2 quads); the image is {w}×{h}"
            )));
        }
        let base = SynthOptions {
            // the camera's raw Bayer mosaic, or colour where the size has no whole 2×2 quads
            style: match o.style {
                Some(s) => s,
                None if w % 2 == 0 && h % 2 == 0 => Style::Bayer,
                None => Style::Grey,
            },
            plant_distance_m: 0.05,
            samples: 2,
            height_m: cal.mounting.height_m,
            curvature_per_m: o.curvature_per_m,
            rows_end_m: o.rows_end_m,
            gap_m: o.gap_m,
            field_half_length_m: SynthOptions::default()
                .field_half_length_m
                .max(o.length_m + 60.0),
            ..SynthOptions::default()
        };
        base.validate()?;
        // the field as a whole (for where the crop is), built once
        let field = crate::synth::Field::new(&base, o.seed, [0.0, 0.0]);
        Ok(SyntheticGround {
            renderer,
            base,
            mounting: cal.mounting,
            seed: o.seed,
            field,
            photo: None,
        })
    }

    /// The field's ground textured from a photograph of real rows, at its rectification's
    /// row spacing. Refused (naming the option) with curved rows, an empty stretch or the
    /// rows' end, which a photograph's ground cannot show.
    pub fn with_photo_ground(mut self, ground: Arc<PhotoGround>) -> Result<Self, SimError> {
        self.base.row_spacing_m = ground.row_spacing_m();
        Scene::new(&self.base, self.seed, &self.mounting)?.with_photo_ground(ground.clone())?;
        self.field = crate::synth::Field::new(&self.base, self.seed, [0.0, 0.0]);
        self.photo = Some(ground);
        Ok(self)
    }
}

impl Ground for SyntheticGround {
    fn render(
        &mut self,
        camera: &RowPose,
        buf: &mut Vec<u8>,
    ) -> Result<(u32, u32, PixelFormat), SimError> {
        let o = SynthOptions {
            yaw_deg: wrap(camera.yaw_rad).to_degrees(),
            lateral_m: camera.lateral_m,
            along_m: camera.along_m,
            ..self.base.clone()
        };
        let mut scene = Scene::new(&o, self.seed, &self.mounting)?;
        if let Some(g) = &self.photo {
            scene = scene.with_photo_ground(g.clone())?;
        }
        buf.resize(self.renderer.buffer_len(o.style), 0);
        self.renderer.render_into(&scene, buf)?;
        let (w, h) = self.renderer.size();
        Ok((w, h, o.style.pixel_format()))
    }

    fn row_spacing_m(&self) -> f64 {
        self.base.row_spacing_m
    }

    fn curvature_per_m(&self) -> f64 {
        self.base.curvature_per_m
    }

    fn rows_end_m(&self) -> Option<f64> {
        self.base.rows_end_m.map(|_| self.field.rows_end())
    }

    fn crop_within(&self, along_m: f64, reach_m: f64) -> bool {
        self.field.crop_within(along_m, reach_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_coordinates_round_trip_and_follow_the_bend() {
        // (within half a turn of the origin: the arc length wraps beyond)
        for c in [0.0, 0.05, -0.05, 0.07] {
            let f = RowFrame { curvature_per_m: c };
            for q in [
                RowPose {
                    along_m: 0.0,
                    lateral_m: 0.25,
                    yaw_rad: 0.0,
                },
                RowPose {
                    along_m: 13.0,
                    lateral_m: -0.4,
                    yaw_rad: 0.1,
                },
                RowPose {
                    along_m: 40.0,
                    lateral_m: 1.75,
                    yaw_rad: -0.2,
                },
            ] {
                let back = f.to_rows(&f.to_world(&q));
                assert!(
                    (back.along_m - q.along_m).abs() < 1e-9,
                    "{c}: {q:?} {back:?}"
                );
                assert!((back.lateral_m - q.lateral_m).abs() < 1e-9);
                assert!((back.yaw_rad - q.yaw_rad).abs() < 1e-9);
            }
            // driving along a row at its curvature keeps the row-relative pose
            let lateral = 0.25;
            let mut p = f.to_world(&RowPose {
                along_m: 0.0,
                lateral_m: lateral,
                yaw_rad: 0.0,
            });
            let k = c / (1.0 - c * lateral);
            for _ in 0..100 {
                p.integrate(1.0, k, 0.1);
            }
            let q = f.to_rows(&p);
            assert!((q.lateral_m - lateral).abs() < 1e-9, "{c}: {q:?}");
            assert!(q.yaw_rad.abs() < 1e-9, "{c}: {q:?}");
            // 10 m along the row at `lateral` is 10·(1 − c·lateral)⁻¹ along row 0
            assert!(
                (q.along_m - 10.0 / (1.0 - c * lateral)).abs() < 1e-9,
                "{q:?}"
            );
        }
    }
}
