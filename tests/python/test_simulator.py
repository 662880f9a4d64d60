"""`madder.Simulator` as the add-on uses it, without Blender: what its outputs mean (the
add-on's cache fields are made from them), pours and splashes, and errors that name the
parameter."""

import numpy as np
import pytest
from test_core import blob, grid

import madder

DT = 1 / 24


def wet_grid(n=16, **kw):
    faces, pos = grid(n)
    sim = madder.Simulator(faces, pos, pos, **kw)
    return sim, faces, pos


def test_outputs_are_sums_of_the_densities():
    sim, _, pos = wet_grid()
    sim.add_liquid(0.5 * blob(pos), 0.04)
    for _ in range(12):
        sim.step(pos, DT)
    d = sim.densities()
    solute = d["solute"] + d["absorbed_solute"] + d["adsorbed"]
    stain = sim.stain()
    np.testing.assert_allclose(stain[:, 3], solute, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(stain[:, :3], solute[:, None] * np.array([0.45, 0.05, 0.1]), rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(sim.wetness(), d["free_solvent"] + d["absorbed_solvent"], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(sim.deposit(), d["adsorbed"], rtol=1e-6, atol=1e-12)
    assert (d["absorbed_solvent"].max(), d["adsorbed"].max()) > (0.0, 0.0)  # the fibres took some


def test_pour_adds_exactly_its_mass_and_solute_is_conserved():
    sim, _, pos = wet_grid(evaporation=0.0)
    area = sim.vertex_area  # still and flat: the areas never change
    pour = 0.3 * blob(pos, r=0.08)
    for k in range(10):
        sim.add_liquid(pour, 0.02, (0.0, 0.0, 1.0) if k % 2 else None)  # two colours
        sim.step(pos, DT)
    t = sim.totals()
    added = 10 * float(area @ pour.astype(np.float64))
    assert t["solvent"] == pytest.approx(added, rel=1e-9)
    assert t["solute"] == pytest.approx(0.02 * added, rel=1e-9)
    assert t["evaporated"] == 0.0
    # the colour is the mass-weighted mix: half the solute of each colour
    c = sim.solute_color()
    wet = sim.stain()[:, 3] > 1e-6 * sim.stain()[:, 3].max()
    mix = (area[wet] * sim.stain()[wet, 3]) @ c[wet] / (area[wet] @ sim.stain()[wet, 3])
    np.testing.assert_allclose(mix, [0.225, 0.025, 0.55], rtol=1e-3)


def test_splash_depends_only_on_its_seed():
    def run(seed):
        sim, _, pos = wet_grid()
        w = blob(pos)
        sim.add_liquid(w, 0.05)
        sim.splash((0.5, 0.5, 0.0), 1.0, seed, w)
        v0 = sim.velocity.copy()
        for _ in range(4):
            sim.step(pos, DT)
        return v0, sim.wetness()

    (va, wa), (vb, wb), (vc, wc) = run(5), run(5), run(6)
    np.testing.assert_array_equal(va, vb)
    np.testing.assert_array_equal(wa, wb)
    assert np.abs(va - vc).max() > 0.01 and np.abs(wa - wc).max() > 0
    _, pos = grid(16)
    out = ((pos[:, :2] - 0.5) * va[:, :2]).sum(1)  # outward component
    assert (out[np.abs(va).sum(1) > 0] > 0).mean() > 0.9


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(friction=-1.0), ["friction", "-1"]),
        (dict(evaporation_boundary=0.5), ["evaporation boundary", "≥ 1"]),
        (dict(saturation=float("nan")), ["saturation"]),
        (dict(gravity=(0.0, float("inf"), 0.0)), ["gravity"]),
        (dict(diffusion=-0.1), ["diffusion"]),
        (dict(substeps=0), ["substeps"]),
        (dict(carried_fraction=0.0), ["carried fraction", "(0, 1]"]),
        (dict(dispersivity=-1e-3), ["dispersivity", "≥ 0"]),
        (dict(film_creep=1.5), ["film creep", "from 0 to 1"]),
    ],
)
def test_out_of_range_parameters_name_themselves(kw, words):
    faces, pos = grid(4)
    with pytest.raises(madder.ParameterError) as e:
        madder.Simulator(faces, pos, pos, **kw)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_a_failed_step_keeps_the_state():
    sim, _, pos = wet_grid()
    sim.add_liquid(blob(pos), 0.05)
    sim.step(pos, DT)
    before = sim.densities()
    bad = pos.copy()
    bad[3, 0] = np.nan
    with pytest.raises(madder.MeshError, match="vertex 3"):
        sim.step(bad, DT)
    with pytest.raises(madder.ParameterError, match="time step"):
        sim.step(pos, 0.0)
    for k, v in sim.densities().items():
        np.testing.assert_array_equal(v, before[k])


def test_the_rim_keywords_reach_the_core():
    """Carried fraction and dispersivity (issue 34 §3): their off values (1, 0) are the
    defaults bit for bit; a dispersivity spreads the carried solute of a drying spill, and
    a carried fraction below 1 leaves solute behind the flow."""
    tide = dict(carry_solute=True, residual_saturation=0.1, vapour_limited=True, adsorption=0.0)

    def dried(**kw):
        sim, _, pos = wet_grid(**tide, **kw)
        sim.add_liquid(0.3 * blob(pos, r=0.1), 0.01)
        for _ in range(24):
            sim.step(pos, 0.5)
        return sim.densities()

    off, told = dried(), dried(carried_fraction=1.0, dispersivity=0.0)
    for k in off:
        np.testing.assert_array_equal(off[k], told[k], err_msg=k)
    for kw in (dict(dispersivity=0.05), dict(carried_fraction=0.5)):
        on = dried(**kw)
        assert np.abs(on["solute"] + on["absorbed_solute"] - off["solute"] - off["absorbed_solute"]).max() > 0, kw
        total = sum(on[k].sum() for k in ("solute", "absorbed_solute", "adsorbed"))
        assert np.isfinite(total) and min(on[k].min() for k in on) >= 0.0, kw


def test_the_film_creep_reaches_the_core():
    """`film_creep` (issue 34 §1): with a holdup on a sheet hung in gravity, the pinned
    film creeps at that share of the free liquid's spreading, so at 0.1 (the default) less
    of a run's film spreads into the dry fibres than at 1 (the holdup in the flow alone)
    and more stays free; on a level sheet nothing is pinned and the default is 1 bit for
    bit."""
    params = dict(holdup=0.05, carry_solute=True, residual_saturation=0.1)

    def run(gravity, **kw):
        sim, _, pos = wet_grid(32, gravity=gravity, **params, **kw)
        pour = 0.2 * blob(pos, centre=(0.5, 0.8), r=0.05)
        for k in range(24):
            if k < 12:
                sim.add_liquid(pour, 0.02)
            sim.step(pos, DT)
        return sim.vertex_area @ sim.densities()["free_solvent"], sim.densities()

    hung = (0.0, -9.81, 0.0)
    (crept, _), (spread, _) = run(hung), run(hung, film_creep=1.0)
    assert crept > spread * (1 + 1e-4), (crept, spread)
    (_, level), (_, level_off) = run((0.0, 0.0, -9.81)), run((0.0, 0.0, -9.81), film_creep=1.0)
    for k in level:
        np.testing.assert_array_equal(level[k], level_off[k], err_msg=k)
