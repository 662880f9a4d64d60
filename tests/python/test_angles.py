"""madder.encode_angles and madder.decode_angles (seed ch. 3) through the binding: angles
against numpy computed here, exact round trips up to a similarity (Procrustes computed
here) and with a reference triangle, the sequential method, bad input named."""

import numpy as np
import pytest

import madder


def torus(nu=24, nv=10):
    """A torus (F, 3) uint32, (N, 3) float64, radii 1 and 0.4, slightly twisted."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    u = 2 * np.pi * i.ravel() / nu
    v = 2 * np.pi * j.ravel() / nv + 0.3 * np.sin(u)
    r = 1.0 + 0.4 * np.cos(v)
    pos = np.stack([r * np.cos(u), r * np.sin(u), 0.4 * np.sin(v)], axis=1)
    a = i.ravel() * nv + j.ravel()
    b = ((i.ravel() + 1) % nu) * nv + j.ravel()
    c = ((i.ravel() + 1) % nu) * nv + (j.ravel() + 1) % nv
    d = i.ravel() * nv + (j.ravel() + 1) % nv
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.uint32)
    return faces, pos


def procrustes_rms(x, ref):
    """RMS distance after the best similarity, over the bounding-box diagonal of ref."""
    xc, rc = x - x.mean(0), ref - ref.mean(0)
    u, s, vt = np.linalg.svd(rc.T @ xc)
    d = np.sign(np.linalg.det(u @ vt))
    dd = np.array([1.0, 1.0, d])
    rot = u @ np.diag(dd) @ vt
    scale = (s * dd).sum() / (xc**2).sum()
    err = scale * xc @ rot.T - rc
    diag = np.linalg.norm(ref.max(0) - ref.min(0))
    return np.sqrt((err**2).sum(1).mean()) / diag


def test_encode_matches_numpy():
    faces, pos = torus()
    corners, dihedrals, edges = madder.encode_angles(faces, pos)
    assert corners.shape == (len(faces), 3)
    assert edges.shape == (len(dihedrals), 2)
    assert len(dihedrals) == 3 * len(faces) // 2  # closed: every edge interior
    p = pos[faces]
    for c in range(3):
        u = p[:, (c + 1) % 3] - p[:, c]
        w = p[:, (c + 2) % 3] - p[:, c]
        cos = (u * w).sum(1) / np.linalg.norm(u, axis=1) / np.linalg.norm(w, axis=1)
        np.testing.assert_allclose(corners[:, c], np.arccos(cos), atol=1e-12)
    # dihedrals: the turn between the two faces' normals about the edge a -> b
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    where = {}
    for f, t in enumerate(faces):
        for k in range(3):
            where[(int(t[k]), int(t[(k + 1) % 3]))] = f
    for (a, b), th in zip(edges, dihedrals, strict=True):
        n1, n2 = normals[where[(a, b)]], normals[where[(b, a)]]
        e = (pos[b] - pos[a]) / np.linalg.norm(pos[b] - pos[a])
        assert th == pytest.approx(np.arctan2(np.cross(n1, n2) @ e, n1 @ n2), abs=1e-12)


def test_round_trip():
    faces, pos = torus()
    corners, dihedrals, _ = madder.encode_angles(faces, pos)
    x = madder.decode_angles(faces, corners, dihedrals)
    assert x.shape == pos.shape
    assert procrustes_rms(x, pos) < 1e-8
    # a reference triangle puts it back in place
    f = 17
    placed = madder.decode_angles(faces, corners, dihedrals, reference_face=f, reference_positions=pos[faces[f]])
    np.testing.assert_allclose(placed, pos, atol=1e-8)
    seq = madder.decode_angles(
        faces,
        corners,
        dihedrals,
        method="sequential",
        reference_face=f,
        reference_positions=pos[faces[f]],
    )
    np.testing.assert_allclose(seq, pos, atol=1e-8)
    refined = madder.decode_angles(faces, corners, dihedrals, refine_iterations=3)
    assert procrustes_rms(refined, pos) < 1e-8


def test_bad_input_is_named():
    faces, pos = torus()
    corners, dihedrals, edges = madder.encode_angles(faces, pos)
    bad = corners.copy()
    bad[4, 1] = np.nan
    with pytest.raises(madder.ParameterError) as e:
        madder.decode_angles(faces, bad, dihedrals)
    assert (e.value.face, e.value.corner) == (4, 1)
    bad = dihedrals.copy()
    bad[9] = np.inf
    with pytest.raises(madder.ParameterError) as e:
        madder.decode_angles(faces, corners, bad)
    assert e.value.index == 9 and tuple(e.value.edge) == tuple(edges[9])
    with pytest.raises(madder.ParameterError) as e:
        madder.decode_angles(faces, corners, dihedrals[:-1])
    assert (e.value.expected, e.value.got) == (len(dihedrals), len(dihedrals) - 1)
    with pytest.raises(madder.ParameterError):
        madder.decode_angles(faces, corners, dihedrals, method="magic")
    with pytest.raises(madder.ParameterError):
        madder.decode_angles(faces, corners, dihedrals, reference_face=0)
    fin = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]], dtype=np.uint32)
    with pytest.raises(madder.MeshError) as e:
        madder.encode_angles(fin, np.random.default_rng(0).random((5, 3)))
    assert tuple(e.value.edge) == (0, 1) and e.value.faces == 3
    with pytest.raises(madder.MeshError):
        madder.encode_angles(faces, pos[:-1])


def test_tracked_follows_the_previous_frame():
    faces, pos = torus()
    corners, dihedrals, _ = madder.encode_angles(faces, pos)
    # the previous frame: the same torus bent about the z axis by an angle growing with x
    ang = 0.2 * pos[:, 0]
    c, s = np.cos(ang), np.sin(ang)
    previous = np.stack([c * pos[:, 0] - s * pos[:, 1], s * pos[:, 0] + c * pos[:, 1], pos[:, 2]], 1)
    f = 17
    x = madder.decode_angles(
        faces,
        corners,
        dihedrals,
        method="tracked",
        previous=previous,
        reference_face=f,
        reference_positions=pos[faces[f]],
    )
    np.testing.assert_allclose(x, pos, atol=1e-9)
    # the spectral method warm-started from the same frame agrees
    warm = madder.decode_angles(faces, corners, dihedrals, previous=previous)
    assert procrustes_rms(warm, pos) < 1e-8
    # without a previous frame the tracked method starts from rotations composed along a tree
    cold = madder.decode_angles(faces, corners, dihedrals, method="tracked")
    assert procrustes_rms(cold, pos) < 1e-8
    with pytest.raises(madder.ParameterError):
        madder.decode_angles(faces, corners, dihedrals, method="tracked", previous=previous[:-1])
    with pytest.raises(madder.ParameterError, match="sequential"):
        madder.decode_angles(faces, corners, dihedrals, method="sequential", previous=previous)
    # the optional descent runs after the tracked fit too (exact angles: nothing to lower)
    refined = madder.decode_angles(faces, corners, dihedrals, method="tracked", previous=previous, refine_iterations=2)
    assert procrustes_rms(refined, pos) < 1e-8
    bad = previous.copy()
    bad[5, 2] = np.nan
    with pytest.raises(madder.MeshError) as e:
        madder.decode_angles(faces, corners, dihedrals, method="tracked", previous=bad)
    assert e.value.vertex == 5
