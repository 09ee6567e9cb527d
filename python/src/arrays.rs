//! numpy arrays in and out. Inputs must be 2-D float64 of the stated width; anything else is a
//! `CbdError` naming the argument. Any memory layout is read (a column slice `data[:, :6]` or a
//! transpose is how data arrive; it is copied in row order, value for value).

use crate::errors::cbd_error;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;

/// A matrix read from Python: row-major values and its row count.
pub struct Rows {
    pub values: Vec<f64>,
    pub rows: usize,
    pub cols: usize,
}

impl Rows {
    pub fn row(&self, r: usize) -> &[f64] {
        &self.values[r * self.cols..(r + 1) * self.cols]
    }

    pub fn to_vecs(&self) -> Vec<Vec<f64>> {
        (0..self.rows).map(|r| self.row(r).to_vec()).collect()
    }
}

/// `value` as an (n, `cols`) float64 matrix; `what` says what its columns are, for the message.
/// `answer_bytes_per_row`: what the call makes of each row (results, text), so that the copy and
/// the answer are checked against the memory this process may use before either is allocated — a
/// broadcast view of 10⁹ rows is a `CbdError`, not an abort of the interpreter.
pub fn matrix(name: &str, value: &Bound<'_, PyAny>, cols: usize, what: &str, answer_bytes_per_row: usize) -> PyResult<Rows> {
    let expected = format!("{name} must be a float64 numpy array of shape (n, {cols}) ({what})");
    let Ok(untyped) = value.cast::<PyUntypedArray>() else {
        let kind = value.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into());
        return Err(cbd_error(format!("{expected}; got a {kind} (np.asarray({name}, dtype=float) makes one)")));
    };
    let dtype = untyped.dtype().str().map(|s| s.to_string()).unwrap_or_else(|_| "?".into());
    if untyped.ndim() != 2 {
        return Err(cbd_error(format!("{expected}; got {} dimensions, shape {:?}", untyped.ndim(), untyped.shape())));
    }
    let Ok(array) = value.cast::<PyArray2<f64>>() else {
        return Err(cbd_error(format!("{expected}; got dtype {dtype} ({name}.astype(np.float64) converts it)")));
    };
    let shape = untyped.shape();
    if shape[1] != cols {
        return Err(cbd_error(format!("{expected}; got shape ({}, {})", shape[0], shape[1])));
    }
    // The copy (and a row-vector copy of it where a call needs one) and the answer.
    let bytes = shape[0] as f64 * (2.0 * 8.0 * cols as f64 + answer_bytes_per_row as f64);
    cbd_trainer::face::room_for(bytes, 0).map_err(|e| {
        crate::errors::memory_error(
            value.py(),
            format!(
                "{name}: an array of shape ({}, {cols}) {}; pass fewer rows at a time",
                shape[0],
                e.0.replacen("needs", "needs, read and answered,", 1)
            ),
        )
    })?;
    let readonly = array.try_readonly().map_err(|e| cbd_error(format!("{name}: {e}")))?;
    // `as_slice` also lends a Fortran-ordered array's memory (column-major): only a C-ordered one's
    // memory is its rows; any other is read in logical (row-major) order.
    let values = match readonly.as_slice() {
        Ok(slice) if untyped.is_c_contiguous() => slice.to_vec(),
        _ => readonly.as_array().iter().copied().collect(),
    };
    Ok(Rows { values, rows: shape[0], cols })
}

/// An (n, m) array of row-major `values`.
pub fn out2(py: Python<'_>, values: Vec<f64>, n: usize, m: usize) -> Bound<'_, PyArray2<f64>> {
    Array2::from_shape_vec((n, m), values).expect("n·m values").into_pyarray(py)
}

/// An (n, a, b) array of row-major `values`.
pub fn out3(py: Python<'_>, values: Vec<f64>, n: usize, a: usize, b: usize) -> Bound<'_, numpy::PyArray3<f64>> {
    Array3::from_shape_vec((n, a, b), values).expect("n·a·b values").into_pyarray(py)
}
