//! A recording's samples — irregular in time, named joint by joint —
//! turned into frames: every `frame_dt` from a run's first stamp, each
//! joint's position, velocity and effort interpolated linearly between the
//! samples around the frame's time, or held from the last sample at or
//! before it. A gap longer than `max_gap` ends a run (or is refused); time
//! going backwards, joints the robot lacks or missing, and values that are
//! not numbers are refused, naming the topic, the time (seconds from the
//! topic's first stamp) and the message.

use std::path::Path;

use alnlab_common::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::recording::Sample;

/// How a frame's values come from the samples around its time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Resample {
    /// Linearly between the last sample at or before the frame's time and
    /// the next.
    #[default]
    Linear,
    /// The last sample at or before the frame's time (zero-order hold).
    Hold,
}

/// What a gap longer than `max_gap` does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Gaps {
    /// It is refused, named.
    #[default]
    Error,
    /// It ends a run; the next sample starts another.
    Split,
}

/// How samples become frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Seconds between frames.
    pub frame_dt: f64,
    pub resample: Resample,
    /// The longest time between two samples of one run (s).
    pub max_gap: f64,
    pub gaps: Gaps,
}

/// One frame: per joint (in the robot's order) what was measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Measured {
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub effort: Vec<f64>,
}

/// A stretch of samples without a gap, as frames.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    /// The first sample's stamp (ns), frame 0's time.
    pub start_ns: i64,
    pub frames: Vec<Measured>,
}

/// Where the samples come from, for messages.
pub struct Source<'a> {
    pub recording: &'a Path,
    pub topic: &'a str,
    /// The robot's description and its one-DOF joints, in model order.
    pub robot: &'a Path,
    pub joints: &'a [String],
}

impl Source<'_> {
    /// An error about `sample`, at its time from the topic's first stamp.
    fn at(&self, first_ns: i64, sample: &Sample, what: impl std::fmt::Display) -> Error {
        Error::bad_file(
            self.recording,
            format!(
                "topic `{}`, at {:.3} s (message {}, stamp {}): {what}",
                self.topic,
                (sample.state.stamp_ns - first_ns) as f64 * 1e-9,
                sample.number,
                stamp(sample.state.stamp_ns)
            ),
        )
    }
}

/// A stamp as ROS 2 prints one: seconds.nanoseconds.
fn stamp(ns: i64) -> String {
    format!(
        "{}.{:09}",
        ns.div_euclid(1_000_000_000),
        ns.rem_euclid(1_000_000_000)
    )
}

/// The runs of frames the `samples` (in file order) make on `grid`.
pub fn frames(source: &Source, samples: &[Sample], grid: &Grid) -> Result<Vec<Run>> {
    let Some(first) = samples.first() else {
        return Ok(Vec::new());
    };
    let first_ns = first.state.stamp_ns;
    let measured = measure(source, first_ns, samples)?;
    for pair in samples.windows(2) {
        let (before, s) = (&pair[0], &pair[1]);
        let gap = (s.state.stamp_ns - before.state.stamp_ns) as f64 * 1e-9;
        if gap <= 0.0 {
            return Err(source.at(
                first_ns,
                s,
                format!(
                    "time goes backwards: message {} before it is stamped {}",
                    before.number,
                    stamp(before.state.stamp_ns)
                ),
            ));
        }
        if gap > grid.max_gap && grid.gaps == Gaps::Error {
            return Err(source.at(
                first_ns,
                s,
                format!(
                    "a gap of {gap:.3} s after message {}, longer than max_gap = {} s \
                     (set ingest.gaps = \"split\" to start a new run after a gap)",
                    before.number, grid.max_gap
                ),
            ));
        }
    }
    let stamps: Vec<i64> = samples.iter().map(|s| s.state.stamp_ns).collect();
    Ok(runs(&stamps, &measured, grid))
}

/// The runs `measured` at `stamps` (increasing) make on `grid`: a new run
/// after each gap longer than `max_gap`, each resampled.
pub fn runs(stamps: &[i64], measured: &[Measured], grid: &Grid) -> Vec<Run> {
    let mut runs = Vec::new();
    let mut start = 0;
    for i in 1..=stamps.len() {
        let ends = stamps
            .get(i)
            .is_none_or(|&t| (t - stamps[i - 1]) as f64 * 1e-9 > grid.max_gap);
        if ends {
            runs.push(resample(&stamps[start..i], &measured[start..i], grid));
            start = i;
        }
    }
    runs
}

