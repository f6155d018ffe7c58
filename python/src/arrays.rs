//! Arguments as Python code passes them: any array-like of real numbers —
//! float32 (what gymnasium's spaces and torch give), ints, bools, nested
//! lists — cast to C-contiguous float64, a single item one dimension short
//! taken as a batch of one; whole-number arguments of any Python int. A
//! bad one is an `InputError` naming the argument, with the shape and
//! dtype expected.

use numpy::ndarray::{ArrayView, Axis, Dimension};
use numpy::{PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::invalid;

/// An argument as C-contiguous float64, and whether it was a single item
/// (one dimension short of a batch), which a result gives back unbatched.
pub struct Floats<'py> {
    array: PyReadonlyArrayDyn<'py, f64>,
    pub single: bool,
}

impl Floats<'_> {
    /// The argument as a batch of `D` dimensions (a single item as a batch
    /// of one).
    pub fn view<D: Dimension>(&self) -> PyResult<ArrayView<'_, f64, D>> {
        let array = self.array.as_array();
        let array = match self.single {
            true => array.insert_axis(Axis(0)),
            false => array,
        };
        array
            .into_dimensionality()
            .map_err(|e| invalid(format!("internal shape error: {e}")))
    }

    /// The argument's values in row-major order.
    pub fn values(&self) -> PyResult<&[f64]> {
        self.array
            .as_slice()
            .map_err(|e| invalid(format!("internal layout error: {e}")))
    }
}

/// `value` as a C-contiguous float64 array of `ndim` dimensions, the first
/// a batch (`shape` says what is expected, as `(B, D)`, asked only for a
/// message); a single item of `ndim - 1` dimensions is taken as a batch of
/// one.
pub fn floats<'py>(
    value: &Bound<'py, PyAny>,
    argument: &str,
    ndim: usize,
    shape: impl Fn() -> String,
) -> PyResult<Floats<'py>> {
    // The common case, a C-contiguous float64 batch or single item, as it
    // is.
    if let Ok(array) = value.cast::<PyArrayDyn<f64>>()
        && array.is_c_contiguous()
        && (array.ndim() == ndim || array.ndim() + 1 == ndim)
    {
        return Ok(Floats {
            single: array.ndim() < ndim,
            array: array.try_readonly()?,
        });
    }
    let py = value.py();
    let numpy = py.import("numpy")?;
    let expected = format!(
        "an array of real numbers of shape {} (cast to float64)",
        shape()
    );
    let array = numpy.call_method1("asarray", (value,)).map_err(|e| {
        if e.is_instance_of::<PyValueError>(py) || e.is_instance_of::<PyTypeError>(py) {
            invalid(format!(
                "{argument}: expected {expected}, got {} that NumPy cannot make an array of: {e}",
                type_name(value)
            ))
        } else {
            e
        }
    })?;
    let dtype = array.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "b" | "i" | "u" | "f") {
        return Err(invalid(format!(
            "{argument}: expected {expected}, got dtype {}",
            dtype.str()?
        )));
    }
    let given: usize = array.getattr("ndim")?.extract()?;
    let single = given + 1 == ndim;
    if given != ndim && !single {
        let found: Vec<usize> = array.getattr("shape")?.extract()?;
        return Err(invalid(format!(
            "{argument}: expected {expected} (or one item of it, one dimension fewer), got shape \
             {found:?}"
        )));
    }
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", numpy.getattr("float64")?)?;
    let array = numpy.call_method("ascontiguousarray", (array,), Some(&kwargs))?;
    Ok(Floats {
        array: array.extract()?,
        single,
    })
}

/// A whole-number argument of at least `least` (`None` stays `None`): any
/// Python int (or NumPy integer); anything else, or less, an `InputError`
/// naming it.
pub fn count(
    value: Option<&Bound<'_, PyAny>>,
    argument: &str,
    least: u64,
) -> PyResult<Option<u64>> {
    let Some(value) = value.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    let refused = || {
        invalid(format!(
            "{argument}: expected a whole number of at least {least}, got {}",
            value
                .repr()
                .map_or_else(|_| type_name(value), |r| r.to_string())
        ))
    };
    if value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(refused());
    }
    // A Python int, the common case, without a call into Python.
    if value.is_instance_of::<pyo3::types::PyInt>() {
        return match value.extract::<i128>() {
            Ok(n) if n >= i128::from(least) => u64::try_from(n).map(Some).map_err(|_| refused()),
            _ => Err(refused()),
        };
    }
    let py = value.py();
    let numpy_bool = py.import("numpy")?.getattr("bool_")?;
    if value.is_instance(&numpy_bool)? {
        return Err(refused());
    }
    let index = py
        .import("operator")?
        .call_method1("index", (value,))
        .map_err(|_| refused())?;
    match index.extract::<i128>() {
        Ok(n) if n >= i128::from(least) => u64::try_from(n).map(Some).map_err(|_| refused()),
        _ => Err(refused()),
    }
}

/// `shape` (or an index) as Python writes a tuple — `(5, 3)`, `(3,)` —
/// without its first dimension where the caller gave one item, not a
/// batch.
pub fn tuple(shape: &[usize], single: bool) -> String {
    let kept = if single {
        &shape[1.min(shape.len())..]
    } else {
        shape
    };
    match kept {
        [one] => format!("({one},)"),
        kept => {
            let items: Vec<String> = kept.iter().map(usize::to_string).collect();
            format!("({})", items.join(", "))
        }
    }
}

/// The name of `value`'s type, for messages.
fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map_or_else(|_| "a value".into(), |n| format!("a {n}"))
}
