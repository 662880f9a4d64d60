//! `encode_angles` and `decode_angles`: the angle-based surface representation (core module
//! `angles`, seed ch. 3). Conversion only; the GIL is released around the core calls.

use glam::DVec3;
use numpy::ndarray::{Ix1, Ix2};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use madder::AngleError;
use madder::angles::{AngleMesh, Angles, Placement, ReconstructOptions};

use crate::args;
use crate::errors::{ParameterError, to_py};

fn shape_error(name: &str, expected: &str, got: &[usize]) -> PyErr {
    to_py(AngleError::Shape {
        name: name.into(),
        expected: expected.into(),
        got: format!("{got:?}").replace('[', "(").replace(']', ")"),
    })
}

fn faces_of(faces: &Bound<'_, PyAny>) -> PyResult<Vec<[u32; 3]>> {
    let faces = args::indices::<Ix2>("faces", faces)?;
    let shape = faces.shape();
    if shape[1] != 3 || shape[0] == 0 {
        return Err(shape_error("faces", "(F, 3) with F > 0", shape));
    }
    Ok(args::triples(&faces))
}

fn rows3(name: &str, a: &Bound<'_, PyAny>, n: Option<usize>) -> PyResult<Vec<DVec3>> {
    let a: PyReadonlyArray2<'_, f64> = args::floats(name, a)?;
    let shape = a.shape();
    if shape[1] != 3 || n.is_some_and(|n| n != shape[0]) {
        let expected = n.map_or("(N, 3)".to_string(), |n| format!("({n}, 3)"));
        return Err(shape_error(name, &expected, shape));
    }
    Ok(a.as_array()
        .rows()
        .into_iter()
        .map(|r| DVec3::new(r[0], r[1], r[2]))
        .collect())
}

/// The vertex count of a mesh whose every vertex is used: the largest index + 1.
fn vertex_count(faces: &[[u32; 3]]) -> usize {
    faces.iter().flatten().max().map_or(0, |&m| m as usize + 1)
}

/// Corner angles `(F, 3)`, signed dihedral angles `(E,)` and the interior edges `(E, 2)`
/// (`a < b`, the dihedrals' order) of the mesh `faces` at `positions`.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn encode_angles<'py>(
    py: Python<'py>,
    faces: &Bound<'py, PyAny>,
    positions: &Bound<'py, PyAny>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<u32>>,
)> {
    let tris = faces_of(faces)?;
    let pos = rows3("positions", positions, None)?;
    let n = pos.len();
    let (angles, edges) = py
        .detach(|| {
            let mesh = AngleMesh::new(n, tris)?;
            let a = mesh.encode(&pos)?;
            Ok::<_, AngleError>((a, mesh.interior_edges()))
        })
        .map_err(to_py)?;
    let f = angles.corners.len();
    let e = edges.len();
    let corners = PyArray1::from_vec(py, angles.corners.concat()).reshape([f, 3])?;
    let dihedrals = PyArray1::from_vec(py, angles.dihedrals);
    let edges = PyArray1::from_vec(py, edges.concat()).reshape([e, 2])?;
    Ok((corners, dihedrals, edges))
}

/// Vertex positions `(N, 3)` from corner angles `(F, 3)` and dihedral angles `(E,)`.
/// `previous` (the previous frame's positions, `(N, 3)`) warm-starts the spectral method
/// and is what the tracked one follows (it falls back to the warm spectral method when its
/// rotations do not settle); without it the tracked method starts from rotations composed
/// along a tree of the faces (falling back to the spectral method's start, then to the
/// spectral method itself).
#[pyfunction]
#[pyo3(signature = (faces, corners, dihedrals, *, reference_face=None, reference_positions=None, refine_iterations=0, method="spectral", previous=None))]
#[allow(clippy::too_many_arguments)]
pub fn decode_angles<'py>(
    py: Python<'py>,
    faces: &Bound<'py, PyAny>,
    corners: &Bound<'py, PyAny>,
    dihedrals: &Bound<'py, PyAny>,
    reference_face: Option<usize>,
    reference_positions: Option<&Bound<'py, PyAny>>,
    refine_iterations: usize,
    method: &str,
    previous: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let tris = faces_of(faces)?;
    let corners: PyReadonlyArray2<'_, f64> = args::floats("corners", corners)?;
    let cs = corners.shape();
    if cs[1] != 3 {
        return Err(shape_error("corners", &format!("({}, 3)", tris.len()), cs));
    }
    let corners: Vec<[f64; 3]> = corners
        .as_array()
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect();
    let dihedrals = args::floats::<f64, Ix1>("dihedrals", dihedrals)?
        .as_array()
        .to_vec();
    let placement = match (reference_face, reference_positions) {
        (None, None) => None,
        (Some(face), Some(p)) => {
            let p = rows3("reference_positions", p, Some(3))?;
            Some(Placement {
                face,
                positions: [p[0], p[1], p[2]],
            })
        }
        _ => {
            return Err(to_py(AngleError::PlacementIncomplete));
        }
    };
    if !matches!(method, "spectral" | "tracked" | "sequential") {
        return Err(to_py(AngleError::Method {
            method: method.into(),
        }));
    }
    let n = vertex_count(&tris);
    let previous = previous
        .map(|p| rows3("previous", p, Some(n)))
        .transpose()?;
    if method == "sequential" && previous.is_some() {
        return Err(ParameterError::new_err(
            "previous= is not used by method 'sequential' (only 'spectral' and 'tracked' start from it)",
        ));
    }
    let x = py
        .detach(|| {
            let mesh = AngleMesh::new(n, tris)?;
            let angles = Angles { corners, dihedrals };
            let opts = ReconstructOptions {
                refine_iterations,
                placement,
                ..Default::default()
            };
            match (method, previous.as_deref()) {
                ("sequential", _) => mesh.sequential(&angles, opts.placement.as_ref()),
                ("tracked", Some(prev)) => mesh
                    .reconstruct_following(&angles, prev, prev, &opts)
                    .map(|r| r.positions),
                ("tracked", None) => mesh.reconstruct_cold(&angles, &opts),
                (_, Some(prev)) => mesh
                    .reconstruct_warm(&angles, prev, &opts)
                    .map(|r| r.positions),
                _ => mesh.reconstruct(&angles, &opts).map(|r| r.positions),
            }
        })
        .map_err(to_py)?;
    let flat: Vec<f64> = x.iter().flat_map(|p| p.to_array()).collect();
    PyArray1::from_vec(py, flat).reshape([n, 3])
}
