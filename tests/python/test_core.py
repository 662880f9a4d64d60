"""The `madder` Python API without Blender: typed errors that name the bad element,
conservation and determinism through the binding, and the cache file's guarantees."""

import os

import numpy as np
import pytest

import madder


def grid(n, size=1.0):
    """(n+1)² vertices on [0, size]², two triangles per quad."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, c, d = a + 1, a + n + 2, a + n + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    x, y = np.meshgrid(np.linspace(0, size, n + 1), np.linspace(0, size, n + 1), indexing="ij")
    pos = np.stack([y.ravel(), x.ravel(), np.zeros(x.size)], 1)
    return madder.as_faces(faces), madder.as_positions(pos)


def blob(pos, centre=(0.5, 0.5), r=0.1):
    d2 = ((pos[:, :2] - np.asarray(centre)) ** 2).sum(1)
    return np.exp(-d2 / (2 * r * r)).astype(np.float32)


def lumped_areas(faces, pos):
    """Independent numpy lumped mass: one third of each incident face area."""
    p = pos.astype(np.float64)
    e1, e2 = p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    out = np.zeros(len(p))
    for k in range(3):
        np.add.at(out, faces[:, k], area / 3)
    return out


def test_topology_reports_boundary_non_manifold_and_loose():
    faces = madder.as_faces([[0, 1, 2], [1, 0, 3], [0, 1, 4]])  # three faces on edge 0–1
    t = madder.Topology(faces, 6)
    assert t.non_manifold_edges().tolist() == [[0, 1]]
    assert t.loose_vertices().tolist() == [5]
    assert len(t.boundary_edges()) == 6


@pytest.mark.parametrize(
    "faces, n, words",
    [
        ([[0, 1, 2], [0, 1, 9]], 3, ["face 1", "vertex 9"]),
        ([[0, 1, 2], [2, 2, 1]], 3, ["face 1", "more than once"]),
    ],
)
def test_bad_topology_is_a_mesh_error_naming_the_face(faces, n, words):
    with pytest.raises(madder.MeshError) as e:
        madder.Topology(madder.as_faces(faces), n)
    assert isinstance(e.value, ValueError) and isinstance(e.value, madder.MadderError)
    for w in words:
        assert w in str(e.value)


def test_step_errors_name_the_vertex_and_leave_state_unchanged():
    faces, pos = grid(8)
    s = madder.DiffusionStepper(madder.Topology(faces, len(pos)), pos, blob(pos), 0.01)
    before = s.density.copy()
    bad = pos.copy()
    bad[17, 2] = np.nan
    with pytest.raises(madder.MeshError, match="vertex 17"):
        s.step(bad, 0.04)
    with pytest.raises(madder.MeshError, match="expected 81"):
        s.step(pos[:-1], 0.04)
    with pytest.raises(madder.ParameterError, match="time step"):
        s.step(pos, 0.0)
    with pytest.raises(madder.ParameterError, match="diffusion rate"):
        madder.DiffusionStepper(madder.Topology(faces, len(pos)), pos, blob(pos), -1.0)
    np.testing.assert_array_equal(s.density, before)


def test_mass_is_conserved_against_an_independent_area_computation():
    faces, rest = grid(30)
    s = madder.DiffusionStepper(madder.Topology(faces, len(rest)), rest, blob(rest), 0.01)
    m0 = float(lumped_areas(faces, rest) @ s.density.astype(np.float64))
    for k in range(1, 21):
        p = rest.copy()
        p[:, 0] *= 1 + 0.05 * k  # stretching cloth
        p[:, 2] = 0.1 * np.sin(3 * p[:, 1] + 0.2 * k)
        s.step(madder.as_positions(p), 1 / 24)
        m = float(lumped_areas(faces, p) @ s.density.astype(np.float64))
        assert abs(m - m0) / m0 < 1e-6  # float32 densities at the boundary
        assert abs(s.total_mass() - m0) / m0 < 1e-11  # float64 inside
    assert s.density.max() < 0.7  # it did spread


def test_results_do_not_depend_on_thread_count():
    faces, pos = grid(40)
    out = []
    for threads in (1, 2):
        s = madder.DiffusionStepper(madder.Topology(faces, len(pos)), pos, blob(pos), 0.02, threads=threads)
        for k in range(5):
            s.step(madder.as_positions(pos * (1 + 0.02 * k)), 0.04, substeps=2)
        out.append(s.density)
    assert out[0].tobytes() == out[1].tobytes()


def write_cache(path, values):
    w = madder.CacheWriter(str(path), values.shape[1], ["density"], 10, len(values))
    for row in values:
        w.push_frame([row])
    return w.finish()


def test_cache_round_trip(tmp_path):
    values = np.random.default_rng(0).random((4, 50), dtype=np.float32)
    write_cache(tmp_path / "a.madder", values)
    r = madder.CacheReader(str(tmp_path / "a.madder"))
    assert (r.first_frame, r.last_frame, r.n_vertices, r.fields) == (10, 13, 50, ["density"])
    for k in range(4):
        np.testing.assert_array_equal(r.read(10 + k, "density"), values[k])


def test_truncated_and_corrupt_caches_name_file_and_frame(tmp_path):
    path = tmp_path / "t.madder"
    write_cache(path, np.ones((5, 100), dtype=np.float32))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 500])  # cut into the last two frames (400 bytes each)
    r = madder.CacheReader(str(path))  # the frames before the cut still play
    assert r.truncated_at == 13
    np.testing.assert_array_equal(r.read(12, "density"), np.ones(100, dtype=np.float32))
    for frame in (13, 14):
        with pytest.raises(madder.CacheError) as e:
            r.read(frame, "density")
        assert "t.madder" in str(e.value) and f"frame {frame} is not in it" in str(e.value)
        assert "truncated at frame 13" in str(e.value) and isinstance(e.value, OSError)
    path.write_bytes(data)
    assert madder.CacheReader(str(path)).truncated_at is None
    corrupt = bytearray(data)
    corrupt[-20] ^= 1
    path.write_bytes(bytes(corrupt))
    with pytest.raises(madder.CacheError, match="frame 14"):
        madder.CacheReader(str(path)).read(14, "density")


def test_aborted_writer_keeps_the_previous_cache(tmp_path):
    path = tmp_path / "keep.madder"
    write_cache(path, np.zeros((2, 10), dtype=np.float32))
    before = path.read_bytes()
    w = madder.CacheWriter(str(path), 10, ["density"], 1, 3)
    w.push_frame([np.ones(10, dtype=np.float32)])
    w.abort()
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["keep.madder"]
    with pytest.raises(madder.CacheError, match="already closed"):
        w.push_frame([np.ones(10, dtype=np.float32)])
