//! `omnirow eval guidance`: synthetic drives through the whole guidance chain — detector, the
//! row fit on the points, the comb and the tracker — scored against the drives' truth.
//!
//! Owns the drives ([`scenarios`]: weaving by ±0.3 spacing, crossing to the next path, a 20 m
//! radius, the headland, and `field`: all of them in one drive, for the long run), the per-drive scores ([`DriveScore`]: offset, heading and curvature
//! errors, row jumps, the end of the rows' error, empty stretches reported) as a Markdown table,
//! and one PNG per drive of the offset, truth and estimate over time (drawn with [`super::chart`]).

use super::chart::{Chart, ChartError, Kind, Series};
use crate::camera::Calibration;
use crate::guidance::CropState;
use crate::perception::{Perception, PerceptionOptions};
use crate::source::synthetic::{SyntheticDrive, SyntheticDriveOptions};
use crate::synth::photo::PhotoGround;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Errors of the guidance evaluation.
#[derive(Debug, thiserror::Error)]
pub enum GuidanceEvalError {
    #[error("drive {drive}: {problem}")]
    Drive { drive: String, problem: String },
    #[error(transparent)]
    Chart(#[from] ChartError),
    #[error("writing {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// One synthetic drive to score.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    pub name: &'static str,
    pub drive: SyntheticDriveOptions,
    pub frames: u64,
}

/// The drives of issue 14, `seconds` long each, at `width`×`height`, 15 fps.
pub fn scenarios(width: u32, height: u32, seconds: f64) -> Vec<Scenario> {
    let base = SyntheticDriveOptions {
        fps: 15.0,
        width,
        height,
        lens: crate::camera::IdealLens::Fisheye185,
        colour: true,
        seed: 7,
        speed_mps: 1.0,
        heading_amplitude_deg: 5.0,
        pitch_amplitude_deg: 2.0,
        // ±0.3 spacing
        offset_amplitude_m: 0.15,
        period_s: 20.0,
        cross_at_s: 0.0,
        curvature_per_m: 0.0,
        rows_end_m: 0.0,
        gap_start_m: 0.0,
        gap_length_m: 0.0,
        render_threads: 0,
    };
    let frames = (seconds * base.fps).round().max(2.0) as u64;
    vec![
        Scenario {
            name: "weaving",
            drive: base.clone(),
            frames,
        },
        Scenario {
            name: "crossing",
            drive: SyntheticDriveOptions {
                cross_at_s: seconds / 4.0,
                ..base.clone()
            },
            frames,
        },
        Scenario {
            name: "curved_r20",
            drive: SyntheticDriveOptions {
                curvature_per_m: 0.05,
                ..base.clone()
            },
            frames,
        },
        Scenario {
            name: "headland",
            drive: SyntheticDriveOptions {
                // at 1 m/s: an empty stretch from 15% of the way (a quarter of it long, at
                // most 6 m), the rows' end at 60%
                rows_end_m: seconds * 0.6,
                gap_start_m: seconds * 0.15,
                gap_length_m: (seconds * 0.25).min(6.0),
                ..base.clone()
            },
            frames,
        },
        Scenario {
            name: "field",
            drive: SyntheticDriveOptions {
                // everything in one drive (the long run): weaving, the crossing at a quarter
                // of the time, an empty stretch from half the way (a tenth of it long, at most
                // 6 m), the rows' end at 90%
                cross_at_s: seconds / 4.0,
                rows_end_m: seconds * 0.9,
                gap_start_m: seconds * 0.5,
                gap_length_m: (seconds * 0.1).min(6.0),
                ..base
            },
            frames,
        },
    ]
}

/// What a drive is seen through and drives over: the scenario's ideal lens or a
/// calibration, the synthetic ground or a photograph's (straight drives only).
#[derive(Clone, Default)]
pub struct Setting {
    pub calibration: Option<Calibration>,
    /// The photograph's ground and the photograph's name (the score's name is
    /// `drive@name`).
    pub photo: Option<(Arc<PhotoGround>, String)>,
}

impl Setting {
    /// The drive of `s` in this setting.
    fn drive(&self, s: &Scenario) -> Result<SyntheticDrive, crate::synth::SynthError> {
        let mut drive = match &self.calibration {
            Some(cal) => SyntheticDrive::through(s.drive.clone(), cal.clone())?,
            None => SyntheticDrive::new(s.drive.clone())?,
        };
        if let Some((g, _)) = &self.photo {
            drive = drive.with_photo_ground(g.clone())?;
        }
        Ok(drive)
    }

