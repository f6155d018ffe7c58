//! A trained model in Python: `Model(model_path, codebook_path)`, its
//! variables' names and ranges, and `predict` and `rollout` over NumPy
//! arrays — the stages' own prediction paths (a piecewise-linear model's
//! batched evaluation, a bit-forest's or threshold model's runtime, the
//! boosted trees' evaluation), rows split among threads with the GIL
//! released — the arguments read and the result written in place, so
//! another Python thread must not change them during the call (as with
//! NumPy's own functions that release it). The robust linear baseline is a
//! piecewise-linear model of one piece per output, and loads as one.

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use alnlab_aln::ModelKind;
use alnlab_aln::boosted::Kept;
use alnlab_aln::model::Base;
use alnlab_aln::pwl::predict::{Path, Predictor, Scratch, advance};
use alnlab_aln::runtime::{Runtime, Trained};
use alnlab_codes::Entry;
use alnlab_codes::codebook::{Quantizer, is_control};
use alnlab_common::Error;
use numpy::ndarray::{ArrayView2, ArrayView3, Axis, Ix2, Ix3, IxDyn};
use numpy::{
    PyArrayDyn, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::{arrays, invalid, raise, threads};

/// What predicts, borrowing the trained model it is made from.
enum Predicts<'a> {
    /// A piecewise-linear model's compiled trees.
    Piecewise(Predictor<'a>),
    /// A bit-forest's or threshold model's runtime, from levels to levels.
    Levels(Runtime<'a>),
    /// Boosted trees, with the learned variables' entries their changes
    /// advance.
    Boosted(&'a Kept, Vec<&'a Entry>),
}

/// The files a model is made from.
enum Files {
    /// A model file (`model.aln`, `linear.aln`) with its codebook (boxed:
    /// the larger by far).
    Aln(Box<Trained>),
    /// Boosted trees (`boosted.parquet`) with theirs.
    Boosted(Kept),
}

impl Files {
    /// The model's kind: an ALN's (`piecewise-linear`, …) or `boosted`.
    fn kind(&self) -> &'static str {
        match self {
            Files::Aln(t) => t.model.header.model.name(),
            Files::Boosted(_) => "boosted",
        }
    }
}

/// What predicts, and the buffers of earlier calls kept for the next:
/// making them costs as much as predicting one state.
struct Ready<'a> {
    predicts: Predicts<'a>,
    spare: Mutex<Vec<Work<'a>>>,
}

self_cell::self_cell!(
    /// A trained model kept together with what predicts with it.
    struct Loaded {
        owner: Files,
        #[not_covariant]
        dependent: Ready,
    }
);

/// A trained model of a run: predicts the next frame of its state
/// variables from the current one and the controls held over the frame.
#[pyclass(module = "alnlab._alnlab", frozen)]
pub struct Model {
    loaded: Loaded,
    model_path: PathBuf,
    codebook_path: PathBuf,
    /// The learned variables' names and quantizers, in the codebook's order.
    names: Vec<String>,
    quantizers: Vec<Quantizer>,
    /// The state variables (learned, not controls) and the controls, as
    /// indices among the learned variables.
    state: Vec<usize>,
    controls: Vec<usize>,
    /// A piecewise-linear model's outputs: the learned variable each
    /// writes, none for a control it predicts (the caller gives controls).
    writes: Vec<Option<usize>>,
}

