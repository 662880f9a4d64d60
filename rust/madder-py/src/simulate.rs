//! `Simulator`: the full stain simulator of chapter 4 (core module `stain::simulate`).

use glam::DVec3;
use numpy::ndarray::Ix1;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::args;
use crate::errors::{ParameterError, to_py};
use crate::mesh::{Topology, dpoints};
use crate::stain::conductivity;
use crate::threads::Pool;

/// Simulates a liquid stain on a moving cloth: velocity, free and absorbed solvent,
/// dissolved, absorbed and adsorbed solute (seed chapter 4).
///
/// `Simulator(topology, rest, positions, *, diffusion=None, face_tensors=None,
/// face_uv=None, face_angle=None, color=DEFAULT_SOLUTE_COLOR, gravity=(0, 0, -9.81),
/// viscosity=..., friction=..., absorption=..., saturation=..., adsorption=...,
/// capacity=..., evaporation=..., evaporation_boundary=1.2, wicking_exponent=0,
/// wicking_density=0.1, wicking_picard=0, wicking_tolerance=0, irregularity=0, irregularity_length=0.003,
/// irregularity_seed=0,
/// irregularity_fine_length=0,
/// carry_solute=False, residual_saturation=0, vapour_limited=False, carried_fraction=1,
/// dispersivity=0, holdup=0, film_creep=0.1, drip_hold=0, substeps=1, first_substep=0, use_gravity=True, use_rectilinear=True,
/// use_coriolis=True, momentum_advection=True, detail=0, threads=None)`.
///
/// `topology` is a `Topology` or an `(F, 3)` face array (any integer dtype); `rest` and
/// `positions` `(N, 3)` world positions in metres (rest pose; first frame), one row per
/// vertex of the topology, of any float dtype and layout (as every array argument of the
/// module, `args.rs`; read as float64). The densities diffuse isotropically at `diffusion`
/// m²/s, or per face along the weave (`face_tensors` `(F, 3)` in m²/s, `face_uv`
/// `(F, 3, 2)`, `face_angle` `(F,)`, as for `DiffusionStepper`; `face_angle` only with
/// the other two); the default is isotropic, `DEFAULT_DIFFUSION` m²/s (2e-4: wicking in
/// cotton, whose front advances about a centimetre in the first second: `D ≈ L²/2t`).
/// `DEFAULT_SOLUTE_COLOR` is (0.45, 0.05, 0.1), a dark red.
/// `wicking_exponent` `n` makes the fabric wick faster where it is wetter: the densities
/// diffuse at `D·θⁿ`, `θ` the liquid density over `wicking_density` (kg/m², capped at 1),
/// which gives a spreading spill a sharp front (0, the default: a constant rate).
/// `wicking_picard` (0 to 8) solves each sub-step again that many times with the rate of
/// the last solution instead of the step's start: the lagged rate lets the front cross
/// one ring of faces per step, so it runs slow and squares off along the mesh (0, the
/// default: lagged; 2 takes a structured grid's 4-fold term from 3.4 % to 0.5 %; at most
/// 64). `wicking_tolerance` ε > 0 goes on solving (up to 64 times) until no face's rate
/// changes by more than ε times the largest, so that a long step's front is not held to
/// a ring per solve; `wicking_picard` is then the least number (0, the default: off).
/// `irregularity` (0–1) makes the fabric uneven: its diffusion and absorption rates vary
/// at random over the rest surface, correlated over `irregularity_length` metres, the
/// same for the same `irregularity_seed` (0, the default: a uniform fabric).
/// `irregularity_fine_length` > 0 (metres, below `irregularity_length`) makes that
/// variation multi-scale, self-affine (Hurst exponent 0.6) from this fibre scale up to
/// `irregularity_length`, so the outline is rough at every scale in between (0, the
/// default: one correlation length).
/// `carry_solute` moves the dissolved solute with the solvent's capillary flow (and the
/// liquid in the fibres wicks too) instead of diffusing it at the solvent's rate.
/// `residual_saturation` (0 to 1, exclusive) pins the wet edge: the fibres' liquid below
/// that fraction of `saturation` neither moves nor lets liquid in (0, the default: off).
/// `vapour_limited` makes a wet patch evaporate fastest at its edge, as vapour diffusing
/// into still air does (`J/J̄ = R/(2√(d(2R − d)))`, `d` the distance to the edge), in place
/// of `evaporation_boundary` on the outermost vertices. With `carry_solute` the two
/// draw the solute to the pinned edge as it dries: a tide line.
/// `carried_fraction` (0 exclusive to 1) is the share of the dissolved solute the flow
/// carries with `carry_solute` at each transfer, the rest staying where it is: the solute
/// moves at that fraction of the liquid's speed (1, the default: all of it).
/// `dispersivity` (m, ≥ 0) spreads the carried solute back against the flow that brings
/// it (mechanical dispersion `α_L |u|`), so a tide line is about that wide at any mesh
/// spacing (0, the default: off, the ring one cell wide).
/// `holdup` (kg/m², ≥ 0) is the free liquid each vertex keeps back from a run, filled
/// before the run moves on and left behind to soak in (0, the default: off).
/// `film_creep` (0 to 1): with a holdup, the share of the free liquid's spreading left
/// to the pinned film, so a run's film stays at `holdup` while it runs and evens out
/// while it dries (0.1, the default; 1: the holdup holds in the flow alone).
/// `drip_hold` (kg/m, ≥ 0): the free liquid a hanging hem holds per metre of the cloth's
/// border; the rest drips off, counted in `totals()` (0, the default: off).
/// `capillary_height` (m, ≥ 0): how high the fabric wicks up from a reservoir; with
/// `carry_solute`, the fibres' liquid drains down the body force (Richards' equation), so
/// a hanging wet cloth settles into a wedge that height tall (0, the default: off).
/// `first_substep` (s, ≥ 0): after liquid is poured, the sub-steps start this long and
/// double until they reach the frame's own, so a fresh spill spreads in short steps in a
/// scene whose frames are long (0, the default: off).
/// Units are SI: densities in kg/m², rates in 1/s, evaporation in kg/(m²·s).
/// `detail` (0–3) runs the simulation on the cloth's triangles each split into
/// `4**detail` (the fine vertices placed on the cloth's triangles every frame): `step`,
/// `add_liquid`, `splash` and every read-out still take and give one value per cloth
/// vertex (mass-exact transfers); `fine=True` read-outs give the refined cloth's.
/// `threads` caps the worker threads; results do not depend on it.
#[pyclass(module = "madder")]
pub struct Simulator {
    inner: madder::stain::Detailed,
    pool: Pool,
}

