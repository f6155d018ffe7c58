//! Trajectories recorded as tables: CSV or Parquet files, each one
//! trajectory, one row a sample, its columns mapped to the robot's joints
//! by `[ingest.table]` ([`Columns`]). A sample's time comes from a time
//! column or a declared rate, and is checked against the data: the step the
//! positions and velocities imply (Δq against q̇ Δt, least squares over every
//! joint) must agree with it within [`RATE_TOLERANCE`]. A file that cannot
//! be read as a trajectory — not CSV or Parquet, a column missing or not
//! numeric, a value missing or not finite, time standing still or going
//! backwards, a rate the data contradict — is refused naming the file, the
//! column and the row (rows count from 1, the header not counted).

use std::fs::File;
use std::path::Path;

use alnlab_common::params::Positive;
use alnlab_common::{Error, Result};
use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int32Type, Int64Type};
use arrow_array::{Array, ArrayRef};
use arrow_schema::DataType;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use serde::{Deserialize, Serialize};

use crate::frames::{Gaps, Grid, Measured};

/// How far the step the data imply may be from the stated one (relative).
pub const RATE_TOLERANCE: f64 = 0.1;

/// The unit of a revolute joint's positions (and, per second, velocities).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Angles {
    #[default]
    Rad,
    Deg,
}

/// The unit of a time column.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimeUnit {
    #[default]
    S,
    Ms,
    Us,
    Ns,
}

impl TimeUnit {
    fn seconds(self) -> f64 {
        match self {
            TimeUnit::S => 1.0,
            TimeUnit::Ms => 1e-3,
            TimeUnit::Us => 1e-6,
            TimeUnit::Ns => 1e-9,
        }
    }
}

/// The `[ingest.table]` table: which columns hold what. A joint's column
/// names are templates: `{joint}` is the URDF joint's name, `{index}` its
/// place among the robot's moving joints from 0, `{number}` from 1.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Columns {
    /// A column of sample times (in `time_unit`), increasing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<String>,
    #[serde(default)]
    pub time_unit: TimeUnit,
    /// Samples a second, for tables without a time column.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate: Option<Positive>,
    #[serde(default = "position")]
    pub position: String,
    #[serde(default = "velocity")]
    pub velocity: String,
    /// The joint's measured effort (N m, or N for a prismatic joint).
    #[serde(default = "effort")]
    pub effort: String,
    /// The unit of revolute joints' positions and velocities.
    #[serde(default)]
    pub angles: Angles,
}

fn position() -> String {
    "{joint}.position".into()
}
fn velocity() -> String {
    "{joint}.velocity".into()
}
fn effort() -> String {
    "{joint}.effort".into()
}

impl Default for Columns {
    fn default() -> Columns {
        Columns {
            time: None,
            time_unit: TimeUnit::default(),
            rate: None,
            position: position(),
            velocity: velocity(),
            effort: effort(),
            angles: Angles::default(),
        }
    }
}

