//! The one convention for array arguments at the Python boundary (issue 36).
//!
//! Every array argument of the native module goes through `floats` or `indices`:
//!
//! - a float argument takes any float dtype (float16, float32, float64, …) in any layout
//!   (C or Fortran order, strided views) or anything `numpy.asarray` makes one of (nested
//!   lists); an array that already has the dtype the binding reads is read in place,
//!   whatever its strides, anything else is converted once with numpy's `astype` (float16
//!   and float32 to float64 exactly; float64 to float32 rounded to nearest, as
//!   `numpy.float32(x)` does);
//! - an index argument (faces, face_polygon, …) takes any integer dtype, the same way,
//!   and refuses a negative index or one beyond uint32.
//!
//! Anything else (a string or object array, booleans, complex numbers, integers where
//! floats are meant and the other way round, the wrong number of dimensions) is a
//! `ParameterError` naming the argument (in its message and its `name`) and saying what
//! it got. Shapes beyond the number
//! of dimensions are checked where the arrays are used.

use numpy::ndarray::Dimension;
use numpy::{
    Element, PyArray, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::argument_error;

/// Float argument `name` as a `T` array of `D`'s dimensions (see the module docs).
pub fn floats<'py, T: Element, D: Dimension>(
    name: &str,
    ob: &Bound<'py, PyAny>,
) -> PyResult<PyReadonlyArray<'py, T, D>> {
    if let Ok(a) = ob.cast::<PyArray<T, D>>() {
        return Ok(a.try_readonly()?);
    }
    let a = untyped(name, ob)?;
    if a.dtype().kind() != b'f' {
        return Err(wrong::<D>(name, "a float array (any float dtype)", &a));
    }
    typed(name, &a)
}

/// Index argument `name` as a uint32 array of `D`'s dimensions (see the module docs).
pub fn indices<'py, D: Dimension>(
    name: &str,
    ob: &Bound<'py, PyAny>,
) -> PyResult<PyReadonlyArray<'py, u32, D>> {
    if let Ok(a) = ob.cast::<PyArray<u32, D>>() {
        return Ok(a.try_readonly()?);
    }
    let a = untyped(name, ob)?;
    if !matches!(a.dtype().kind(), b'i' | b'u') {
        return Err(wrong::<D>(name, "an integer array (any integer dtype)", &a));
    }
    if !a.is_empty() {
        let min: i128 = a.call_method0("min")?.extract()?;
        if min < 0 {
            return Err(argument_error(
                name,
                format!("{name} must hold non-negative indices, got {min}"),
            ));
        }
        let max: i128 = a.call_method0("max")?.extract()?;
        if max > i128::from(u32::MAX) {
            return Err(argument_error(
                name,
                format!("{name} must hold indices that fit uint32, got {max}"),
            ));
        }
    }
    typed(name, &a)
}

/// `ob` as a numpy array (itself when it is one).
fn untyped<'py>(name: &str, ob: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = ob.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let a = ob
        .py()
        .import("numpy")?
        .call_method1("asarray", (ob,))
        .map_err(|e| {
            argument_error(
                name,
                format!("{name} must be an array, got a {}: {e}", type_name(ob)),
            )
        })?;
    Ok(a.cast_into::<PyUntypedArray>()?)
}

/// `a` (of an accepted kind) checked for its number of dimensions and converted to `T`.
fn typed<'py, T: Element, D: Dimension>(
    name: &str,
    a: &Bound<'py, PyUntypedArray>,
) -> PyResult<PyReadonlyArray<'py, T, D>> {
    if D::NDIM.is_some_and(|n| n != a.ndim()) {
        return Err(wrong::<D>(name, "an array", a));
    }
    let converted = a.call_method1("astype", (T::get_dtype(a.py()),))?;
    Ok(converted.cast_into::<PyArray<T, D>>()?.try_readonly()?)
}

/// The error for argument `name`, which must be `what` (with `D`'s dimensions).
fn wrong<D: Dimension>(name: &str, what: &str, a: &Bound<'_, PyUntypedArray>) -> PyErr {
    let dims = D::NDIM.map_or(String::new(), |n| format!(" with {n} dimensions"));
    let shape = shape(a.shape());
    let dtype = a
        .dtype()
        .str()
        .map_or_else(|_| "?".into(), |s| s.to_string());
    argument_error(
        name,
        format!("{name} must be {what}{dims}, got a {dtype} array of shape {shape}"),
    )
}

/// A shape as Python writes it: `(3,)`, `(169, 2)`.
pub fn shape(s: &[usize]) -> String {
    match s {
        [n] => format!("({n},)"),
        s => format!("{s:?}").replace('[', "(").replace(']', ")"),
    }
}

fn type_name(ob: &Bound<'_, PyAny>) -> String {
    ob.get_type()
        .name()
        .map_or_else(|_| "?".into(), |n| n.to_string())
}

/// The rows of a `(T, 3)` index array (its shape checked by the caller) as triples.
pub fn triples(a: &PyReadonlyArray<'_, u32, numpy::ndarray::Ix2>) -> Vec<[u32; 3]> {
    a.as_array()
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect()
}