impl Model {
    fn kind(&self) -> &'static str {
        self.loaded.borrow_owner().kind()
    }

    /// Checks that `x0` is B×D and `controls` B×H×U and finite; `frames`
    /// says whether the caller gave H (a rollout) or one frame, B×U, and
    /// `single` whether it gave one state, and one item of controls (each
    /// argument's shapes and indices are then reported without the batch
    /// dimension, as the caller wrote it).
    fn check(
        &self,
        x0: &ArrayView2<f64>,
        controls: &ArrayView3<f64>,
        frames: bool,
        (single, controls_single): (bool, bool),
    ) -> PyResult<()> {
        let (d, u) = (self.state.len(), self.controls.len());
        let names = |of: &[usize]| {
            of.iter()
                .map(|&v| self.names[v].as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        // A shape or index as the caller wrote it: without the batch where
        // one item was given, without H where one frame was.
        let shown = |index: &[usize], frame_axis: bool| {
            let mut index = index.to_vec();
            if frame_axis && !frames {
                index.remove(1);
            }
            arrays::tuple(&index, if frame_axis { controls_single } else { single })
        };
        // The argument's name: rollout's is `x0`, predict's `states`.
        let states = if frames { "x0" } else { "states" };
        if x0.ncols() != d {
            let expected = if single {
                format!("({d},)")
            } else {
                format!("(B, {d})")
            };
            return Err(invalid(format!(
                "{states}: expected shape {expected}, one value per state variable ({}), got {}",
                names(&self.state),
                shown(x0.shape(), false)
            )));
        }
        let (b, h, given) = controls.dim();
        if b != x0.nrows() || given != u {
            let expected = match (single, frames) {
                (true, true) => format!("(H, {u})"),
                (true, false) => format!("({u},)"),
                (false, true) => format!("({}, H, {u})", x0.nrows()),
                (false, false) => format!("({}, {u})", x0.nrows()),
            };
            return Err(invalid(format!(
                "controls: expected shape {expected} — {}a value per control ({}) — got {}",
                if single { "" } else { "a row per state, " },
                names(&self.controls),
                shown(&[b, h, given], true)
            )));
        }
        // A value the model can take: finite, and within its variable's
        // reach — no further outside the range the model learned than
        // that range is wide, beyond which it would extrapolate unchecked.
        let takes = |x: f64, v: usize| {
            let q = &self.quantizers[v];
            let width = q.max - q.min;
            (q.min - width..=q.max + width).contains(&x)
        };
        let all_taken = |a: Option<&[f64]>, of: &[usize]| {
            a.is_some_and(|a| a.iter().zip(of.iter().cycle()).all(|(&x, &v)| takes(x, v)))
        };
        // The indexed search only where a value is refused: it is slow.
        if all_taken(x0.as_slice(), &self.state) && all_taken(controls.as_slice(), &self.controls) {
            return Ok(());
        }
        let refused = |what: &str, index: String, x: f64, v: usize| {
            let name = &self.names[v];
            let q = &self.quantizers[v];
            invalid(match x.is_finite() {
                false => format!("{what}: not a finite number at index {index} (`{name}`)"),
                true => format!(
                    "{what}: `{name}` is {x:e} at index {index}, far outside what the model \
                     learned ({} to {}): more than that range's width beyond it, where the model \
                     would extrapolate unchecked",
                    short(q.min),
                    short(q.max)
                ),
            })
        };
        if let Some(((r, k), &x)) = x0
            .indexed_iter()
            .find(|(i, x)| !takes(**x, self.state[i.1]))
        {
            return Err(refused(states, shown(&[r, k], false), x, self.state[k]));
        }
        let control = |i: &(usize, usize, usize)| self.controls[i.2];
        if let Some(((r, f, c), &x)) = controls
            .indexed_iter()
            .find(|(i, x)| !takes(**x, control(i)))
        {
            return Err(refused(
                "controls",
                shown(&[r, f, c], true),
                x,
                self.controls[c],
            ));
        }
        Ok(())
    }

    /// The states from `x0` (B×D) under `controls` (B×H×U) into `out`:
    /// B×(H+1)×D values, row-major, the first frame `x0`'s — or, without
    /// `first`, B×H×D, the predicted frames only; on `threads` threads.
    fn roll(
        &self,
        x0: &[f64],
        controls: &[f64],
        horizon: usize,
        first: bool,
        threads: Option<usize>,
        out: &mut [f64],
    ) -> PyResult<()> {
        let (d, u) = (self.state.len(), self.controls.len());
        let rows = x0.len().checked_div(d).unwrap_or(0);
        let frames = horizon + usize::from(first);
        if rows == 0 {
            return Ok(());
        }
        let chunk = threads::chunk_rows(rows, threads);
        self.loaded.with_dependent(|_, ready| {
            let task = |at: usize, n: usize, out: &mut [f64]| {
                let x0 = &x0[at * d..(at + n) * d];
                let controls = &controls[at * horizon * u..(at + n) * horizon * u];
                let mut work = Work::take(self, ready, n);
                work.roll(self, ready, x0, controls, horizon, first, out);
                work.finish(ready);
            };
            match ready.predicts {
                // One task: no thread pool to hand it to and wait on.
                Predicts::Piecewise(_) | Predicts::Boosted(..) if chunk >= rows => {
                    task(0, rows, out)
                }
                Predicts::Piecewise(_) | Predicts::Boosted(..) => threads::run(threads, || {
                    out.par_chunks_mut(chunk * frames * d)
                        .enumerate()
                        .for_each(|(k, out)| task(k * chunk, chunk.min(rows - k * chunk), out));
                })?,
                // One row at a time, on this thread.
                Predicts::Levels(_) if rows < ONE_ROW_BELOW => task(0, rows, out),
                // The runtime spreads its own work over the threads.
                Predicts::Levels(_) => threads::run(threads, || task(0, rows, out))?,
            }
            Ok(())
        })
    }

    /// The states (B×D) rolled out under the controls (B×H×U), as
    /// [`Model::roll`] gives them, in an array of `shape` (the batch
    /// dimension left out where the caller gave one item): a new one, or
    /// `out`, checked before the work (see [`Model::check_out`]); as levels
    /// (uint16) on request. The inputs are copied where `out` is given: it
    /// may be one of them.
    #[allow(clippy::too_many_arguments)]
    fn answer<'py>(
        &self,
        py: Python<'py>,
        inputs: (arrays::Floats<'py>, arrays::Floats<'py>),
        horizon: usize,
        first: bool,
        threads: Option<usize>,
        shape: &[usize],
        levels: bool,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let asked = Asked {
            horizon,
            first,
            threads,
            shape,
            levels,
        };
        match out {
            Some(out) => {
                let copied = (inputs.0.values()?.to_vec(), inputs.1.values()?.to_vec());
                drop(inputs);
                self.write_out(py, (&copied.0, &copied.1), &asked, Some(out))
            }
            None => {
                let (x, c) = (inputs.0.values()?, inputs.1.values()?);
                self.write_out(py, (x, c), &asked, None)
            }
        }
    }

    /// [`Model::answer`]'s work, from inputs `x` and `c` that are not
    /// `out`'s memory.
    fn write_out<'py>(
        &self,
        py: Python<'py>,
        (x, c): (&[f64], &[f64]),
        asked: &Asked,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let Asked {
            horizon,
            first,
            threads,
            shape,
            levels,
        } = *asked;
        let layout = |e: numpy::AsSliceError| invalid(format!("internal layout error: {e}"));
        if levels {
            let array = match out {
                Some(out) => self.check_out(out, shape, true)?,
                None => PyArrayDyn::<u16>::zeros(py, IxDyn(shape), false).into_any(),
            };
            let mut values = vec![0.0; shape.iter().product()];
            py.detach(|| self.roll(x, c, horizon, first, threads, &mut values))?;
            let levels = self.levels(&values);
            let mut written = array.cast::<PyArrayDyn<u16>>()?.try_readwrite()?;
            written
                .as_slice_mut()
                .map_err(layout)?
                .copy_from_slice(&levels);
            drop(written);
            return Ok(array);
        }
        // The values written where they are returned, not copied there.
        let array = match out {
            Some(out) => self.check_out(out, shape, false)?,
            None => PyArrayDyn::<f64>::zeros(py, IxDyn(shape), false).into_any(),
        };
        let mut written = array.cast::<PyArrayDyn<f64>>()?.try_readwrite()?;
        let values = written.as_slice_mut().map_err(layout)?;
        py.detach(|| self.roll(x, c, horizon, first, threads, values))?;
        drop(written);
        Ok(array)
    }

    /// Checks that `out` is a writeable C-contiguous array of `shape`
    /// (the caller's: without the batch where one item was given),
    /// float64 or, with `levels`, uint16, and returns it; an `InputError`
    /// naming `out` otherwise.
    fn check_out<'py>(
        &self,
        out: &Bound<'py, PyAny>,
        shape: &[usize],
        levels: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let refused = || {
            let dtype = out.getattr("dtype").and_then(|d| Ok(d.str()?.to_string()));
            let found = out.getattr("shape").and_then(|s| Ok(s.str()?.to_string()));
            let got = match (dtype, found) {
                (Ok(d), Ok(s)) => format!("dtype {d}, shape {s}"),
                _ => out
                    .get_type()
                    .name()
                    .map_or("a value".into(), |n| format!("a {n}")),
            };
            invalid(format!(
                "out: expected a writeable C-contiguous {} array of shape {}, got {got}",
                if levels { "uint16" } else { "float64" },
                arrays::tuple(shape, false)
            ))
        };
        macro_rules! check {
            ($t:ty) => {{
                let array = out.cast::<PyArrayDyn<$t>>().map_err(|_| refused())?;
                if array.shape() != shape || !array.is_c_contiguous() {
                    return Err(refused());
                }
                // Writeable and not borrowed: an input's own array is
                // copied before `out` is written.
                array.try_readwrite().map_err(|_| refused())?;
            }};
        }
        match levels {
            true => check!(u16),
            false => check!(f64),
        }
        Ok(out.clone())
    }

    /// `values` (state variables last) as their levels.
    fn levels(&self, values: &[f64]) -> Vec<u16> {
        let d = self.state.len();
        values
            .iter()
            .enumerate()
            .map(|(i, &x)| self.quantizers[self.state[i % d]].level(x).0)
            .collect()
    }
}

