//! Fabrics: weave tiles and their homogenized tensors (core module `weave`).

use std::sync::Arc;

use numpy::ndarray::Ix3;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;

use crate::args;
use crate::errors::{ParameterError, to_py};
use madder::weave::{PairCoefficients, Tile, Weave};

fn weave_kind(name: &str) -> PyResult<Option<Weave>> {
    Ok(Some(match name.to_ascii_uppercase().as_str() {
        "PLAIN" => Weave::Plain,
        "TWILL21" => Weave::Twill21,
        "TWILL31" => Weave::Twill31,
        "SATIN5" => Weave::Satin5,
        "BASKET" => Weave::Basket,
        "CUSTOM" => return Ok(None),
        other => {
            return Err(ParameterError::new_err(format!(
                "unknown weave '{other}' (PLAIN, TWILL21, TWILL31, SATIN5, BASKET or CUSTOM)"
            )));
        }
    }))
}

/// The tile of a built-in weave, or of a custom `grid` (lines top row first: `W`/`w`
/// warp up/down, `F`/`f` weft up/down, `.` gap).
fn tile(weave: &str, grid: Option<&str>, gaps: bool) -> PyResult<Tile> {
    match (weave_kind(weave)?, grid) {
        (Some(w), _) => Ok(Tile::builtin(w, gaps)),
        (None, Some(g)) => Tile::parse(g).map_err(to_py),
        (None, None) => Err(ParameterError::new_err("a CUSTOM weave needs a grid")),
    }
}

fn coefficients(c: Option<[f64; 6]>) -> PairCoefficients {
    match c {
        None => PairCoefficients::default(),
        Some([gap_gap, weft_weft, warp_warp, gap_weft, gap_warp, weft_warp]) => PairCoefficients {
            gap_gap,
            weft_weft,
            warp_warp,
            gap_weft,
            gap_warp,
            weft_warp,
        },
    }
}

/// Rows of a weave's tile as text, top row first.
#[pyfunction]
#[pyo3(signature = (weave, grid=None, gaps=true))]
pub fn fabric_tile(weave: &str, grid: Option<&str>, gaps: bool) -> PyResult<Vec<String>> {
    let t = tile(weave, grid, gaps)?;
    let (w, h) = (t.width(), t.height());
    Ok((0..h)
        .rev()
        .map(|r| {
            t.cells()[r * w..(r + 1) * w]
                .iter()
                .map(|c| c.to_char())
                .collect()
        })
        .collect())
}

/// Effective (homogenized) tensor `[s11, s12, s22]` of a weave in the (weft, warp) basis,
/// from the pair `coefficients` (gap–gap, weft–weft, warp–warp, gap–weft, gap–warp,
/// weft–warp; the seed's table when omitted). Results are cached in the core.
#[pyfunction]
#[pyo3(signature = (weave, grid=None, coefficients=None, gaps=true))]
pub fn fabric_tensor<'py>(
    py: Python<'py>,
    weave: &str,
    grid: Option<&str>,
    coefficients: Option<[f64; 6]>,
    gaps: bool,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let t = tile(weave, grid, gaps)?;
    let cells =
        madder::weave::cell_tensors(&t, &self::coefficients(coefficients)).map_err(to_py)?;
    let eff = py
        .detach(|| madder::weave::homogenize_cached(t.width(), t.height(), &cells))
        .map_err(to_py)?;
    Ok(PyArray1::from_vec(py, eff.to_vec()))
}

/// Effective tensor of a tile of per-cell tensors, `tensors` `(H, W, 3)` (any float dtype), row 0
/// at the bottom (y = 0).
#[pyfunction]
pub fn homogenize<'py>(
    py: Python<'py>,
    tensors: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let tensors = args::floats::<f64, Ix3>("tensors", tensors)?;
    let a = tensors.as_array();
    let &[h, w, k] = a.shape() else {
        unreachable!()
    };
    if k != 3 {
        return Err(ParameterError::new_err(format!(
            "tensors must have shape (H, W, 3), got {:?}",
            a.shape()
        )));
    }
    let cells: Vec<[f64; 3]> = (0..h * w)
        .map(|i| std::array::from_fn(|c| a[[i / w, i % w, c]]))
        .collect();
    let eff = py
        .detach(|| madder::weave::homogenize_cached(w, h, &cells))
        .map_err(to_py)?;
    Ok(PyArray1::from_vec(py, eff.to_vec()))
}

