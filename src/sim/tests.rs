//! The loop on a small synthetic field: it stays in its path, and leaves it with the
//! controller's sign flipped (the loop is closed: the estimate steers the robot).

use super::*;
use crate::camera::IdealLens;
use crate::perception::PerceptionOptions;

fn options(controller: Controller) -> SimOptions {
    SimOptions {
        speed_mps: 1.5,
        distance_m: 6.0,
        fps: 15.0,
        start_offset_m: 0.1,
        start_heading_deg: 5.0,
        robot: RobotModel::DiffDrive {
            max_yaw_rate_rad_s: 2.0,
        },
        controller,
        latency: Latency::Fixed { seconds: 0.05 },
        settle_m: 4.0,
    }
}

fn sim(controller: Controller, curvature_per_m: f64, flip: bool) -> (Summary, Vec<FrameRecord>) {
    let cal = IdealLens::Fisheye185.calibration(256, 306).unwrap();
    let o = options(controller);
    let mut ground = SyntheticGround::new(
        &cal,
        &SyntheticFieldOptions {
            curvature_per_m,
            gap_m: None,
            rows_end_m: None,
            length_m: o.distance_m,
            seed: 3,
            style: None,
        },
    )
    .unwrap();
    let mut p = Perception::new(&cal, &PerceptionOptions::default()).unwrap();
    let mut frames = Vec::new();
    let sign = if flip { -1.0 } else { 1.0 };
    let s = run_steered(
        &mut ground,
        &mut p,
        &cal.mounting,
        [0.0, 0.0],
        &o,
        &|m, v| sign * controller.command(m, v),
        |r| frames.push(r.clone()),
    )
    .unwrap();
    (s, frames)
}

#[test]
fn the_loop_keeps_the_robot_in_its_path_on_straight_and_curved_rows() {
    for (ctl, c) in [
        (Controller::PurePursuit { lookahead_m: 1.5 }, 0.0),
        (
            Controller::Stanley {
                gain: 1.0,
                wheelbase_m: 1.0,
            },
            0.05,
        ),
    ] {
        let (s, frames) = sim(ctl, c, false);
        assert_eq!(s.row_changes, 0, "{ctl:?} {c}: {s:?}");
        assert_eq!(s.frames_without_guidance, 0, "{ctl:?} {c}: {s:?}");
        assert_eq!(s.end, End::Distance, "{s:?}");
        assert!(s.cross_track_max_m < 0.05, "{ctl:?} {c}: {s:?}");
        assert!(s.distance_m > 5.8, "{s:?}");
        // past the approach, the published offset follows the truth
        for f in frames.iter().filter(|f| f.rows.along_m > 2.0) {
            let e = f.estimate.offset_m.unwrap();
            assert!((e - f.cross_track_m).abs() < 0.02, "{ctl:?} {c}: {f:?}");
        }
    }
}

#[test]
fn with_the_steering_sign_flipped_the_robot_leaves_its_path() {
    let ctl = Controller::PurePursuit { lookahead_m: 1.5 };
    let (s, _) = sim(ctl, 0.0, true);
    assert!(s.row_changes > 0 || s.cross_track_max_all_m > 0.25, "{s:?}");
}