/// Whether `path` is a Parquet file (boosted trees), not a model file.
fn is_parquet(path: &std::path::Path) -> PyResult<bool> {
    use std::io::Read;
    let mut magic = [0u8; 4];
    let mut file = std::fs::File::open(path).map_err(|e| raise(Error::io(path, e)))?;
    let read = file
        .read(&mut magic)
        .map_err(|e| raise(Error::io(path, e)))?;
    Ok(read == 4 && &magic == b"PAR1")
}

/// `x` to four decimals, for a message.
fn short(x: f64) -> String {
    format!("{}", (x * 1e4).round() / 1e4)
}

/// What a call asked for, beside its inputs: H frames (from the first, or
/// after it), on how many threads, the result's shape, values or levels.
#[derive(Clone, Copy)]
struct Asked<'a> {
    horizon: usize,
    first: bool,
    threads: Option<usize>,
    shape: &'a [usize],
    levels: bool,
}

/// The most values a call's buffers may hold and still be kept for the
/// next call (8 MB): a large batch's are freed with it.
const KEPT_VALUES: usize = 1 << 20;

/// Rows below which a bit-forest or threshold model predicts one row at a
/// time: a bit-sliced word's.
const ONE_ROW_BELOW: usize = 64;

/// Rows below which a piecewise-linear model predicts one row at a time
/// (every piece of a row, the test stage's fastest one-row path), not in
/// blocks of 32 rows that cost
/// the same for one row as for 32; both give the same values.
const PIECEWISE_ONE_ROW_BELOW: usize = 16;