impl Columns {
    /// Checks what does not need the files: a time column or a rate, not
    /// both, and templates that name each joint apart.
    pub fn validate(&self) -> std::result::Result<(), (String, String)> {
        match (&self.time, &self.rate) {
            (Some(_), Some(_)) => Err((
                "rate".into(),
                "a table has a time column or a declared rate, not both".into(),
            )),
            (None, None) => Err((
                "time".into(),
                "expected a time column (`time`, in `time_unit`) or the samples' `rate` (Hz)"
                    .into(),
            )),
            (Some(t), None) if t.is_empty() => {
                Err(("time".into(), "expected a column name".into()))
            }
            _ => Ok(()),
        }?;
        for (field, template) in [
            ("position", &self.position),
            ("velocity", &self.velocity),
            ("effort", &self.effort),
        ] {
            if !["{joint}", "{index}", "{number}"]
                .iter()
                .any(|k| template.contains(k))
            {
                return Err((
                    field.into(),
                    format!(
                        "`{template}` names one column for every joint: put `{{joint}}`, \
                         `{{index}}` or `{{number}}` in it"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The column `template` names for joint `name`, the `index`th.
    fn column(template: &str, name: &str, index: usize) -> String {
        template
            .replace("{joint}", name)
            .replace("{index}", &index.to_string())
            .replace("{number}", &(index + 1).to_string())
    }
}

/// A table's file format, by its name's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Csv,
    Parquet,
}

impl Format {
    /// The format `path` names (`.csv`, `.parquet`, any case); an error
    /// naming the file for anything else.
    pub fn of(path: &Path) -> Result<Format> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match extension.as_deref() {
            Some("csv") => Ok(Format::Csv),
            Some("parquet") => Ok(Format::Parquet),
            _ => Err(Error::bad_file(
                path,
                "expected a table of samples: a `.csv` or `.parquet` file",
            )),
        }
    }
}

/// A robot joint, as the table is read for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    pub name: String,
    /// Whether its position is an angle (`angles` applies).
    pub revolute: bool,
}

/// One table read: its samples' times (ns from its first) and what each
/// measured, in the robot's joint order and SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    pub stamps_ns: Vec<i64>,
    pub samples: Vec<Measured>,
    /// The step between samples the positions and velocities imply (s),
    /// when the joints move enough to say.
    pub implied_dt: Option<f64>,
}

/// Reads the table at `stored` as the trajectory of `joints` that
/// `columns` (validated) describe; `path` names it — its extension says
/// whether it is CSV or Parquet (`.csv`, `.parquet`), and every message
/// names it (an archived table is stored under its hash, named by its
/// dataset and file name). A gap longer than the `grid`'s `max_gap` is
/// refused where its gaps are errors, and takes no part in the rate check.
pub fn read(
    stored: &Path,
    path: &Path,
    columns: &Columns,
    joints: &[Joint],
    grid: &Grid,
) -> Result<Trajectory> {
    let bad = |what: String| Error::bad_file(path, what);
    let mut wanted: Vec<String> = Vec::new();
    if let Some(t) = &columns.time {
        wanted.push(t.clone());
    }
    for (i, j) in joints.iter().enumerate() {
        for template in [&columns.position, &columns.velocity, &columns.effort] {
            let column = Columns::column(template, &j.name, i);
            if wanted.contains(&column) {
                return Err(Error::Invalid(format!(
                    "ingest.table: `{column}` would be read twice (for joint `{}`): each \
                     quantity of each joint needs a column of its own",
                    j.name
                )));
            }
            wanted.push(column);
        }
    }
    let values = match Format::of(path)? {
        Format::Csv => read_csv(stored, path, &wanted)?,
        Format::Parquet => read_parquet(stored, path, &wanted)?,
    };
    let rows = values.first().map_or(0, Vec::len);
    if rows < 2 {
        return Err(bad(format!(
            "{rows} rows: a trajectory needs at least two samples"
        )));
    }
    let mut next = values.into_iter();
    let stamps_ns = match (&columns.time, columns.rate) {
        (Some(name), _) => {
            let times = next.next().expect("the time column first");
            stamps(path, name, &times, columns.time_unit)?
        }
        (None, Some(rate)) => (0..rows)
            .map(|k| (k as f64 * 1e9 / rate.get()).round() as i64)
            .collect(),
        (None, None) => unreachable!("validated: a time column or a rate"),
    };
    let mut samples = vec![Measured::default(); rows];
    for j in joints {
        let scale = match (j.revolute, columns.angles) {
            (true, Angles::Deg) => std::f64::consts::PI / 180.0,
            _ => 1.0,
        };
        let (q, qd, effort) = (
            next.next().expect("a position column"),
            next.next().expect("a velocity column"),
            next.next().expect("an effort column"),
        );
        for (k, s) in samples.iter_mut().enumerate() {
            s.q.push(q[k] * scale);
            s.qd.push(qd[k] * scale);
            s.effort.push(effort[k]);
        }
    }
    if grid.gaps == Gaps::Error {
        check_gaps(path, columns, &stamps_ns, grid.max_gap)?;
    }
    let implied_dt = check_rate(path, columns, &stamps_ns, &samples, grid.max_gap)?;
    Ok(Trajectory {
        stamps_ns,
        samples,
        implied_dt,
    })
}

/// `times` (in `unit`) as ns from the first, each after the one before.
fn stamps(path: &Path, column: &str, times: &[f64], unit: TimeUnit) -> Result<Vec<i64>> {
    let ns: Vec<i64> = times
        .iter()
        .map(|t| ((t - times[0]) * unit.seconds() * 1e9).round() as i64)
        .collect();
    for k in 1..ns.len() {
        if ns[k] <= ns[k - 1] {
            let how = match ns[k] == ns[k - 1] {
                true => "time stands still",
                false => "time goes backwards",
            };
            return Err(Error::bad_file(
                path,
                format!(
                    "column `{column}`, row {}: {how} ({} after {} on row {})",
                    k + 1,
                    times[k],
                    times[k - 1],
                    k
                ),
            ));
        }
    }
    Ok(ns)
}

/// How far the stated steps are from what the data imply: the scale s that
/// best explains the positions' changes by the mean of the velocities
/// around them over each pair's own step, Δq ≈ s q̄̇ Δt (least squares over
/// every joint and pair no more than `max_gap` apart; 1 when the stated
/// times are right). None when the joints barely move (mean speed under
/// 1e-3 rad/s or m/s); negative when the velocities oppose the motion.
pub fn rate_scale(samples: &[Measured], stamps_ns: &[i64], max_gap: f64) -> Option<f64> {
    let (mut cross, mut square, mut speed, mut n) = (0.0, 0.0, 0.0, 0usize);
    for (pair, stamps) in samples.windows(2).zip(stamps_ns.windows(2)) {
        let dt = (stamps[1] - stamps[0]) as f64 * 1e-9;
        if dt > max_gap {
            continue;
        }
        for j in 0..pair[0].q.len() {
            let dq = pair[1].q[j] - pair[0].q[j];
            let v = 0.5 * (pair[1].qd[j] + pair[0].qd[j]);
            cross += dq * v * dt;
            square += v * v * dt * dt;
            speed += v * v;
            n += 1;
        }
    }
    (n > 0 && speed / n as f64 > 1e-6).then(|| cross / square)
}

/// Refuses stated times (a time column, or a rate) that the data
/// contradict by more than [`RATE_TOLERANCE`], and velocities that oppose
/// the positions' change; returns the step the data imply (the median
/// stated step, scaled), when the joints move enough to say.
fn check_rate(
    path: &Path,
    columns: &Columns,
    stamps_ns: &[i64],
    samples: &[Measured],
    max_gap: f64,
) -> Result<Option<f64>> {
    let Some(scale) = rate_scale(samples, stamps_ns, max_gap) else {
        return Ok(None);
    };
    if scale <= 0.0 {
        return Err(Error::bad_file(
            path,
            format!(
                "the velocities ({}) oppose the positions' change ({}): a velocity column of the \
                 wrong sign, or columns swapped",
                columns.velocity, columns.position
            ),
        ));
    }
    let mut steps: Vec<i64> = stamps_ns.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_unstable();
    let stated = steps[steps.len() / 2] as f64 * 1e-9;
    let implied = stated * scale;
    if (scale - 1.0).abs() <= RATE_TOLERANCE {
        return Ok(Some(implied));
    }
    let says = match (&columns.time, columns.rate) {
        (Some(c), _) => format!("column `{c}` puts them {} apart (median)", ms(stated)),
        (None, Some(r)) => format!("rate = {} Hz puts them {} apart", r.get(), ms(stated)),
        (None, None) => unreachable!("validated"),
    };
    Err(Error::bad_file(
        path,
        format!(
            "the positions and velocities imply samples {} apart ({:.1} Hz; Δq against the \
             velocities, least squares over every joint), but {says}: check the time column's \
             unit, the rate, or the velocities' unit (more than {:.0}% apart)",
            ms(implied),
            1.0 / implied,
            RATE_TOLERANCE * 100.0
        ),
    ))
}

fn ms(seconds: f64) -> String {
    format!("{:.2} ms", seconds * 1e3)
}

/// The `wanted` columns of the CSV file at `stored`, named `path` (a header
/// row, then one row a sample), each as numbers.
fn read_csv(stored: &Path, path: &Path, wanted: &[String]) -> Result<Vec<Vec<f64>>> {
    let bad = |what: String| Error::bad_file(path, what);
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(stored)
        .map_err(|e| csv_error(path, e))?;
    let header = reader.headers().map_err(|e| csv_error(path, e))?.clone();
    let at: Vec<usize> = wanted
        .iter()
        .map(|w| {
            header.iter().position(|h| h == w).ok_or_else(|| {
                bad(format!(
                    "no column `{w}` (its columns: {})",
                    header.iter().collect::<Vec<_>>().join(", ")
                ))
            })
        })
        .collect::<Result<_>>()?;
    let mut values = vec![Vec::new(); wanted.len()];
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| csv_error(path, e))?;
        for ((column, &i), out) in wanted.iter().zip(&at).zip(values.iter_mut()) {
            let cell = record.get(i).unwrap_or("");
            let x: f64 = cell.parse().map_err(|_| {
                let what = match cell.is_empty() {
                    true => "empty".to_string(),
                    false => format!("`{cell}` is not a number"),
                };
                bad(format!("column `{column}`, row {}: {what}", row + 1))
            })?;
            out.push(finite(path, column, row, x)?);
        }
    }
    Ok(values)
}

