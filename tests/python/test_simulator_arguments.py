"""`madder.Simulator`'s array arguments (issue 10, item 7): float64 positions are taken as
they are, and a wrong array is refused with an error naming the argument at fault."""

import numpy as np
import pytest
from test_core import blob, grid

import madder

DT = 1 / 24


def tilted(pos, angle=0.3):
    """The grid turned about the x axis, so gravity runs the liquid downhill."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float32)
    return np.ascontiguousarray(pos @ rot.T, dtype=np.float32)


def run(rest, pos, frames=6):
    """Solute density after `frames` frames of a blob running down a still, tilted grid."""
    faces, _ = grid(12)
    sim = madder.Simulator(faces, rest, pos, friction=5.0)
    sim.add_liquid(0.4 * blob(pos.astype(np.float32)), 0.03)
    for _ in range(frames):
        sim.step(pos, DT, after=pos)
    return sim.stain()[:, 3]


def test_float64_positions_bake_like_the_same_float32_ones():
    _, flat = grid(12)
    pos32 = tilted(flat)
    pos64 = pos32.astype(np.float64)  # the same values, exactly
    expected = run(pos32, pos32)
    assert expected.max() > 0
    np.testing.assert_array_equal(run(pos64, pos64), expected)
    np.testing.assert_array_equal(run(pos32, pos64), expected)


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda faces, pos: madder.Simulator(faces, pos.astype(np.int32), pos),
         ["rest", "float array (any float dtype)", "int32"]),
        (lambda faces, pos: madder.Simulator(faces, pos, pos[:, :2].copy()), ["positions", "(N, 3)", "(169, 2)"]),
        (lambda faces, pos: madder.Simulator(faces, pos[:-5], pos), ["rest has 164 rows", "positions has 169"]),
        (lambda faces, pos: madder.Simulator(madder.Topology(faces, 169), pos[:-5], pos[:-5]),
         ["rest and positions have 164 rows", "topology has 169 vertices"]),
        (lambda faces, pos: madder.Simulator(faces, pos, pos, face_angle=np.zeros(len(faces), np.float32)),
         ["face_angle", "face_tensors and face_uv"]),
    ],
    ids=["int-rest", "2-column-positions", "short-rest", "short-both", "face-angle-alone"],
)
def test_bad_arrays_name_the_argument(make, words):
    faces, pos = grid(12)
    with pytest.raises(madder.ParameterError) as e:
        make(faces, pos)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_step_names_the_after_argument():
    faces, pos = grid(12)
    sim = madder.Simulator(faces, pos, pos)
    with pytest.raises(madder.ParameterError, match=r"after must be a float array \(any float dtype\)"):
        sim.step(pos, DT, after=pos.astype(np.int16))