/// One task's rows: their learned variables' values as columns
/// (`[variable][row]`), and the predictor's buffers.
struct Work<'m> {
    columns: Vec<f64>,
    rows: usize,
    scratch: Option<Scratch<'m>>,
    /// The outputs' next values, `[output][row]`.
    next: Vec<Vec<f64>>,
    /// One row's learned variables and its outputs' next values.
    row: Vec<f64>,
    row_next: Vec<f64>,
    /// One row's learned variables as boosted trees read them.
    features: Vec<f32>,
}

impl<'m> Work<'m> {
    /// Buffers for `rows` rows: an earlier call's, or new ones.
    fn take(model: &Model, ready: &Ready<'m>, rows: usize) -> Work<'m> {
        let mut work = spare(ready).pop().unwrap_or_else(|| {
            let outputs = model.writes.len();
            Work {
                columns: Vec::new(),
                rows: 0,
                scratch: match &ready.predicts {
                    Predicts::Piecewise(p) => Some(p.scratch()),
                    Predicts::Levels(_) | Predicts::Boosted(..) => None,
                },
                next: vec![Vec::new(); outputs],
                row: vec![0.0; model.names.len()],
                row_next: vec![0.0; outputs],
                features: match ready.predicts {
                    Predicts::Boosted(..) => vec![0.0; model.names.len()],
                    _ => Vec::new(),
                },
            }
        });
        let batched =
            matches!(ready.predicts, Predicts::Piecewise(_)) && rows >= PIECEWISE_ONE_ROW_BELOW;
        work.rows = rows;
        // Zeroed: a learned variable that is neither state nor control is
        // read as 0, whatever the last call left.
        work.columns.clear();
        work.columns.resize(model.names.len() * rows, 0.0);
        for next in &mut work.next {
            next.clear();
            next.resize(if batched { rows } else { 0 }, 0.0);
        }
        work
    }

    /// Gives the buffers back for the next call, unless a large call left
    /// them large: the model would hold that memory for its lifetime.
    fn finish(self, ready: &Ready<'m>) {
        if self.columns.capacity() <= KEPT_VALUES {
            spare(ready).push(self);
        }
    }

    fn column_mut(&mut self, v: usize) -> &mut [f64] {
        &mut self.columns[v * self.rows..(v + 1) * self.rows]
    }

    /// Sets `of` (indices among the learned variables) from `values`, rows
    /// of `stride` values whose first `of.len()` from `at` on are theirs.
    fn set(&mut self, of: &[usize], values: &[f64], stride: usize, at: usize) {
        for (k, &v) in of.iter().enumerate() {
            for (i, x) in self.column_mut(v).iter_mut().enumerate() {
                *x = values[i * stride + at + k];
            }
        }
    }

    /// Advances the state variables one frame.
    fn step(&mut self, model: &Model, ready: &Ready<'m>) {
        let rows = self.rows;
        match &ready.predicts {
            Predicts::Piecewise(_) if rows < PIECEWISE_ONE_ROW_BELOW => self.each_row(model, ready),
            Predicts::Boosted(..) => self.each_row(model, ready),
            Predicts::Piecewise(predictor) => {
                let scratch = self.scratch.as_mut().expect("made for a piecewise model");
                let columns: Vec<&[f64]> = self.columns.chunks(rows).collect();
                predictor.values(&columns, scratch, &mut self.next);
                for (write, next) in model.writes.iter().zip(&self.next) {
                    if let Some(v) = *write {
                        self.columns[v * rows..(v + 1) * rows].copy_from_slice(next);
                    }
                }
            }
            Predicts::Levels(runtime) => {
                let x: Vec<Vec<u16>> = self
                    .columns
                    .chunks(rows)
                    .zip(&model.quantizers)
                    .map(|(column, q)| column.iter().map(|&x| q.level(x).0).collect())
                    .collect();
                // Below a word of rows, coding and decoding bit-sliced
                // costs more than the one-row path; both give the same
                // levels.
                let next = if rows < ONE_ROW_BELOW {
                    runtime.one_row(&x, &runtime.encode(&x), None)
                } else {
                    runtime.levels(&x, None)
                };
                for &v in &model.state {
                    let q = model.quantizers[v];
                    for (x, &level) in self.column_mut(v).iter_mut().zip(&next[v]) {
                        *x = q.value(usize::from(level));
                    }
                }
            }
        }
    }

    /// Advances the state variables one frame, one row at a time: each
    /// row's learned variables read, its outputs predicted (a
    /// piecewise-linear model's plain path, or the boosted trees), the
    /// state variables among them written back.
    fn each_row(&mut self, model: &Model, ready: &Ready<'m>) {
        let rows = self.rows;
        for r in 0..rows {
            for (v, x) in self.row.iter_mut().enumerate() {
                *x = self.columns[v * rows + r];
            }
            match &ready.predicts {
                Predicts::Piecewise(predictor) => {
                    let scratch = self.scratch.as_mut().expect("made for a piecewise model");
                    predictor.next_values(&self.row, Path::Plain, scratch, &mut self.row_next);
                }
                Predicts::Boosted(kept, learned) => {
                    for (feature, &x) in self.features.iter_mut().zip(&self.row) {
                        *feature = x as f32;
                    }
                    let outputs = kept.boosted.outputs.iter().zip(&kept.variables);
                    for (next, (trees, &v)) in self.row_next.iter_mut().zip(outputs) {
                        let change = f64::from(trees.change(&self.features));
                        *next = advance(learned[v], self.row[v], change);
                    }
                }
                Predicts::Levels(_) => unreachable!("a bit model predicts through its runtime"),
            }
            for (write, &x) in model.writes.iter().zip(&self.row_next) {
                if let Some(v) = *write {
                    self.columns[v * rows + r] = x;
                }
            }
        }
    }

    /// Rolls these rows out: `x0` (rows×D) under `controls` (rows×H×U)
    /// into `out`: rows×(H+1)×D, the first frame `x0`'s, or without
    /// `first` rows×H×D.
    #[allow(clippy::too_many_arguments)]
    fn roll(
        &mut self,
        model: &Model,
        ready: &Ready<'m>,
        x0: &[f64],
        controls: &[f64],
        horizon: usize,
        first: bool,
        out: &mut [f64],
    ) {
        let (d, u) = (model.state.len(), model.controls.len());
        let (frames, at) = (horizon + usize::from(first), usize::from(first));
        self.set(&model.state, x0, d, 0);
        if first {
            for (r, row) in x0.chunks(d).enumerate() {
                out[r * frames * d..][..d].copy_from_slice(row);
            }
        }
        for h in 0..horizon {
            self.set(&model.controls, controls, horizon * u, h * u);
            self.step(model, ready);
            // Row by row: each row's frame is contiguous in `out`.
            let rows = self.rows;
            for r in 0..rows {
                let written = &mut out[(r * frames + h + at) * d..][..d];
                for (x, &v) in written.iter_mut().zip(&model.state) {
                    *x = self.columns[v * rows + r];
                }
            }
        }
    }
}

/// The spare buffers, whatever a panicking thread left them as (each is
/// overwritten before it is read).
fn spare<'r, 'm>(ready: &'r Ready<'m>) -> std::sync::MutexGuard<'r, Vec<Work<'m>>> {
    ready
        .spare
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

#[pymethods]
impl Model {
    /// Loads `model_path` — a run's `model.aln`, or its test stage's
    /// baselines `linear.aln` (the robust linear fit) and `boosted.parquet`
    /// — with the codebook it was trained with (`codebook.parquet`); an
    /// error names the file that does not fit.
    #[new]
    fn new(model_path: PathBuf, codebook_path: PathBuf) -> PyResult<Model> {
        // Absolute, so that a pickled model loads from any folder.
        let absolute = |p: PathBuf| std::fs::canonicalize(&p).unwrap_or(p);
        let (model_path, codebook_path) = (absolute(model_path), absolute(codebook_path));
        let files = match is_parquet(&model_path)? {
            true => Files::Boosted(Kept::read(&model_path, &codebook_path).map_err(raise)?),
            false => Files::Aln(Box::new(
                Trained::read(&model_path, &codebook_path).map_err(raise)?,
            )),
        };
        let (codebook, predicted) = match &files {
            Files::Aln(t) if t.model.header.base == Base::Nominal => {
                return Err(raise(Error::bad_file(
                    &model_path,
                    "is a hybrid (a learned correction on the nominal simulator's prediction), \
                     which predicts only with the simulator beside it: the Python package \
                     loads models of the dynamics (piecewise-linear, bit-forest, threshold, \
                     boosted)",
                )));
            }
            Files::Aln(t) => (&t.codebook, t.reads.iter().map(|r| r.variable).collect()),
            Files::Boosted(k) => (&k.codebook, k.variables.clone()),
        };
        let learned: Vec<_> = codebook.learned().collect();
        let names: Vec<String> = learned.iter().map(|e| e.variable.clone()).collect();
        let quantizers = learned.iter().map(|e| e.quantizer).collect();
        let (controls, state): (Vec<usize>, Vec<usize>) =
            (0..names.len()).partition(|&v| is_control(&names[v]));
        let writes: Vec<Option<usize>> = predicted
            .iter()
            .map(|&v| (!controls.contains(&v)).then_some(v))
            .collect::<Vec<_>>();
        let bits = match &files {
            Files::Aln(t) => match t.model.header.model {
                ModelKind::BitForest | ModelKind::Threshold => true,
                ModelKind::PiecewiseLinear => false,
            },
            Files::Boosted(_) => false,
        };
        if !bits && let Some(&v) = state.iter().find(|v| !writes.contains(&Some(**v))) {
            return Err(raise(Error::bad_file(
                &model_path,
                format!(
                    "does not predict `{}`, a state variable it reads: it cannot be rolled out",
                    names[v]
                ),
            )));
        }
        let loaded = Loaded::new(files, |files| Ready {
            predicts: match files {
                Files::Aln(t) => match t.model.header.model {
                    ModelKind::PiecewiseLinear => {
                        let learned: Vec<_> = t.codebook.learned().collect();
                        // The compiled boxes speed only the compiled one-row
                        // path, which this package does not take: no points.
                        Predicts::Piecewise(Predictor::new(
                            &t.model.pieces,
                            &t.reads,
                            &learned,
                            &[],
                        ))
                    }
                    ModelKind::BitForest | ModelKind::Threshold => Predicts::Levels(
                        t.runtime()
                            .expect("a bit-forest or threshold model has a level runtime"),
                    ),
                },
                Files::Boosted(k) => Predicts::Boosted(k, k.codebook.learned().collect()),
            },
            spare: Mutex::new(Vec::new()),
        });
        Ok(Model {
            loaded,
            model_path,
            codebook_path,
            names,
            quantizers,
            state,
            controls,
            writes,
        })
    }

    /// The model's kind: `piecewise-linear` (the robust linear fit is one,
    /// of one piece per output), `bit-forest`, `threshold` or `boosted`.
    #[getter(kind)]
    fn kind_name(&self) -> &'static str {
        self.kind()
    }

    /// The state variables' names (D), in the columns' order.
    #[getter]
    fn state_names(&self) -> Vec<String> {
        self.state.iter().map(|&v| self.names[v].clone()).collect()
    }

    /// The controls' names (U): joint efforts `tau.<joint>` or hinge
    /// torques `g.<link>.<axis>`, held over a frame.
    #[getter]
    fn control_names(&self) -> Vec<String> {
        self.controls
            .iter()
            .map(|&v| self.names[v].clone())
            .collect()
    }

    /// Each variable's range and levels, the controls' too: a list of
    /// `(name, (min, max, levels))` in the codebook's order; level k
    /// stands for min + (max − min)·k/(levels − 1).
    #[getter]
    fn ranges(&self) -> Vec<(String, (f64, f64, usize))> {
        self.names
            .iter()
            .zip(&self.quantizers)
            .map(|(n, q)| (n.clone(), (q.min, q.max, q.levels)))
            .collect()
    }

    /// Pickled as its files' absolute paths, loaded again (their formats
    /// checked, as at any load) on unpickling: a model moves between
    /// processes on one machine, or wherever the same files are.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (PathBuf, PathBuf))> {
        let model = slf.get();
        Ok((
            slf.get_type().into_any(),
            (model.model_path.clone(), model.codebook_path.clone()),
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "Model({}, {} state variables, {} controls, {})",
            self.kind(),
            self.state.len(),
            self.controls.len(),
            self.model_path.display()
        )
    }

    /// The next states (B×D) from `states` (B×D) under `controls` (B×U),
    /// as values or, with `levels`, their levels (uint16); any array-like
    /// of real numbers, one state (D) and its controls (U) giving one next
    /// state (D).
    #[pyo3(signature = (states, controls, *, levels = false, threads = None, out = None))]
    #[allow(clippy::too_many_arguments)]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
        controls: &Bound<'py, PyAny>,
        levels: bool,
        threads: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let d = self.state.len();
        let states = arrays::floats(states, "states", 2, || format!("(B, {d})"))?;
        let controls = arrays::floats(controls, "controls", 2, || {
            format!("(B, {})", self.controls.len())
        })?;
        let threads = thread_count(threads)?;
        let single = states.single;
        let (x0, c) = (states.view::<Ix2>()?, controls.view::<Ix2>()?);
        // One frame of controls: B×1×U.
        self.check(
            &x0,
            &c.insert_axis(Axis(1)),
            false,
            (single, controls.single),
        )?;
        let shape: &[usize] = &[x0.nrows(), d][usize::from(single)..];
        let inputs = (states, controls);
        self.answer(py, inputs, 1, false, threads, shape, levels, out)
    }

