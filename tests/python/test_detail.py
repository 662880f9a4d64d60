"""Stain Detail from Python (issue 12): `Simulator(..., detail=L)` keeps its per-cloth-vertex
interface, its totals are the same read at either level, the `fine=True` read-outs are
numbered as `Refinement` numbers the refined cloth, and bad levels are refused."""

import numpy as np
import pytest
from test_core import blob, grid

import madder

DT = 1 / 24


def run(detail, n=10, frames=8, **kw):
    faces, pos = grid(n)
    sim = madder.Simulator(faces, pos, pos, detail=detail, evaporation=0.0, **kw)
    sim.add_liquid(0.5 * blob(pos), 0.05, (0.2, 0.3, 0.9))
    for _ in range(frames):
        sim.step(pos, DT)
    return sim, faces, pos


@pytest.mark.parametrize("detail", [1, 2])
def test_the_interface_is_per_cloth_vertex_and_totals_agree(detail):
    sim, faces, pos = run(detail)
    n = len(pos)
    assert sim.detail == detail
    assert sim.stain().shape == (n, 4) and sim.wetness().shape == (n,) and sim.deposit().shape == (n,)
    assert sim.velocity.shape == (n, 3) and sim.vertex_area.shape == (n,)
    # the stain read at the cloth, integrated over the cloth's areas, is the fine total
    solute = float(sim.vertex_area @ sim.stain()[:, 3].astype(np.float64))
    assert solute == pytest.approx(sim.totals()["solute"], rel=1e-6)  # float32 read-out
    d = sim.densities()
    exact = float(sim.vertex_area @ (d["solute"] + d["absorbed_solute"] + d["adsorbed"]))
    assert exact == pytest.approx(sim.totals()["solute"], rel=1e-12)
    # the colour poured comes back where there is solute
    wet = sim.stain()[:, 3] > 1e-3 * sim.stain()[:, 3].max()
    np.testing.assert_allclose(sim.solute_color()[wet], np.tile([0.2, 0.3, 0.9], (wet.sum(), 1)), atol=1e-5)


def test_fine_read_outs_follow_the_refinement():
    sim, faces, pos = run(2)
    r = madder.Refinement(madder.Topology(faces, len(pos)), 2)
    assert (r.level, r.n_vertices, r.n_faces) == (2, sim.n_fine_vertices, 16 * len(faces))
    fine = sim.stain(fine=True)
    assert fine.shape == (r.n_vertices, 4)
    assert sim.wetness(fine=True).shape == (r.n_vertices,)
    # the cloth's vertices come first in the fine numbering: where the fine stain is
    # smooth, the cloth's value (a hat average) is close to the fine value at the vertex
    assert r.faces().shape == (r.n_faces, 3) and r.faces().max() == r.n_vertices - 1
    # fine UVs: the cloth's corner UVs combined barycentrically; a UV map equal to the
    # positions' xy comes back as the fine faces' corners
    uv = pos[faces][:, :, :2].astype(np.float32)
    fuv = r.face_uv(uv)
    assert fuv.shape == (r.n_faces, 3, 2)
    # every fine face lies inside its cloth face (area sums agree)
    def area(t):
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        return 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    np.testing.assert_allclose(area(fuv).reshape(len(faces), 16).sum(1), area(uv), rtol=1e-5)


def test_detail_zero_is_the_cloth_simulator():
    a, _, _ = run(0)
    faces, pos = grid(10)
    b = madder.Simulator(faces, pos, pos, evaporation=0.0)
    b.add_liquid(0.5 * blob(pos), 0.05, (0.2, 0.3, 0.9))
    for _ in range(8):
        b.step(pos, DT)
    np.testing.assert_array_equal(a.stain(), b.stain())
    np.testing.assert_array_equal(a.stain(fine=True), b.stain())


def test_bad_levels_are_refused():
    faces, pos = grid(6)
    with pytest.raises(madder.ParameterError, match="detail level"):
        madder.Simulator(faces, pos, pos, detail=4)
    with pytest.raises(OverflowError):
        madder.Simulator(faces, pos, pos, detail=-1)


@pytest.mark.parametrize("detail", [0, 2])
def test_a_pool_lays_the_weights_mass_amount_deep_on_the_refined_cloth(detail):
    # the core's own tests (rust/madder/tests/pool.rs) check its shape; here the binding:
    # the mass is amount x the weights' integral at either level, laid at the amount on
    # the fine vertices, and bad weights name the vertex
    faces, pos = grid(10)
    sim = madder.Simulator(faces, pos, pos, detail=detail, evaporation=0.0)
    w = np.clip(blob(pos) / blob(pos).max(), 0.0, 1.0).astype(np.float32)
    w[w < 0.05] = 0.0
    sim.add_pool(w, 1.2, 0.05, (0.2, 0.3, 0.9))
    assert sim.totals()["solvent"] == pytest.approx(1.2 * float(sim.vertex_area @ w.astype(np.float64)), rel=1e-6)
    fine = sim.wetness(fine=True)
    assert fine.max() == pytest.approx(1.2, rel=1e-6)
    assert ((fine > 0) & (fine < np.float32(1.2) * (1 - 1e-6))).sum() <= 1
    w[3] = 1.5
    with pytest.raises(ValueError, match="pool weight at vertex 3 must be in \\[0, 1\\], got 1.5"):
        sim.add_pool(w, 1.2)
