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
        // the first frame: one measurement does not start the tracker
        assert_eq!(s.frames_without_guidance, 1, "{ctl:?} {c}: {s:?}");
        assert_eq!(s.end, End::Distance, "{s:?}");
        assert!(s.cross_track_max_m < 0.05, "{ctl:?} {c}: {s:?}");
        assert!(s.distance_m > 5.8, "{s:?}");
        // past the approach, the published offset follows the truth (within the estimate's
        // noise on this 306×256 image: 1–2 cm, at most 3.2 cm on the curved field)
        for f in frames.iter().filter(|f| f.rows.along_m > 3.0) {
            let e = f.estimate.offset_m.unwrap();
            assert!((e - f.cross_track_m).abs() < 0.035, "{ctl:?} {c}: {f:?}");
        }
    }
}

#[test]
fn with_the_steering_sign_flipped_the_robot_leaves_its_path() {
    let ctl = Controller::PurePursuit { lookahead_m: 1.5 };
    let (s, _) = sim(ctl, 0.0, true);
    assert!(s.row_changes > 0 || s.cross_track_max_all_m > 0.25, "{s:?}");
}

#[test]
fn a_command_acts_from_its_time_and_a_long_latency_waits_for_later_frames() {
    let robot = RobotModel::DiffDrive {
        max_yaw_rate_rad_s: 10.0,
    };
    let start = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };
    // frame 0 at t = 0, its command (curvature 0.2) acting after 30 ms, frames 100 ms apart
    let mut pose = start;
    let mut pending = vec![(0.03, 0.2)];
    let now = drive(&mut pose, 0.0, &mut pending, 0.0, 0.1, &robot, 1.0);
    assert_eq!(now, 0.2);
    assert!(pending.is_empty());
    let mut want = start;
    want.integrate(1.0, 0.0, 0.03);
    want.integrate(1.0, 0.2, 0.07);
    assert!((pose.x - want.x).abs() < 1e-12 && (pose.y - want.y).abs() < 1e-12);
    assert!((pose.theta - 0.2 * 0.07).abs() < 1e-12);
    // a latency of 150 ms: the command waits into the next frame's interval
    let mut pose = start;
    let mut pending = vec![(0.15, -0.5)];
    let now = drive(&mut pose, 0.1, &mut pending, 0.0, 0.1, &robot, 1.0);
    assert_eq!(now, 0.1);
    assert_eq!(pending, vec![(0.15, -0.5)]);
    let now = drive(&mut pose, now, &mut pending, 0.1, 0.2, &robot, 1.0);
    assert_eq!(now, -0.5);
    assert!((pose.theta - (0.1 * 0.15 - 0.5 * 0.05)).abs() < 1e-12);
}