    /// The states over `H` frames (B×(H+1)×D, the first `x0`) from `x0`
    /// (B×D) under `controls` (B×H×U), each frame predicted from the last
    /// prediction; as values or, with `levels`, their levels (uint16). One
    /// state (D) under H frames of controls (H×U) gives one path
    /// ((H+1)×D).
    #[pyo3(signature = (x0, controls, *, levels = false, threads = None, out = None))]
    #[allow(clippy::too_many_arguments)]
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        x0: &Bound<'py, PyAny>,
        controls: &Bound<'py, PyAny>,
        levels: bool,
        threads: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let d = self.state.len();
        let x0 = arrays::floats(x0, "x0", 2, || format!("(B, {d})"))?;
        let controls = arrays::floats(controls, "controls", 3, || {
            format!("(B, H, {})", self.controls.len())
        })?;
        let threads = thread_count(threads)?;
        let single = x0.single;
        let (x, c) = (x0.view::<Ix2>()?, controls.view::<Ix3>()?);
        self.check(&x, &c, true, (single, controls.single))?;
        let (b, horizon, _) = c.dim();
        let shape: &[usize] = &[b, horizon + 1, d][usize::from(single)..];
        self.answer(
            py,
            (x0, controls),
            horizon,
            true,
            threads,
            shape,
            levels,
            out,
        )
    }
}