    /// The score's name for drive `name`.
    fn name(&self, name: &str) -> String {
        match &self.photo {
            Some((_, p)) => format!("{name}@{p}"),
            None => name.to_string(),
        }
    }
}

/// The drives run unless others are named: all but `field` (which repeats them in one).
pub const DEFAULT_DRIVES: [&str; 4] = ["weaving", "crossing", "curved_r20", "headland"];

/// What one drive scored.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveScore {
    pub name: String,
    pub frames: usize,
    /// Frames with an estimate (not lost).
    pub estimated: usize,
    /// Offset from the followed line (the start's inter-row path), against the truth, metres.
    pub offset_mean_abs_m: f64,
    pub offset_p99_m: f64,
    pub heading_p99_deg: f64,
    /// Largest relative curvature error over the second half (curved drives), else `None`.
    pub curvature_max_rel: Option<f64>,
    /// Frames whose offset moved by more than half a spacing against the truth's motion.
    pub row_jumps: usize,
    /// Largest error of `end_of_row_m` while the end is 0.3–5 m ahead, and the frames
    /// where it was due but missing.
    pub end_max_err_m: Option<f64>,
    pub end_missed: usize,
    /// Frames with no plant within 3 m (truth), and those of them reported as not `rows`.
    pub empty_frames: usize,
    pub empty_reported: usize,
    /// Every frame: the plot's series and `frames.jsonl`.
    pub series: Vec<FrameScore>,
}

/// One frame of a drive: the truth and what guidance published.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FrameScore {
    pub time_s: f64,
    /// The truth's offset from the start's inter-row path (metres).
    pub truth_offset_m: f64,
    /// The published offset from the followed line (`None`: no offset this frame).
    pub offset_m: Option<f64>,
    /// The truth's and the published heading relative to the rows (radians).
    pub truth_heading_rad: f64,
    pub heading_rad: Option<f64>,
    /// The tracker's state after this frame.
    pub tracking: crate::guidance::TrackState,
    /// True when the tracker rejected this frame's measurement.
    pub rejected: bool,
    /// This frame's own answer before the filter (`None`: the frame measured nothing).
    pub measured: Option<crate::guidance::FrameGuidance>,
    /// The detector's status and quality (0–1) of this frame's estimate.
    pub status: crate::estimate::Status,
    pub quality: f64,
}

