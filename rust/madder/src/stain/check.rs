//! The checks of the parameters the stain simulator is given: each names the parameter
//! (and the vertex) that is out of range ([`crate::error::ParamError`]).

use crate::error::ParamError;

/// `value` finite and `ok`, else the error naming `name` and its `requirement`.
pub(crate) fn check_range(
    name: &'static str,
    value: f64,
    ok: bool,
    requirement: &'static str,
) -> Result<(), ParamError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(ParamError::OutOfRange {
            name,
            requirement,
            value,
        })
    }
}

/// `got` values where one per vertex, `expected`, are needed, else the error naming both.
pub(super) fn check_length(
    name: &'static str,
    expected: usize,
    got: usize,
) -> Result<(), ParamError> {
    if got == expected {
        Ok(())
    } else {
        Err(ParamError::Length {
            name,
            expected,
            got,
        })
    }
}

/// Every value finite and `≥ 0`, else the error names the first vertex that is not.
pub(super) fn check_each_nonnegative(name: &'static str, values: &[f64]) -> Result<(), ParamError> {
    check_each(name, values, "finite and ≥ 0", |x| {
        x.is_finite() && x >= 0.0
    })
}

/// Every value in `[0, 1]`, else the error names the first vertex that is not.
pub(super) fn check_each_unit(name: &'static str, values: &[f64]) -> Result<(), ParamError> {
    check_each(name, values, "in [0, 1]", |x| (0.0..=1.0).contains(&x))
}

/// Every value `ok`, else the error names the first vertex that is not and `requirement`.
fn check_each(
    name: &'static str,
    values: &[f64],
    requirement: &'static str,
    ok: impl Fn(f64) -> bool,
) -> Result<(), ParamError> {
    match values.iter().position(|&x| !ok(x)) {
        None => Ok(()),
        Some(index) => Err(ParamError::OutOfRangeAt {
            name,
            index,
            requirement,
            value: values[index],
        }),
    }
}