impl Simulator {
    fn run<T: Send>(
        &mut self,
        py: Python<'_>,
        f: impl FnOnce(&mut madder::stain::Detailed) -> T + Send,
    ) -> T {
        let Self { inner, pool } = self;
        pool.run(py, || f(inner))
    }
}

/// The core's default solute colour as the tuple the `color` argument takes.
const DEFAULT_COLOR: (f64, f64, f64) = {
    let [r, g, b] = madder::stain::DEFAULT_SOLUTE_COLOR;
    (r, g, b)
};

/// The `(N,)` float argument `name` as float64 values (any float dtype, see `args`).
fn f64s(name: &str, a: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    Ok(args::floats::<f64, Ix1>(name, a)?.as_array().to_vec())
}

fn out1<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f32>> {
    PyArray1::from_vec(py, v.iter().map(|&x| x as f32).collect())
}

fn out2<'py, const K: usize>(
    py: Python<'py>,
    v: impl ExactSizeIterator<Item = [f64; K]>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let n = v.len();
    let flat: Vec<f32> = v.flat_map(|a| a.map(|x| x as f32)).collect();
    PyArray1::from_vec(py, flat).reshape([n, K])
}

#[pymethods]
impl Simulator {
    #[new]
    #[pyo3(signature = (topology, rest, positions, *, diffusion=None, face_tensors=None,
        face_uv=None, face_angle=None, color=DEFAULT_COLOR, gravity=(0.0, 0.0, -9.81),
        viscosity=None, friction=None, absorption=None, saturation=None, adsorption=None,
        capacity=None, evaporation=None, evaporation_boundary=None, wicking_exponent=None,
        wicking_density=None, wicking_picard=0, wicking_tolerance=0.0, irregularity=None, irregularity_length=None, irregularity_seed=0,
        irregularity_fine_length=None,
        carry_solute=false, residual_saturation=None, vapour_limited=false, carried_fraction=None,
        dispersivity=None, holdup=None, film_creep=None, drip_hold=0.0, capillary_height=0.0, substeps=1, first_substep=0.0,
        use_gravity=true, use_rectilinear=true, use_coriolis=true, momentum_advection=true,
        detail=0, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        topology: &Bound<'_, PyAny>,
        rest: &Bound<'_, PyAny>,
        positions: &Bound<'_, PyAny>,
        diffusion: Option<f64>,
        face_tensors: Option<&Bound<'_, PyAny>>,
        face_uv: Option<&Bound<'_, PyAny>>,
        face_angle: Option<&Bound<'_, PyAny>>,
        color: (f64, f64, f64),
        gravity: (f64, f64, f64),
        viscosity: Option<f64>,
        friction: Option<f64>,
        absorption: Option<f64>,
        saturation: Option<f64>,
        adsorption: Option<f64>,
        capacity: Option<f64>,
        evaporation: Option<f64>,
        evaporation_boundary: Option<f64>,
        wicking_exponent: Option<f64>,
        wicking_density: Option<f64>,
        wicking_picard: u32,
        wicking_tolerance: f64,
        irregularity: Option<f64>,
        irregularity_length: Option<f64>,
        irregularity_seed: u64,
        irregularity_fine_length: Option<f64>,
        carry_solute: bool,
        residual_saturation: Option<f64>,
        vapour_limited: bool,
        carried_fraction: Option<f64>,
        dispersivity: Option<f64>,
        holdup: Option<f64>,
        film_creep: Option<f64>,
        drip_hold: f64,
        capillary_height: f64,
        substeps: u32,
        first_substep: f64,
        use_gravity: bool,
        use_rectilinear: bool,
        use_coriolis: bool,
        momentum_advection: bool,
        detail: u32,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        let rest = dpoints("rest", rest)?;
        let pos = dpoints("positions", positions)?;
        if rest.len() != pos.len() {
            return Err(ParameterError::new_err(format!(
                "rest has {} rows but positions has {}: both need one row per vertex",
                rest.len(),
                pos.len()
            )));
        }
        if face_angle.is_some() && (face_tensors.is_none() || face_uv.is_none()) {
            return Err(ParameterError::new_err(
                "face_angle turns the weave of woven faces: it needs face_tensors and face_uv too",
            ));
        }
        let topo = if let Ok(t) = topology.cast::<Topology>() {
            t.get().inner.clone()
        } else {
            let faces = args::indices::<numpy::ndarray::Ix2>(
                "topology (a madder.Topology or an (F, 3) face array)",
                topology,
            )?;
            if faces.shape()[1] != 3 {
                return Err(ParameterError::new_err(format!(
                    "faces must have shape (F, 3), got {:?}",
                    faces.shape()
                )));
            }
            let tris = faces
                .as_array()
                .rows()
                .into_iter()
                .map(|r| [r[0], r[1], r[2]])
                .collect();
            madder::mesh::Topology::from_triangles(rest.len(), tris).map_err(to_py)?
        };
        if topo.n_vertices() != rest.len() {
            return Err(ParameterError::new_err(format!(
                "rest and positions have {} rows but the topology has {} vertices",
                rest.len(),
                topo.n_vertices()
            )));
        }
        let conductivity = if diffusion.is_none() && face_tensors.is_none() {
            madder::stain::Conductivity::default()
        } else {
            conductivity(diffusion, face_tensors, face_uv, face_angle)?
        };
        let mut params = madder::stain::StainParams {
            gravity: DVec3::new(gravity.0, gravity.1, gravity.2),
            forces: madder::stain::Forces {
                gravity: use_gravity,
                rectilinear: use_rectilinear,
                coriolis: use_coriolis,
            },
            momentum_advection,
            substeps,
            first_substep,
            drip_hold,
            capillary_height,
            ..Default::default()
        };
        let set = |slot: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *slot = v;
            }
        };
        set(&mut params.viscosity, viscosity);
        set(&mut params.friction, friction);
        set(&mut params.wicking.exponent, wicking_exponent);
        set(&mut params.wicking.density, wicking_density);
        params.wicking.picard = wicking_picard;
        params.wicking.tolerance = wicking_tolerance;
        set(&mut params.irregularity.amplitude, irregularity);
        set(
            &mut params.irregularity.correlation_length,
            irregularity_length,
        );
        params.irregularity.seed = irregularity_seed;
        set(
            &mut params.irregularity.fine_length,
            irregularity_fine_length,
        );
        params.carry_solute = carry_solute;
        set(&mut params.residual_saturation, residual_saturation);
        params.vapour_limited = vapour_limited;
        set(&mut params.carried_fraction, carried_fraction);
        set(&mut params.dispersivity, dispersivity);
        set(&mut params.holdup, holdup);
        set(&mut params.film_creep, film_creep);
        let r = &mut params.interaction;
        set(&mut r.absorption, absorption);
        set(&mut r.saturation, saturation);
        set(&mut r.adsorption, adsorption);
        set(&mut r.capacity, capacity);
        set(&mut r.evaporation, evaporation);
        set(&mut r.evaporation_boundary, evaporation_boundary);
        let pool = Pool::new(threads)?;
        let solute_color = [color.0, color.1, color.2];
        let inner = pool.run(py, || {
            madder::stain::Detailed::new(
                topo,
                &rest,
                &pos,
                conductivity,
                params,
                solute_color,
                detail,
                faer::Par::Seq,
            )
        });
        Ok(Self {
            inner: inner.map_err(to_py)?,
            pool,
        })
    }

    /// Advances one frame: the cloth moves to `positions` ((N, 3), any float dtype) over `dt`
    /// seconds. `after`, the positions one frame later when known, makes the cloth's
    /// acceleration second-order accurate (and right at the first frame); they come
    /// `after_dt` seconds later (default `dt`). Frames may differ in length (a Frame Time
    /// that changes): the accelerations are then divided differences over the uneven
    /// frames. Releases the GIL. On error the simulator stays at the previous frame.
    #[pyo3(signature = (positions, dt, after=None, after_dt=None))]
    fn step(
        &mut self,
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        dt: f64,
        after: Option<&Bound<'_, PyAny>>,
        after_dt: Option<f64>,
    ) -> PyResult<()> {
        let pos = dpoints("positions", positions)?;
        let after = after.map(|a| dpoints("after", a)).transpose()?;
        let h = after_dt.unwrap_or(dt);
        self.run(py, |s| {
            s.step_until(&pos, dt, after.as_deref().map(|a| (a, h)))
        })
        .map_err(to_py)
    }

    /// Pours `solvent` ((N,) floats, kg/m², ≥ 0) at every vertex, with `concentration`
    /// kg of solute per kg of solvent, of `color` (RGB; default the liquid's colour).
    #[pyo3(signature = (solvent, concentration=0.05, color=None))]
    fn add_liquid(
        &mut self,
        solvent: &Bound<'_, PyAny>,
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> PyResult<()> {
        let d = f64s("solvent", solvent)?;
        self.inner
            .add_liquid(&d, concentration, color)
            .map_err(to_py)
    }

    /// Pours a pool: the liquid `weights` ((N,) floats in [0, 1], per cloth vertex) hold at
    /// `amount` kg/m², `amount × Σ weight × area` kg, laid `amount` deep where the weights
    /// are highest (their smooth reconstruction, so the edge does not follow the cloth's
    /// mesh), on the refined cloth's vertices at a Detail level; `concentration` and
    /// `color` as for `add_liquid`.
    #[pyo3(signature = (weights, amount, concentration=0.05, color=None))]
    fn add_pool(
        &mut self,
        weights: &Bound<'_, PyAny>,
        amount: f64,
        concentration: f64,
        color: Option<[f64; 3]>,
    ) -> PyResult<()> {
        let w = f64s("weights", weights)?;
        self.inner
            .add_pool(&w, amount, concentration, color)
            .map_err(to_py)
    }

    /// A splash: a random outgoing velocity (m/s) away from `center` (world), for the
    /// vertices with `weights` > 0 ((N,) floats, scaling the speed), reproducible from
    /// `seed`.
    fn splash(
        &mut self,
        center: (f64, f64, f64),
        speed: f64,
        seed: u64,
        weights: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let w = f64s("weights", weights)?;
        let c = DVec3::new(center.0, center.1, center.2);
        self.inner.splash(c, speed, seed, &w).map_err(to_py)
    }

    /// Liquid (free + absorbed solvent) per unit area, kg/m², `(N,)` float32; with
    /// `fine=True`, per vertex of the refined cloth (`n_fine_vertices`; the cloth's own
    /// at detail 0).
    #[pyo3(signature = (*, fine=false))]
    fn wetness<'py>(&self, py: Python<'py>, fine: bool) -> Bound<'py, PyArray1<f32>> {
        if fine {
            out1(py, &self.inner.fine_wetness())
        } else {
            out1(py, &self.inner.wetness())
        }
    }

    /// The stain for shading, `(N, 4)` float32: RGB = solute colour × total solute
    /// density (kg/m²), A = total solute density; `fine=True` as for `wetness`.
    #[pyo3(signature = (*, fine=false))]
    fn stain<'py>(&self, py: Python<'py>, fine: bool) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let (s, c) = if fine {
            (
                self.inner.fine_solute_density(),
                self.inner.fine_solute_color(),
            )
        } else {
            (self.inner.solute_density(), self.inner.solute_color())
        };
        out2(
            py,
            s.iter()
                .zip(c)
                .map(|(&s, c)| [c[0] * s, c[1] * s, c[2] * s, s]),
        )
    }

    /// Adsorbed solute per unit area (the permanent deposit), kg/m², `(N,)` float32;
    /// `fine=True` as for `wetness`.
    #[pyo3(signature = (*, fine=false))]
    fn deposit<'py>(&self, py: Python<'py>, fine: bool) -> Bound<'py, PyArray1<f32>> {
        if fine {
            out1(py, &self.inner.fine_deposit())
        } else {
            out1(py, &self.inner.deposit())
        }
    }

    /// Solute colour at every vertex (mass-weighted mix), `(N, 3)` float32; `fine=True`
    /// as for `wetness`.
    #[pyo3(signature = (*, fine=false))]
    fn solute_color<'py>(
        &self,
        py: Python<'py>,
        fine: bool,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        if fine {
            out2(py, self.inner.fine_solute_color().into_iter())
        } else {
            out2(py, self.inner.solute_color().into_iter())
        }
    }

    /// The Detail level: the cloth's triangles are each split into `4**detail` for the
    /// simulation (0: the cloth's own vertices).
    #[getter]
    fn detail(&self) -> u32 {
        self.inner.level()
    }

    /// Vertices of the refined cloth the simulation runs on (the cloth's at detail 0):
    /// the length of the `fine=True` read-outs, numbered as `Refinement(topology,
    /// detail)` numbers them.
    #[getter]
    fn n_fine_vertices(&self) -> usize {
        self.inner.n_fine_vertices()
    }

    /// Densities (kg/m², float64) of every field: a dict with `free_solvent`, `solute`,
    /// `absorbed_solvent`, `absorbed_solute`, `adsorbed`.
    fn densities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = self.inner.fields();
        let f = f.as_ref();
        let d = PyDict::new(py);
        for (name, m) in [
            ("free_solvent", &f.free_solvent),
            ("solute", &f.solute),
            ("absorbed_solvent", &f.absorbed_solvent),
            ("absorbed_solute", &f.absorbed_solute),
            ("adsorbed", &f.adsorbed),
        ] {
            d.set_item(name, PyArray1::from_vec(py, self.inner.density(m)))?;
        }
        Ok(d)
    }

    /// Totals over the mesh, kg (float64): `solvent` (free + absorbed), `solute` (all
    /// three kinds), `evaporated`, `dripped` and `dripped_solute` (since the start).
    fn totals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = self.inner.totals();
        let d = PyDict::new(py);
        d.set_item("solvent", t.solvent)?;
        d.set_item("solute", t.solute)?;
        d.set_item("evaporated", t.evaporated)?;
        d.set_item("dripped", t.dripped)?;
        d.set_item("dripped_solute", t.dripped_solute)?;
        Ok(d)
    }

    /// Velocity as world vectors, m/s, `(N, 3)` float32.
    #[getter]
    fn velocity<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        out2(
            py,
            self.inner
                .velocity_world()
                .into_iter()
                .map(|v| v.to_array()),
        )
    }

    /// Sets the velocity from world vectors ((N, 3), any float dtype, projected on each
    /// vertex's tangent plane).
    #[setter]
    fn set_velocity(&mut self, velocity: &Bound<'_, PyAny>) -> PyResult<()> {
        let w = dpoints("velocity", velocity)?;
        self.inner.set_velocity_world(&w).map_err(to_py)
    }

    /// Lumped vertex areas at the current frame, m², float64 (of every vertex that holds
    /// or held liquid or solute; a vertex that never did keeps an older area).
    #[getter]
    fn vertex_area<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.vertex_area().to_vec())
    }

    /// Wall-clock seconds per phase since the simulator was built, and counters: a dict
    /// with `window`, `geometry`, `forces`, `advection` (its parts `advection_trace`,
    /// `advection_plan`, `advection_apply`), `diffusion`, `interaction` (s), the counters
    /// of `Profile` (`substeps`, `density_iterations`, ...). The work model of each phase
    /// (`Profile::least_work`) is the benches' alone (madder's `roofline` feature).
    fn profile<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = self.inner.profile();
        let d = PyDict::new(py);
        for (k, v) in [
            ("window", p.window),
            ("geometry", p.geometry),
            ("forces", p.forces),
            ("advection", p.advection),
            ("advection_trace", p.advection_trace),
            ("advection_plan", p.advection_plan),
            ("advection_apply", p.advection_apply),
            ("diffusion", p.diffusion),
            ("interaction", p.interaction),
        ] {
            d.set_item(k, v)?;
        }
        for (k, v) in [
            ("frames", p.frames),
            ("substeps", p.substeps),
            ("density_iterations", p.density_iterations),
            ("velocity_iterations", p.velocity_iterations),
            ("transport_cycles", p.transport_cycles),
            ("active_vertices", p.active_vertices),
            ("window_vertices", p.window_vertices),
            ("window_rebuilds", p.window_rebuilds),
            ("window_retries", p.window_retries),
            ("window_edges", p.window_edges),
            ("window_faces", p.window_faces),
            ("transport_passes", p.transport_passes),
            ("density_solves", p.density_solves),
            ("carried_fields", p.carried_fields),
        ] {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Simulated time, s.
    #[getter]
    fn time(&self) -> f64 {
        self.inner.time()
    }
}