/// The p-quantile of `v` (sorted in place), 0 when empty.
fn quantile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// Runs one drive in `setting` through the perception step as `opts` configure it (the
/// detector, the row fit and guidance; with `narrow_search`, each frame's search narrowed
/// by the tracker's prediction as the node's pipeline does,
/// [`crate::perception::NarrowSearch`]).
pub fn run_drive(
    s: &Scenario,
    setting: &Setting,
    opts: &PerceptionOptions,
) -> Result<DriveScore, GuidanceEvalError> {
    let name = setting.name(s.name);
    let fail = |problem: String| GuidanceEvalError::Drive {
        drive: name.clone(),
        problem,
    };
    let mut drive = setting.drive(s).map_err(|e| fail(e.to_string()))?;
    let cal = drive.calibration().clone();
    let mut perception = Perception::new(&cal, opts).map_err(|e| fail(e.to_string()))?;
    let (mut offs, mut heads, mut curv) = (Vec::new(), Vec::new(), Vec::new());
    let mut score = DriveScore {
        name: name.clone(),
        frames: s.frames as usize,
        estimated: 0,
        offset_mean_abs_m: 0.0,
        offset_p99_m: 0.0,
        heading_p99_deg: 0.0,
        curvature_max_rel: None,
        row_jumps: 0,
        end_max_err_m: None,
        end_missed: 0,
        empty_frames: 0,
        empty_reported: 0,
        series: Vec::with_capacity(s.frames as usize),
    };
    let mut start_path = None;
    let mut prev: Option<(f64, f64)> = None;
    for seq in 0..s.frames {
        let frame = drive.frame_at(seq).map_err(|e| fail(e.to_string()))?;
        let est = perception
            .process(&frame)
            .map_err(|e| fail(e.to_string()))?;
        let (Some(t), Some(g)) = (est.truth.as_ref(), est.guidance.as_ref()) else {
            return Err(fail("a frame without truth or guidance".into()));
        };
        let path = *start_path.get_or_insert(t.path());
        let truth_off = t.path_offset_m(path);
        let time = seq as f64 / s.drive.fps;
        score.series.push(FrameScore {
            time_s: time,
            truth_offset_m: truth_off,
            offset_m: g.lateral_offset_m,
            truth_heading_rad: t.heading_rad,
            heading_rad: g.heading_rad,
            tracking: g.tracking,
            rejected: g.rejected,
            measured: g.frame,
            status: est.status,
            quality: est.quality,
        });
        let own = est.row_fit.as_ref();
        tracing::trace!(
            drive = s.name,
            seq,
            truth_end_m = ?t.end_of_rows_m,
            no_crop = t.no_crop,
            frame_end_m = ?own.and_then(|f| f.end_of_rows_m),
            frame_crop_near = ?own.map(|f| f.crop_near),
            end_m = ?g.end_of_row_m,
            crop = ?g.crop,
            status = ?est.status,
            "frame"
        );
        if t.no_crop {
            score.empty_frames += 1;
            score.empty_reported += usize::from(g.crop != CropState::Rows);
            if g.crop == CropState::Rows {
                tracing::debug!(
                    drive = s.name,
                    seq,
                    truth_end_m = ?t.end_of_rows_m,
                    frame_crop_near = ?own.map(|f| f.crop_near),
                    frame_end_m = ?own.and_then(|f| f.end_of_rows_m),
                    "empty-stretch frame not reported"
                );
            }
        }
        if let Some(end) = t.end_of_rows_m.filter(|e| (0.3..=5.0).contains(e)) {
            match g.end_of_row_m {
                Some(e) => {
                    let err = (e - end).abs();
                    score.end_max_err_m = Some(score.end_max_err_m.map_or(err, |m| m.max(err)));
                }
                None => {
                    score.end_missed += 1;
                    tracing::debug!(
                        drive = s.name,
                        seq,
                        truth_end_m = end,
                        frame_end_m = ?own.and_then(|f| f.end_of_rows_m),
                        status = ?est.status,
                        "end of the rows due but not reported"
                    );
                }
            }
        }
        let Some(off) = g.lateral_offset_m else {
            prev = None;
            continue;
        };
        score.estimated += 1;
        if let Some((p_off, p_truth)) = prev {
            if ((off - p_off) - (truth_off - p_truth)).abs() > t.row_spacing_m / 2.0 {
                score.row_jumps += 1;
            }
        }
        prev = Some((off, truth_off));
        if t.no_crop || t.end_of_rows_m.is_some_and(|e| e < 0.0) {
            continue;
        }
        offs.push((off - truth_off).abs());
        if let Some(h) = g.heading_rad {
            heads.push((h - t.heading_rad).abs().to_degrees());
        }
        if t.curvature_per_m != 0.0 && seq >= s.frames / 2 {
            if let Some(k) = g.curvature_per_m {
                let truth = t.path_curvature_per_m(path);
                curv.push(((k - truth) / truth).abs());
            }
        }
    }
    score.offset_mean_abs_m = offs.iter().sum::<f64>() / offs.len().max(1) as f64;
    score.offset_p99_m = quantile(&mut offs, 0.99);
    score.heading_p99_deg = quantile(&mut heads, 0.99);
    score.curvature_max_rel = (!curv.is_empty()).then(|| quantile(&mut curv, 1.0));
    Ok(score)
}

/// The drives of `scores` named `drive` (in any setting, `drive@…`) pooled into one score
/// named `name`: every frame's offset and heading error together, the counts summed.
/// `None` when there is no such drive.
pub fn pooled(scores: &[DriveScore], drive: &str, name: &str) -> Option<DriveScore> {
    let of: Vec<&DriveScore> = scores
        .iter()
        .filter(|d| d.name == drive || d.name.starts_with(&format!("{drive}@")))
        .collect();
    if of.is_empty() {
        return None;
    }
    let (mut offs, mut heads) = (Vec::new(), Vec::new());
    for f in of.iter().flat_map(|d| &d.series) {
        if let Some(o) = f.offset_m {
            offs.push((o - f.truth_offset_m).abs());
        }
        if let Some(h) = f.heading_rad {
            heads.push((h - f.truth_heading_rad).abs().to_degrees());
        }
    }
    let sum = |f: fn(&DriveScore) -> usize| of.iter().map(|d| f(d)).sum::<usize>();
    Some(DriveScore {
        name: name.to_string(),
        frames: sum(|d| d.frames),
        estimated: sum(|d| d.estimated),
        offset_mean_abs_m: offs.iter().sum::<f64>() / offs.len().max(1) as f64,
        offset_p99_m: quantile(&mut offs, 0.99),
        heading_p99_deg: quantile(&mut heads, 0.99),
        curvature_max_rel: None,
        row_jumps: sum(|d| d.row_jumps),
        end_max_err_m: None,
        end_missed: sum(|d| d.end_missed),
        empty_frames: sum(|d| d.empty_frames),
        empty_reported: sum(|d| d.empty_reported),
        series: Vec::new(),
    })
}

