//! Python bindings of the madder core, importable as `madder._core`.
//!
//! This crate only converts: numpy arrays in (any float dtype for floats, any integer dtype
//! for indices, any layout: one convention, `args.rs`; copied into owned Rust data), numpy arrays
//! out (Rust vectors handed to numpy without a copy), core errors to typed Python
//! exceptions (`errors.rs`, the one place that maps them), and the GIL released around
//! every heavy call. One file per core module.

use pyo3::prelude::*;

mod angles;
mod args;
mod errors;
mod io;
mod lcs;
mod mesh;
mod motion_codec;
mod point_cache;
mod simulate;
mod stain;
mod texture;
mod threads;
mod weave;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // the core's defaults and thresholds Python needs (one definition, in the core)
    m.add("DEFAULT_DIFFUSION", madder::stain::DEFAULT_DIFFUSION)?;
    let [r, g, b] = madder::stain::DEFAULT_SOLUTE_COLOR;
    m.add("DEFAULT_SOLUTE_COLOR", (r, g, b))?;
    m.add("DEGENERATE_UV_REL", madder::ops::DEGENERATE_UV_REL)?;
    m.add("DYE_EXCESS_RANGE", madder::io::EXCESS_RANGE)?;
    errors::register(m)?;
    m.add_class::<mesh::Topology>()?;
    m.add_class::<mesh::Refinement>()?;
    m.add_function(wrap_pyfunction!(mesh::weft_directions, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::distances_within, m)?)?;
    m.add_class::<stain::DiffusionStepper>()?;
    m.add_class::<simulate::Simulator>()?;
    m.add_class::<io::CacheWriter>()?;
    m.add_class::<io::CacheReader>()?;
    m.add_function(wrap_pyfunction!(lcs::ftle, m)?)?;
    m.add_function(wrap_pyfunction!(lcs::ridges, m)?)?;
    m.add_function(wrap_pyfunction!(angles::encode_angles, m)?)?;
    m.add_function(wrap_pyfunction!(angles::decode_angles, m)?)?;
    weave::register(m)?;
    point_cache::register(m)?;
    texture::register(m)?;
    motion_codec::register(m)?;
    Ok(())
}