/// `threads`: a whole number of at least 1, or `None` for all.
pub(crate) fn thread_count(threads: Option<&Bound<'_, PyAny>>) -> PyResult<Option<usize>> {
    arrays::count(threads, "threads", 1)?
        .map(|n| usize::try_from(n).map_err(|_| invalid(format!("threads: {n} is too many"))))
        .transpose()
}

/// The Rust batched path a rollout is measured against: the piecewise
/// model's candidates advanced as the plan stage advances them
/// (controls set, [`Predictor::values`], the predicted columns written
/// back), on Rust-owned columns, one thread, `repeats` times. Returns
/// each repeat's nanoseconds per predicted state (B·H states).
#[pyfunction]
#[pyo3(signature = (model, x0, controls, repeats = 7))]
pub fn reference_rollout_ns(
    py: Python<'_>,
    model: &Model,
    x0: PyReadonlyArray2<'_, f64>,
    controls: PyReadonlyArray3<'_, f64>,
    repeats: usize,
) -> PyResult<Vec<f64>> {
    let (x0, c) = (x0.as_array(), controls.as_array());
    model.check(&x0, &c, true, (false, false))?;
    let (b, horizon, u) = c.dim();
    let d = model.state.len();
    let x0: Vec<f64> = x0.iter().copied().collect();
    let c: Vec<f64> = c.iter().copied().collect();
    py.detach(|| {
        model.loaded.with_dependent(|_, ready| {
            let Predicts::Piecewise(predictor) = &ready.predicts else {
                return Err(invalid("the reference path is a piecewise-linear model's"));
            };
            threads::run(Some(1), || {
                let mut scratch = predictor.scratch();
                let mut columns = vec![0.0; model.names.len() * b];
                let mut next = vec![vec![0.0; b]; model.writes.len()];
                (0..repeats)
                    .map(|_| {
                        let start = Instant::now();
                        for (k, &v) in model.state.iter().enumerate() {
                            for (i, x) in columns[v * b..(v + 1) * b].iter_mut().enumerate() {
                                *x = x0[i * d + k];
                            }
                        }
                        for h in 0..horizon {
                            for (k, &v) in model.controls.iter().enumerate() {
                                for (i, x) in columns[v * b..(v + 1) * b].iter_mut().enumerate() {
                                    *x = c[(i * horizon + h) * u + k];
                                }
                            }
                            let view: Vec<&[f64]> = columns.chunks(b).collect();
                            predictor.values(&view, &mut scratch, &mut next);
                            for (write, next) in model.writes.iter().zip(&next) {
                                if let Some(v) = *write {
                                    columns[v * b..(v + 1) * b].copy_from_slice(next);
                                }
                            }
                        }
                        std::hint::black_box(&columns);
                        start.elapsed().as_nanos() as f64 / (b * horizon).max(1) as f64
                    })
                    .collect()
            })
        })
    })
}