/// The scores as a Markdown table.
pub fn markdown(scores: &[DriveScore], command: &str) -> String {
    let mut s = format!(
        "# Row guidance on synthetic drives\n\n`{command}`\n\n| drive | frames | estimated | offset mean abs (mm) | offset p99 (mm) | heading p99 (°) | curvature max rel. error | row jumps | end of rows max error (m) / missed | empty-stretch frames reported |\n|---|---|---|---|---|---|---|---|---|---|\n"
    );
    for d in scores {
        let curv = d
            .curvature_max_rel
            .map_or("—".into(), |c| format!("{:.1}%", c * 100.0));
        let end = match (d.end_max_err_m, d.end_missed) {
            (None, 0) => "—".to_string(),
            (e, m) => format!("{} / {m}", e.map_or("—".into(), |e| format!("{e:.2}"))),
        };
        // no estimate: no error to give
        let mm = |v: f64| match d.estimated {
            0 => "—".to_string(),
            _ => format!("{:.1}", v * 1e3),
        };
        let heading = match d.estimated {
            0 => "—".to_string(),
            _ => format!("{:.3}", d.heading_p99_deg),
        };
        s += &format!(
            "| {} | {} | {} | {} | {} | {heading} | {curv} | {} | {end} | {}/{} |\n",
            d.name,
            d.frames,
            d.estimated,
            mm(d.offset_mean_abs_m),
            mm(d.offset_p99_m),
            d.row_jumps,
            d.empty_reported,
            d.empty_frames
        );
    }
    s
}

/// Writes README.md (the table), frames.jsonl (every frame of every drive, a
/// [`FrameScore`] with its drive's name) and one PNG per drive (offset, truth and estimate
/// over time) into `dir`; the files written.
pub fn write(
    scores: &[DriveScore],
    dir: &Path,
    command: &str,
) -> Result<Vec<PathBuf>, GuidanceEvalError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| GuidanceEvalError::Write { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut files = Vec::new();
    let md = dir.join("README.md");
    std::fs::write(&md, markdown(scores, command)).map_err(io(&md))?;
    files.push(md);
    let jsonl = dir.join("frames.jsonl");
    let mut lines = String::new();
    for d in scores {
        for f in &d.series {
            let line = serde_json::json!({ "drive": d.name, "frame": f });
            lines += &line.to_string();
            lines.push('\n');
        }
    }
    std::fs::write(&jsonl, lines).map_err(io(&jsonl))?;
    files.push(jsonl);
    for d in scores.iter().filter(|d| !d.series.is_empty()) {
        let chart = Chart {
            title: format!("guidance: {} — offset from the followed line", d.name),
            x_label: "time (s)".into(),
            y_label: "lateral offset (m)".into(),
            x_range: None,
            y_range: None,
            x_categories: Vec::new(),
            series: vec![
                Series {
                    label: "truth".into(),
                    colour: [40, 40, 40],
                    points: d
                        .series
                        .iter()
                        .map(|p| (p.time_s, p.truth_offset_m))
                        .collect(),
                    kind: Kind::Line,
                },
                Series {
                    label: "estimate".into(),
                    colour: [220, 60, 30],
                    points: d
                        .series
                        .iter()
                        .filter_map(|p| Some((p.time_s, p.offset_m?)))
                        .collect(),
                    kind: Kind::Markers,
                },
            ],
        };
        let png = dir.join(format!("guidance_{}.png", d.name.replace(['/', '\\'], "_")));
        chart
            .render()?
            .save(&png)
            .map_err(|e| GuidanceEvalError::Write {
                path: png.clone(),
                source: std::io::Error::other(e.to_string()),
            })?;
        files.push(png);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_weaving_drive_scores_within_the_targets_and_writes_its_files() {
        let mut s = scenarios(306, 256, 1.0).remove(0);
        s.frames = 8;
        let opts = PerceptionOptions {
            narrow_search: true,
            threads: 2,
            ..PerceptionOptions::default()
        };
        let d = run_drive(&s, &Setting::default(), &opts).unwrap();
        assert_eq!(d.frames, 8);
        // the tracker starts on the second frame (two agreeing measurements)
        assert_eq!(d.estimated, 7);
        assert_eq!(d.row_jumps, 0);
        assert!(d.offset_p99_m < 0.03, "{d:?}");
        let dir =
            std::env::temp_dir().join(format!("omnirow-eval-guidance-{}", std::process::id()));
        let files = write(&[d], &dir, "test").unwrap();
        assert_eq!(files.len(), 3);
        let md = std::fs::read_to_string(&files[0]).unwrap();
        assert!(md.contains("| weaving | 8 | 7 |"), "{md}");
        let frames = std::fs::read_to_string(&files[1]).unwrap();
        assert_eq!(frames.lines().count(), 8, "{frames}");
        assert!(image::open(&files[2]).is_ok());
        std::fs::remove_dir_all(&dir).ok();
    }
}
