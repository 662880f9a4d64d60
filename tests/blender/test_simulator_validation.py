"""Validation of the full simulator (issue 3) on real Blender cloth: the dropping
tablecloth fixture (41 x 41 vertices, 60 frames of a cloth falling onto a sphere),
evaluated through the depsgraph and stepped with `madder.Simulator` directly.

- About 1000 sub-steps with every process on: the total solute is constant to 1e-9
  relative, and the solvent plus the evaporated solvent too.
- About 2000 sub-steps: no NaN and no negative density in any field, at any frame.
"""

import bpy
import numpy as np

import madder

FIELDS = ("free_solvent", "solute", "absorbed_solvent", "absorbed_solute", "adsorbed")


def tablecloth(open_fixture):
    """(faces (F, 3) uint32, rest (N, 3) float32, world positions per frame [(N, 3)
    float32], dt): every frame of the cloth evaluated once, in order."""
    scene = open_fixture("tablecloth.blend")
    obj = bpy.data.objects["Tablecloth"]
    mesh = obj.data
    mesh.calc_loop_triangles()
    faces = np.empty(3 * len(mesh.loop_triangles), dtype=np.uint32)
    mesh.loop_triangles.foreach_get("vertices", faces)
    faces = faces.reshape(-1, 3)
    n = len(mesh.vertices)

    def world(data, matrix):
        co = np.empty(3 * n, dtype=np.float64)
        data.vertices.foreach_get("co", co)
        m = np.array(matrix, dtype=np.float64)
        return (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)

    frames = []
    for f in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(f)
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        assert len(ev.data.vertices) == n
        frames.append(world(ev.data, ev.matrix_world))
    rest = world(mesh, obj.matrix_world)
    # the fixture does move: the cloth drops and drapes
    assert np.abs(frames[-1] - frames[0]).max() > 0.3
    dt = scene.render.fps_base / scene.render.fps
    return faces, rest, frames, dt


def run(open_fixture, substeps, check):
    """Pours a Gaussian patch (0.5 kg/m² at its centre) at the first frame, splashes it,
    and steps through every frame with everything on; `check(k, sim, start)` after each
    frame, `start` the totals right after the pour."""
    faces, rest, frames, dt = tablecloth(open_fixture)
    sim = madder.Simulator(
        faces, rest, frames[0],
        diffusion=2e-3, viscosity=1e-3, friction=5.0,
        absorption=2.0, saturation=0.1, adsorption=0.5, capacity=2e-3,
        evaporation=2e-3, evaporation_boundary=1.2,
        gravity=tuple(bpy.context.scene.gravity),
        use_gravity=True, use_rectilinear=True, use_coriolis=True,
        substeps=substeps,
    )
    centre = rest[:, :2].mean(axis=0) + np.array([0.25, 0.15])  # the stain_source patch
    r2 = ((rest[:, :2] - centre) ** 2).sum(axis=1)
    patch = 0.5 * np.exp(-r2 / (2 * 0.2**2))
    sim.add_liquid(patch.astype(np.float32), 0.03)
    weights = (patch / patch.max()).astype(np.float32)
    sim.splash(tuple(map(float, frames[0][np.argmax(patch)])), 1.0, 5, weights)
    start = sim.totals()
    assert start["solute"] > 0 and start["solvent"] > 0 and start["evaporated"] == 0
    for k in range(1, len(frames)):
        after = frames[k + 1] if k + 1 < len(frames) else None
        sim.step(frames[k], dt, after=after)
        check(k, sim, start)
    return sim, start, (len(frames) - 1) * substeps


def sane_densities(k, sim):
    densities = sim.densities()
    assert set(densities) == set(FIELDS)
    for name, d in densities.items():
        assert d.dtype == np.float64
        bad = ~np.isfinite(d)
        assert not bad.any(), f"frame {k}: {name} is not finite at vertices {np.flatnonzero(bad)[:10]}"
        neg = d < 0
        assert not neg.any(), f"frame {k}: {name} is negative at {np.flatnonzero(neg)[:10]}: {d[neg][:10]}"
    for name, a in (("wetness", sim.wetness()), ("stain", sim.stain()), ("deposit", sim.deposit()),
                    ("velocity", sim.velocity)):
        assert np.isfinite(a).all(), f"frame {k}: {name} is not finite"


def defects(sim, start):
    """Relative change of the total solute and of solvent + evaporated since `start`."""
    t = sim.totals()
    ds = abs(t["solute"] - start["solute"]) / start["solute"]
    dv = abs(t["solvent"] + t["evaporated"] - start["solvent"]) / start["solvent"]
    return ds, dv


def test_tablecloth_conserves_solute_and_accounts_for_evaporation(open_fixture):
    worst = [0.0, 0.0]

    def check(k, sim, start):
        ds, dv = defects(sim, start)
        worst[:] = max(worst[0], ds), max(worst[1], dv)
        t = sim.totals()
        assert ds <= 1e-9, f"frame {k}: total solute {t['solute']!r} vs {start['solute']!r}"
        assert dv <= 1e-9, (f"frame {k}: solvent {t['solvent']!r} + evaporated {t['evaporated']!r} "
                            f"vs {start['solvent']!r}")

    sim, start, steps = run(open_fixture, 17, check)
    t = sim.totals()
    adsorbed = float((sim.densities()["adsorbed"] * sim.vertex_area).sum())
    print(f"tablecloth, {steps} sub-steps: solute defect <= {worst[0]:.2e}, solvent + evaporated "
          f"defect <= {worst[1]:.2e}; evaporated {t['evaporated']:.4e} of {start['solvent']:.4e} kg, "
          f"adsorbed {adsorbed:.3e} of {start['solute']:.3e} kg")
    assert steps >= 1000
    assert t["evaporated"] > 0.01 * start["solvent"]  # evaporation did act
    assert adsorbed > 0.01 * start["solute"]  # and adsorption


def test_tablecloth_2000_steps_stay_finite_and_non_negative(open_fixture):
    sim, start, steps = run(open_fixture, 34, lambda k, sim, start: sane_densities(k, sim))
    ds, dv = defects(sim, start)
    print(f"tablecloth, {steps} sub-steps: no NaN, no negative density; max wetness "
          f"{sim.wetness().max():.4f} kg/m², solute defect {ds:.2e}, solvent defect {dv:.2e}")
    assert steps >= 2000
    assert ds <= 1e-9 and dv <= 1e-9