fn csv_error(path: &Path, e: csv::Error) -> Error {
    match e.kind() {
        csv::ErrorKind::Io(_) => match e.into_kind() {
            csv::ErrorKind::Io(io) => Error::io(path, io),
            _ => unreachable!("matched an I/O error"),
        },
        _ => Error::bad_file(path, format!("not a CSV table: {e}")),
    }
}

/// `x` of `column`'s `row` (from 0), refused where it is not finite.
fn finite(path: &Path, column: &str, row: usize, x: f64) -> Result<f64> {
    match x.is_finite() {
        true => Ok(x),
        false => Err(Error::bad_file(
            path,
            format!(
                "column `{column}`, row {}: {x}, expected a finite number",
                row + 1
            ),
        )),
    }
}

/// The `wanted` columns of the Parquet file at `stored`, named `path`, each
/// of a numeric type and without nulls.
fn read_parquet(stored: &Path, path: &Path, wanted: &[String]) -> Result<Vec<Vec<f64>>> {
    let bad = |what: String| Error::bad_file(path, what);
    let file = File::open(stored).map_err(|e| Error::io(path, e))?;
    let builder = ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| bad(format!("not a Parquet table: {e}")))?;
    let schema = builder.schema().clone();
    for w in wanted {
        if schema.field_with_name(w).is_err() {
            let names: Vec<&str> = schema.fields().iter().map(|f| f.name().as_str()).collect();
            return Err(bad(format!(
                "no column `{w}` (its columns: {})",
                names.join(", ")
            )));
        }
    }
    let reader = builder
        .build()
        .map_err(|e| bad(format!("not a Parquet table: {e}")))?;
    let mut values = vec![Vec::new(); wanted.len()];
    for batch in reader {
        let batch = batch.map_err(|e| Error::damaged(path, e))?;
        for (column, out) in wanted.iter().zip(values.iter_mut()) {
            let array = batch.column_by_name(column).expect("checked in the schema");
            append(path, column, array, out)?;
        }
    }
    Ok(values)
}