/// Each sample's values in the robot's joint order, checked.
fn measure(source: &Source, first_ns: i64, samples: &[Sample]) -> Result<Vec<Measured>> {
    let mut order: Option<(Vec<String>, Vec<usize>)> = None;
    samples
        .iter()
        .map(|s| {
            let m = &s.state;
            let n = m.name.len();
            for (field, values) in [
                ("position", &m.position),
                ("velocity", &m.velocity),
                ("effort", &m.effort),
            ] {
                if values.len() != n {
                    return Err(source.at(
                        first_ns,
                        s,
                        format!("{} {field} values for {n} joint names", values.len()),
                    ));
                }
            }
            // Where each robot joint is in the message (names rarely change).
            if order.as_ref().is_none_or(|(names, _)| *names != m.name) {
                if let Some(unknown) = m.name.iter().find(|j| !source.joints.contains(j)) {
                    return Err(source.at(
                        first_ns,
                        s,
                        format!(
                            "joint `{unknown}` is not one of the moving joints of {} ({})",
                            source.robot.display(),
                            source.joints.join(", ")
                        ),
                    ));
                }
                let at = source
                    .joints
                    .iter()
                    .map(|j| {
                        m.name.iter().position(|n| n == j).ok_or_else(|| {
                            source.at(
                                first_ns,
                                s,
                                format!("lacks joint `{j}` of {}", source.robot.display()),
                            )
                        })
                    })
                    .collect::<Result<Vec<_>>>()?;
                order = Some((m.name.clone(), at));
            }
            let (_, at) = order.as_ref().expect("set above");
            let pick = |values: &[f64], field: &str| {
                at.iter()
                    .map(|&k| match values[k] {
                        x if x.is_finite() => Ok(x),
                        x => Err(source.at(
                            first_ns,
                            s,
                            format!("{field} of `{}` is {x}", m.name[k]),
                        )),
                    })
                    .collect::<Result<Vec<f64>>>()
            };
            Ok(Measured {
                q: pick(&m.position, "position")?,
                qd: pick(&m.velocity, "velocity")?,
                effort: pick(&m.effort, "effort")?,
            })
        })
        .collect()
}

