//! The optional worker-thread cap of the stepping classes, and running their heavy calls
//! on it with the GIL released.

use pyo3::prelude::*;

use crate::errors::ParameterError;

/// `threads=None` runs on rayon's global pool; `threads=n` on a private pool of `n`.
/// (Results do not depend on it: the core's parallel loops are deterministic.)
pub struct Pool(Option<rayon::ThreadPool>);

impl Pool {
    pub fn new(threads: Option<usize>) -> PyResult<Self> {
        match threads {
            None => Ok(Self(None)),
            Some(0) => Err(ParameterError::new_err("threads must be ≥ 1")),
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map(|p| Self(Some(p)))
                .map_err(|e| ParameterError::new_err(e.to_string())),
        }
    }

    /// Runs `f` on the pool with the GIL released.
    pub fn run<T: Send>(&self, py: Python<'_>, f: impl FnOnce() -> T + Send) -> T {
        py.detach(|| match &self.0 {
            Some(p) => p.install(f),
            None => f(),
        })
    }
}