/// Appends `array` (a column of `column`) to `out` as f64.
fn append(path: &Path, column: &str, array: &ArrayRef, out: &mut Vec<f64>) -> Result<()> {
    let first = out.len();
    let widened: Vec<Option<f64>> = match array.data_type() {
        DataType::Float64 => array.as_primitive::<Float64Type>().iter().collect(),
        DataType::Float32 => array
            .as_primitive::<Float32Type>()
            .iter()
            .map(|x| x.map(f64::from))
            .collect(),
        DataType::Int64 => array
            .as_primitive::<Int64Type>()
            .iter()
            .map(|x| x.map(|x| x as f64))
            .collect(),
        DataType::Int32 => array
            .as_primitive::<Int32Type>()
            .iter()
            .map(|x| x.map(f64::from))
            .collect(),
        other => {
            return Err(Error::bad_file(
                path,
                format!(
                    "column `{column}` holds {other}, not numbers (expected a float or integer column)"
                ),
            ));
        }
    };
    for (k, x) in widened.into_iter().enumerate() {
        let row = first + k;
        let x = x.ok_or_else(|| {
            Error::bad_file(
                path,
                format!("column `{column}`, row {}: missing (null)", row + 1),
            )
        })?;
        out.push(finite(path, column, row, x)?);
    }
    Ok(())
}