/// One run's samples (stamps ascending) on the grid: a frame every
/// `frame_dt` from the first stamp up to the last.
fn resample(stamps: &[i64], measured: &[Measured], grid: &Grid) -> Run {
    let start_ns = stamps[0];
    let span = (stamps[stamps.len() - 1] - start_ns) as f64 * 1e-9;
    // A frame at the last sample's time counts, whatever the rounding.
    let count = (span / grid.frame_dt + 1e-9).floor() as usize + 1;
    let mut frames = Vec::with_capacity(count);
    let mut i = 0;
    // Times from the run's start: an absolute stamp (~1.7e18 ns) has no
    // exact f64.
    let since = |k: usize| (stamps[k] - start_ns) as f64;
    for k in 0..count {
        let t = k as f64 * grid.frame_dt * 1e9;
        while i + 1 < stamps.len() && since(i + 1) <= t {
            i += 1;
        }
        let (a, b) = (&measured[i], measured.get(i + 1));
        frames.push(match (grid.resample, b) {
            (Resample::Linear, Some(b)) => {
                let w = (t - since(i)) / (stamps[i + 1] - stamps[i]) as f64;
                let mix = |x: &[f64], y: &[f64]| -> Vec<f64> {
                    x.iter().zip(y).map(|(x, y)| x + w * (y - x)).collect()
                };
                Measured {
                    q: mix(&a.q, &b.q),
                    qd: mix(&a.qd, &b.qd),
                    effort: mix(&a.effort, &b.effort),
                }
            }
            _ => a.clone(),
        });
    }
    Run { start_ns, frames }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::joint_state::JointState;

    fn joints() -> Vec<String> {
        vec!["a".into(), "b".into()]
    }

    fn sample(number: usize, ms: i64, names: &[&str], x: f64) -> Sample {
        let n = names.len();
        Sample {
            number,
            log_time_ns: number as u64,
            state: JointState {
                stamp_ns: 1_000_000_000_000 + ms * 1_000_000,
                name: names.iter().map(|s| s.to_string()).collect(),
                position: (0..n).map(|j| x + j as f64).collect(),
                velocity: vec![2.0 * x; n],
                effort: vec![-x; n],
            },
        }
    }

    fn grid(resample: Resample, gaps: Gaps) -> Grid {
        Grid {
            frame_dt: 0.01,
            resample,
            max_gap: 0.05,
            gaps,
        }
    }

    fn run(samples: &[Sample], grid: &Grid) -> Result<Vec<Run>> {
        let joints = joints();
        let source = Source {
            recording: Path::new("r.mcap"),
            topic: "/joint_states",
            robot: Path::new("arm.urdf"),
            joints: &joints,
        };
        frames(&source, samples, grid)
    }

    #[test]
    fn linear_is_exact_on_a_line_and_hold_keeps_the_last_sample() {
        // Samples every 7, 13 ms... of x = t (ms); names in another order.
        let times = [0, 7, 20, 26, 41];
        let samples: Vec<Sample> = times
            .iter()
            .enumerate()
            .map(|(i, &ms)| sample(i, ms, &["b", "a"], ms as f64))
            .collect();
        let runs = run(&samples, &grid(Resample::Linear, Gaps::Error)).unwrap();
        assert_eq!(runs.len(), 1);
        let frames = &runs[0].frames;
        assert_eq!(frames.len(), 5); // 0, 10, 20, 30, 40 ms
        for (k, f) in frames.iter().enumerate() {
            let x = 10.0 * k as f64;
            // Joint a is the message's second: x + 1.
            assert!(
                (f.q[0] - (x + 1.0)).abs() < 1e-9 && (f.q[1] - x).abs() < 1e-9,
                "{f:?}"
            );
            assert!((f.qd[0] - 2.0 * x).abs() < 1e-9 && (f.effort[1] + x).abs() < 1e-9);
        }
        let held = run(&samples, &grid(Resample::Hold, Gaps::Error)).unwrap();
        let q: Vec<f64> = held[0].frames.iter().map(|f| f.q[1]).collect();
        assert_eq!(q, [0.0, 7.0, 20.0, 26.0, 26.0]);
    }

    #[test]
    fn a_gap_splits_a_run_or_is_refused_by_its_time() {
        let samples: Vec<Sample> = [0, 10, 20, 200, 210]
            .iter()
            .enumerate()
            .map(|(i, &ms)| sample(i, ms, &["a", "b"], 1.0))
            .collect();
        let runs = run(&samples, &grid(Resample::Linear, Gaps::Split)).unwrap();
        let lengths: Vec<usize> = runs.iter().map(|r| r.frames.len()).collect();
        assert_eq!(lengths, [3, 2]);
        assert_eq!(runs[1].start_ns, samples[3].state.stamp_ns);
        let err = run(&samples, &grid(Resample::Linear, Gaps::Error)).unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("r.mcap: topic `/joint_states`, at 0.200 s (message 3, stamp 1000.200000000): a gap of 0.180 s after message 2"), "{text}");
    }

    #[test]
    fn what_cannot_be_a_frame_is_named() {
        let g = grid(Resample::Linear, Gaps::Error);
        let backwards = [
            sample(0, 10, &["a", "b"], 0.0),
            sample(1, 5, &["a", "b"], 0.0),
        ];
        let text = run(&backwards, &g).unwrap_err().to_string();
        assert!(text.contains("at -0.005 s (message 1, stamp 1000.005000000): time goes backwards: message 0 before it is stamped 1000.010000000"), "{text}");
        let unknown = [sample(0, 0, &["a", "b", "gripper"], 0.0)];
        let text = run(&unknown, &g).unwrap_err().to_string();
        assert!(
            text.contains("joint `gripper` is not one of the moving joints of arm.urdf (a, b)"),
            "{text}"
        );
        let missing = [sample(0, 0, &["a"], 0.0)];
        assert!(
            run(&missing, &g)
                .unwrap_err()
                .to_string()
                .contains("lacks joint `b` of arm.urdf")
        );
        let mut short = sample(0, 0, &["a", "b"], 0.0);
        short.state.effort.pop();
        assert!(
            run(&[short], &g)
                .unwrap_err()
                .to_string()
                .contains("1 effort values for 2 joint names")
        );
        let mut nan = sample(0, 0, &["a", "b"], 0.0);
        nan.state.velocity[1] = f64::NAN;
        assert!(
            run(&[nan], &g)
                .unwrap_err()
                .to_string()
                .contains("velocity of `b` is NaN")
        );
    }
}