/// The cell problem's correctors of a fabric's tile and its per-cell uptake (core
/// `weave::Corrector`): what `WeaveDetail` adds back to the texture. Made by
/// `fabric_corrector`.
#[pyclass(module = "madder", frozen)]
pub struct Corrector {
    pub(crate) inner: Arc<madder::weave::Corrector>,
}

/// A `(rows, cols)` float64 array of row-major values.
fn grid<'py>(py: Python<'py>, v: &[f64], cols: usize) -> Bound<'py, PyArray2<f64>> {
    PyArray1::from_slice(py, v)
        .reshape([v.len() / cols, cols])
        .expect("a whole number of rows")
}

#[pymethods]
impl Corrector {
    /// `(width, height)` of the tile in cells.
    #[getter]
    fn cells(&self) -> (usize, usize) {
        self.inner.cells()
    }
    /// Threads per tile along the weft and the warp.
    #[getter]
    fn threads(&self) -> (f64, f64) {
        let [x, y] = self.inner.threads();
        (x, y)
    }
    /// Corrector samples per cell side.
    #[getter]
    fn refine(&self) -> usize {
        self.inner.refine()
    }
    /// The prefilter's standard deviation in cells (0: none).
    #[getter]
    fn filter(&self) -> f64 {
        self.inner.filter()
    }
    /// `χ_x` (`i = 0`) or `χ_y` (`i = 1`) in tile cells, `(height·refine, width·refine)`
    /// float64, row 0 at the bottom (zero mean).
    fn samples<'py>(&self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyArray2<f64>>> {
        if i > 1 {
            return Err(ParameterError::new_err(format!(
                "i must be 0 or 1, got {i}"
            )));
        }
        let (w, _) = self.inner.cells();
        Ok(grid(py, self.inner.samples(i), w * self.inner.refine()))
    }
    /// Per-cell uptake factors, `(height, width)` float64, row 0 at the bottom (mean 1).
    fn uptake<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        grid(py, self.inner.uptake(), self.inner.cells().0)
    }
    /// `⟨(e_i + ∇χ_i)ᵀ a (e_j + ∇χ_j)⟩` as `[s11, s12, s22]`: the effective tensor of the
    /// corrector's discretization.
    #[getter]
    fn energy(&self) -> [f64; 3] {
        self.inner.energy()
    }

    fn __repr__(&self) -> String {
        let (w, h) = self.inner.cells();
        format!(
            "Corrector(cells=({w}, {h}), refine={})",
            self.inner.refine()
        )
    }
}

/// The corrector of a weave (arguments as `fabric_tensor`); cached in the core. A
/// built-in weave's tile holds its repeat of threads each way (a cell per thread, two
/// with gaps); a custom grid a thread per cell. `filter` > 0 prefilters it with a
/// Gaussian of that standard deviation in cells (core `Corrector::filtered`: what a
/// texel of a given footprint can hold).
#[pyfunction]
#[pyo3(signature = (weave, grid=None, coefficients=None, gaps=true, filter=0.0))]
pub fn fabric_corrector(
    py: Python<'_>,
    weave: &str,
    grid: Option<&str>,
    coefficients: Option<[f64; 6]>,
    gaps: bool,
    filter: f64,
) -> PyResult<Corrector> {
    let t = tile(weave, grid, gaps)?;
    let per = if weave_kind(weave)?.is_some() && gaps {
        2.0
    } else {
        1.0
    };
    let threads = [t.width() as f64 / per, t.height() as f64 / per];
    let c = self::coefficients(coefficients);
    let inner = py
        .detach(|| {
            let base = madder::weave::corrector_cached(&t, &c, threads)?;
            if filter == 0.0 {
                Ok(base)
            } else {
                base.filtered(filter).map(Arc::new)
            }
        })
        .map_err(to_py)?;
    Ok(Corrector { inner })
}

/// `(ratio, angle)` of a tensor's ellipse: major/minor eigenvalue ratio and the angle of
/// the major axis from the weft, radians.
#[pyfunction]
pub fn ellipse(tensor: [f64; 3]) -> (f64, f64) {
    madder::weave::ellipse(tensor)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fabric_tile, m)?)?;
    m.add_function(wrap_pyfunction!(fabric_tensor, m)?)?;
    m.add_function(wrap_pyfunction!(fabric_corrector, m)?)?;
    m.add_class::<Corrector>()?;
    m.add_function(wrap_pyfunction!(homogenize, m)?)?;
    m.add_function(wrap_pyfunction!(ellipse, m)?)?;
    Ok(())
}