/// Refuses a gap between samples longer than `max_gap` (s), naming the
/// rows around it, where gaps are errors.
fn check_gaps(path: &Path, columns: &Columns, stamps_ns: &[i64], max_gap: f64) -> Result<()> {
    for (k, w) in stamps_ns.windows(2).enumerate() {
        let gap = (w[1] - w[0]) as f64 * 1e-9;
        if gap > max_gap {
            let column = columns.time.as_deref().unwrap_or("time");
            return Err(Error::bad_file(
                path,
                format!(
                    "column `{column}`, row {}: a gap of {gap:.3} s after row {}, longer than \
                     max_gap = {max_gap} s (set ingest.gaps = \"split\" to start a new run \
                     after a gap)",
                    k + 2,
                    k + 1
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arrow_array::{Float32Array, Float64Array, Int64Array, RecordBatch, StringArray};
    use parquet::arrow::ArrowWriter;

    use super::*;
    use crate::frames::Resample;

    fn grid(gaps: Gaps) -> Grid {
        Grid {
            frame_dt: 0.01,
            resample: Resample::Linear,
            max_gap: 0.05,
            gaps,
        }
    }

    fn joints() -> Vec<Joint> {
        vec![
            Joint {
                name: "a".into(),
                revolute: true,
            },
            Joint {
                name: "slide".into(),
                revolute: false,
            },
        ]
    }

    /// Rows of a trajectory sampled every `dt` s: joint j at q = sin(t + j),
    /// q̇ = cos(t + j) (times `velocity_scale`), effort 1 + j.
    fn rows(n: usize, dt: f64, velocity_scale: f64) -> Vec<[f64; 7]> {
        (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                let (a, b) = (t, t + 1.0);
                [
                    t,
                    a.sin(),
                    velocity_scale * a.cos(),
                    1.0,
                    b.sin(),
                    velocity_scale * b.cos(),
                    2.0,
                ]
            })
            .collect()
    }

    const HEADER: &str =
        "t,a.position,a.velocity,a.effort,slide.position,slide.velocity,slide.effort";

    fn csv(dir: &Path, name: &str, header: &str, rows: &[[f64; 7]]) -> std::path::PathBuf {
        let mut text = format!("{header}\n");
        for r in rows {
            let cells: Vec<String> = r.iter().map(|x| x.to_string()).collect();
            text += &cells.join(",");
            text += "\n";
        }
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    fn timed() -> Columns {
        Columns {
            time: Some("t".into()),
            ..Columns::default()
        }
    }

    #[test]
    fn a_csv_and_a_parquet_table_read_alike_and_their_rate_is_checked() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(200, 0.005, 1.0);
        let path = csv(dir.path(), "a.csv", HEADER, &data);
        let t = read(&path, &path, &timed(), &joints(), &grid(Gaps::Error)).unwrap();
        assert_eq!(t.stamps_ns.len(), 200);
        assert_eq!(t.stamps_ns[3], 15_000_000);
        assert_eq!(t.samples[7].q, [data[7][1], data[7][4]]);
        assert_eq!(t.samples[7].qd, [data[7][2], data[7][5]]);
        assert_eq!(t.samples[7].effort, [1.0, 2.0]);
        // Δq against the mean velocity: the trapezoid's step, to O(dt³).
        let implied = t.implied_dt.unwrap();
        assert!((implied - 0.005).abs() < 1e-7, "{implied}");

        // The same values in Parquet, the time as float32 and an effort as
        // integers: read alike (float32 widened exactly).
        let column = |i: usize| -> Vec<f64> { data.iter().map(|r| r[i]).collect() };
        let names: Vec<&str> = HEADER.split(',').collect();
        let mut arrays: Vec<(&str, ArrayRef)> = Vec::new();
        for (i, name) in names.iter().enumerate() {
            let array: ArrayRef = match i {
                0 => Arc::new(Float32Array::from(
                    column(0).iter().map(|&x| x as f32).collect::<Vec<_>>(),
                )),
                3 => Arc::new(Int64Array::from(vec![1i64; data.len()])),
                _ => Arc::new(Float64Array::from(column(i))),
            };
            arrays.push((name, array));
        }
        let batch = RecordBatch::try_from_iter(arrays).unwrap();
        let parquet = dir.path().join("a.parquet");
        let mut w =
            ArrowWriter::try_new(File::create(&parquet).unwrap(), batch.schema(), None).unwrap();
        w.write(&batch).unwrap();
        w.close().unwrap();
        let p = read(&parquet, &parquet, &timed(), &joints(), &grid(Gaps::Error)).unwrap();
        assert_eq!(p.samples, t.samples);
        let drift = p
            .stamps_ns
            .iter()
            .zip(&t.stamps_ns)
            .map(|(a, b)| (a - b).abs())
            .max()
            .unwrap();
        assert!(drift < 100, "float32 times within 100 ns: {drift}");

        // A declared rate instead of the time column.
        let rated = Columns {
            rate: Some(Positive(200.0)),
            ..Columns::default()
        };
        let r = read(&path, &path, &rated, &joints(), &grid(Gaps::Error)).unwrap();
        assert_eq!(r.stamps_ns, t.stamps_ns);
        // The wrong rate, or velocities in another unit, are refused with
        // the rate the data imply.
        let wrong = Columns {
            rate: Some(Positive(100.0)),
            ..Columns::default()
        };
        let text = read(&path, &path, &wrong, &joints(), &grid(Gaps::Error))
            .unwrap_err()
            .to_string();
        assert!(
            text.contains(
                "a.csv: the positions and velocities imply samples 5.00 ms apart (200.0 Hz"
            ) && text.contains("rate = 100 Hz puts them 10.00 ms apart"),
            "{text}"
        );
        let fast = csv(dir.path(), "fast.csv", HEADER, &rows(200, 0.005, 2.0));
        let text = read(&fast, &fast, &timed(), &joints(), &grid(Gaps::Error))
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("imply samples 2.50 ms apart")
                && text.contains("column `t` puts them 5.00 ms apart (median)"),
            "{text}"
        );
    }

    #[test]
    fn a_gap_takes_no_part_in_the_rate_and_a_velocity_of_the_wrong_sign_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        // 0.5 s missing after row 100, the arm moving through it.
        let data: Vec<[f64; 7]> = rows(300, 0.005, 1.0)
            .into_iter()
            .enumerate()
            .filter(|(k, _)| !(100..200).contains(k))
            .map(|(_, r)| r)
            .collect();
        let path = csv(dir.path(), "gap.csv", HEADER, &data);
        let t = read(&path, &path, &timed(), &joints(), &grid(Gaps::Split)).unwrap();
        assert!((t.implied_dt.unwrap() - 0.005).abs() < 1e-7);
        // Where gaps are refused, the gap is what the message names.
        let text = read(&path, &path, &timed(), &joints(), &grid(Gaps::Error))
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("row 101: a gap of 0.505 s after row 100"),
            "{text}"
        );
        let backwards = csv(dir.path(), "sign.csv", HEADER, &rows(200, 0.005, -1.0));
        let text = read(
            &backwards,
            &backwards,
            &timed(),
            &joints(),
            &grid(Gaps::Error),
        )
        .unwrap_err()
        .to_string();
        assert!(
            text.contains("the velocities ({joint}.velocity) oppose the positions' change"),
            "{text}"
        );
        // One column read as two quantities.
        let twice = Columns {
            velocity: "{joint}.position".into(),
            ..timed()
        };
        let text = read(&path, &path, &twice, &joints(), &grid(Gaps::Error))
            .unwrap_err()
            .to_string();
        assert!(text.contains("`a.position` would be read twice"), "{text}");
    }

    #[test]
    fn degrees_turn_revolute_joints_only_and_templates_name_the_columns() {
        let dir = tempfile::tempdir().unwrap();
        let data = rows(50, 0.01, 1.0);
        let header = "t,q1,v1,e1,q2,v2,e2";
        let path = csv(dir.path(), "d.csv", header, &data);
        let columns = Columns {
            position: "q{number}".into(),
            velocity: "v{number}".into(),
            effort: "e{number}".into(),
            angles: Angles::Deg,
            ..timed()
        };
        let t = read(&path, &path, &columns, &joints(), &grid(Gaps::Error)).unwrap();
        let rad = std::f64::consts::PI / 180.0;
        assert_eq!(t.samples[3].q, [data[3][1] * rad, data[3][4]]);
        assert_eq!(t.samples[3].qd, [data[3][2] * rad, data[3][5]]);
        // A template that names one column for all joints, and a table with
        // both a time column and a rate, are refused before any file is read.
        let one = Columns {
            effort: "effort".into(),
            ..timed()
        };
        assert_eq!(one.validate().unwrap_err().0, "effort");
        let both = Columns {
            rate: Some(Positive(100.0)),
            ..timed()
        };
        assert!(both.validate().unwrap_err().1.contains("not both"));
        assert!(
            Columns::default()
                .validate()
                .unwrap_err()
                .1
                .contains("rate")
        );
    }

    #[test]
    fn what_cannot_be_a_trajectory_is_named_by_file_column_and_row() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let data = rows(40, 0.01, 1.0);
        let fails = |path: &Path| {
            read(path, path, &timed(), &joints(), &grid(Gaps::Error))
                .unwrap_err()
                .to_string()
        };

        let missing = csv(
            d,
            "missing.csv",
            &HEADER.replace("slide.effort", "slide.force"),
            &data,
        );
        let text = fails(&missing);
        assert!(
            text.starts_with("")
                && text
                    .contains("missing.csv: no column `slide.effort` (its columns: t, a.position"),
            "{text}"
        );

        let mut backwards = data.clone();
        backwards[12][0] = backwards[10][0];
        let text = fails(&csv(d, "backwards.csv", HEADER, &backwards));
        assert!(
            text.contains(
                "backwards.csv: column `t`, row 13: time goes backwards (0.1 after 0.11 on row 12)"
            ),
            "{text}"
        );
        let mut still = data.clone();
        still[5][0] = still[4][0];
        assert!(fails(&csv(d, "still.csv", HEADER, &still)).contains("row 6: time stands still"));

        let mut nan = data.clone();
        nan[20][5] = f64::NAN;
        let text = fails(&csv(d, "nan.csv", HEADER, &nan));
        assert!(
            text.contains("nan.csv: column `slide.velocity`, row 21: NaN"),
            "{text}"
        );

        let words = d.join("words.csv");
        std::fs::write(
            &words,
            format!("{HEADER}\n0,1,2,3,4,5,6\n0.01,1,two,3,4,5,6\n"),
        )
        .unwrap();
        let text = fails(&words);
        assert!(
            text.contains("words.csv: column `a.velocity`, row 2: `two` is not a number"),
            "{text}"
        );

        let empty = d.join("empty.csv");
        std::fs::write(
            &empty,
            format!("{HEADER}\n0,1,2,3,4,5,6\n0.01,1,,3,4,5,6\n"),
        )
        .unwrap();
        assert!(fails(&empty).contains("column `a.velocity`, row 2: empty"));

        let short = d.join("short.csv");
        std::fs::write(&short, format!("{HEADER}\n0,1,2,3,4,5,6\n")).unwrap();
        assert!(fails(&short).contains("1 rows: a trajectory needs at least two samples"));

        let text_file = d.join("notes.txt");
        std::fs::write(&text_file, "hello").unwrap();
        assert!(
            fails(&text_file)
                .contains("notes.txt: expected a table of samples: a `.csv` or `.parquet` file")
        );

        let fake = d.join("fake.parquet");
        std::fs::write(&fake, "not parquet at all").unwrap();
        assert!(fails(&fake).contains("fake.parquet: not a Parquet table"));

        // Parquet: a null and a column of strings.
        let batch = RecordBatch::try_from_iter([
            (
                "t",
                Arc::new(Float64Array::from(vec![Some(0.0), None])) as ArrayRef,
            ),
            (
                "a.position",
                Arc::new(StringArray::from(vec!["x", "y"])) as ArrayRef,
            ),
        ])
        .unwrap();
        let bad = d.join("bad.parquet");
        let mut w =
            ArrowWriter::try_new(File::create(&bad).unwrap(), batch.schema(), None).unwrap();
        w.write(&batch).unwrap();
        w.close().unwrap();
        let only_time = vec!["t".to_string(), "a.position".to_string()];
        let text = read_parquet(&bad, &bad, &only_time)
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("bad.parquet: column `t`, row 2: missing (null)"),
            "{text}"
        );
        let text = read_parquet(&bad, &bad, &only_time[1..])
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("column `a.position` holds Utf8, not numbers"),
            "{text}"
        );

        // A gap, where gaps are errors.
        let stamps = [0, 10_000_000, 20_000_000, 300_000_000];
        let text = check_gaps(Path::new("g.csv"), &timed(), &stamps, 0.05)
            .unwrap_err()
            .to_string();
        assert!(text.contains("g.csv: column `t`, row 4: a gap of 0.280 s after row 3, longer than max_gap = 0.05 s"), "{text}");
    }
}
