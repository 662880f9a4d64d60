"""The angle representation (seed ch. 3) on the flag fixture's baked cloth frames, read
with real Blender: encode, decode, and compare with the frame's positions (to 1e-8 of the
bounding-box diagonal, after the reference triangle puts the result in place)."""

import bpy
import numpy as np
import pytest
from harness import frame_mesh

import madder


@pytest.mark.parametrize("frame", [1, 20, 48])
def test_flag_frames_round_trip(open_fixture, frame):
    scene = open_fixture("flag.blend")
    scene.frame_set(frame)
    faces, pos = frame_mesh(bpy.data.objects["Flag"])
    corners, dihedrals, edges = madder.encode_angles(faces, pos)
    assert len(edges) == len(dihedrals) > 0
    f = len(faces) // 2
    x = madder.decode_angles(faces, corners, dihedrals, reference_face=f, reference_positions=pos[faces[f]])
    diag = np.linalg.norm(pos.max(0) - pos.min(0))
    err = np.linalg.norm(x - pos, axis=1).max() / diag
    print(f"flag frame {frame}: {len(pos)} vertices, max error {err:.2e} of the diagonal")
    assert err <= 1e-8, err
    if frame > 1:
        # the cloth has moved off its rest plane: the dihedrals are not all zero
        assert np.abs(dihedrals).max() > 1e-3
