//! Typed Python exceptions, mapped from the core error variants in one place.
//!
//! ```text
//! MadderError
//! ├── MeshError       (also a ValueError)  bad topology or positions; names face/vertex
//! ├── ParameterError  (also a ValueError)  out-of-range parameters
//! ├── FabricError     (also a ValueError)  a weave or cell tensor is invalid; names the cell
//! ├── SolveError                           a linear solve failed
//! └── CacheError      (also an OSError)    cache or PC2/MDD file missing, truncated or corrupt
//! ```

use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::{create_exception, import_exception};

create_exception!(
    madder,
    MadderError,
    PyException,
    "Base class of every Madder error."
);

// The subclasses need two bases (MadderError and a builtin), which `create_exception!`
// cannot express, so they are defined in `madder/_errors.py` and imported here.
import_exception!(madder._errors, MeshError);
import_exception!(madder._errors, ParameterError);
import_exception!(madder._errors, SolveError);
import_exception!(madder._errors, CacheError);
import_exception!(madder._errors, FabricError);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MadderError", m.py().get_type::<MadderError>())
}

/// Converts a core error into the matching Python exception.
pub fn to_py(e: impl Into<madder::Error>) -> PyErr {
    let e = e.into();
    let msg = e.to_string();
    match e {
        madder::Error::Mesh(_) => MeshError::new_err(msg),
        madder::Error::Param(_) => ParameterError::new_err(msg),
        madder::Error::Solve(_) => SolveError::new_err(msg),
        madder::Error::Cache(_) => CacheError::new_err(msg),
        madder::Error::PointCache(_) => CacheError::new_err(msg),
        madder::Error::Weave(_) => FabricError::new_err(msg),
    }
}
