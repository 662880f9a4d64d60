"""The core's defaults and thresholds that Python reads (`madder.DEFAULT_DIFFUSION`,
`DEFAULT_SOLUTE_COLOR`, `DEGENERATE_UV_REL`): they are what the simulator does when told
nothing, and the add-on's count of degenerate UVs is the core's."""

import numpy as np
from test_core import blob, grid

import madder
from madder.addon import bridge


def test_the_simulators_defaults_are_the_constants():
    faces, pos = grid(12)
    told = madder.Simulator(faces, pos, pos, diffusion=madder.DEFAULT_DIFFUSION, color=madder.DEFAULT_SOLUTE_COLOR)
    untold = madder.Simulator(faces, pos, pos)
    for sim in (told, untold):
        sim.add_liquid(0.5 * blob(pos), 0.05)
        for _ in range(6):
            sim.step(pos, 1 / 24)
    a, b = told.densities(), untold.densities()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)  # bit for bit
    np.testing.assert_array_equal(told.stain(), untold.stain())
    np.testing.assert_allclose(untold.solute_color()[0], madder.DEFAULT_SOLUTE_COLOR, rtol=1e-6)


def test_the_add_on_counts_degenerate_uvs_as_the_core_does():
    faces, pos = grid(6)
    uv = np.ascontiguousarray(pos[:, :2][faces].astype(np.float32))
    # collapse two faces' UVs (to a point, to a line) and thin a third one, which keeps a
    # u axis (its relative determinant, ~1e-6, is far above the threshold)
    uv[0] = uv[0, 0]
    uv[1, 2] = uv[1, 0] + 2 * (uv[1, 1] - uv[1, 0])
    uv[2, 2] = uv[2, 0] + 2 * (uv[2, 1] - uv[2, 0]) + np.float32(1e-6) * (uv[2, 2] - uv[2, 0])
    t = madder.Topology(faces, len(pos))
    stepper = madder.DiffusionStepper(
        t, pos, blob(pos), face_tensors=np.tile([1e-3, 0.0, 1e-3], (len(faces), 1)), face_uv=uv
    )
    stepper.step(pos, 1 / 24)
    assert stepper.degenerate_uv_faces == bridge.degenerate_uv_faces(uv) == 2