/// The Rust one-row path a one-state `predict` is measured against: the
/// piecewise model's plain path on one row (every piece; what `predict`
/// takes below [`PIECEWISE_ONE_ROW_BELOW`] rows), `calls` times on this
/// thread, `repeats` times. Returns each repeat's nanoseconds a call.
#[pyfunction]
#[pyo3(signature = (model, state, controls, calls = 2000, repeats = 7))]
pub fn reference_predict_ns(
    py: Python<'_>,
    model: &Model,
    state: PyReadonlyArray1<'_, f64>,
    controls: PyReadonlyArray1<'_, f64>,
    calls: usize,
    repeats: usize,
) -> PyResult<Vec<f64>> {
    let (state, controls) = (state.as_array(), controls.as_array());
    let (d, u) = (model.state.len(), model.controls.len());
    if state.len() != d || controls.len() != u {
        return Err(invalid(format!(
            "expected a state of {d} values and {u} controls, got {} and {}",
            state.len(),
            controls.len()
        )));
    }
    let mut row = vec![0.0; model.names.len()];
    for (&v, &x) in model.state.iter().zip(state.iter()) {
        row[v] = x;
    }
    for (&v, &x) in model.controls.iter().zip(controls.iter()) {
        row[v] = x;
    }
    py.detach(|| {
        model.loaded.with_dependent(|_, ready| {
            let Predicts::Piecewise(predictor) = &ready.predicts else {
                return Err(invalid("the reference path is a piecewise-linear model's"));
            };
            let mut scratch = predictor.scratch();
            let mut next = vec![0.0; model.writes.len()];
            Ok((0..repeats)
                .map(|_| {
                    let start = Instant::now();
                    for _ in 0..calls {
                        predictor.next_values(
                            std::hint::black_box(&row),
                            Path::Plain,
                            &mut scratch,
                            &mut next,
                        );
                    }
                    std::hint::black_box(&next);
                    start.elapsed().as_nanos() as f64 / calls.max(1) as f64
                })
                .collect())
        })
    })
}
