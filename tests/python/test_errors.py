"""The binding's one error mapping: every exception carries the core error's fields as
attributes (the element, frame, cell or parameter that failed), and file errors are the
built-in I/O kinds with `filename` and `errno`. The messages are the core's, unchanged."""

import errno
import os

import numpy as np
import pytest

import madder


def square():
    faces = madder.as_faces([[0, 1, 2], [0, 2, 3]])
    pos = madder.as_positions([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    return faces, pos


def test_mesh_errors_carry_face_and_vertex():
    with pytest.raises(madder.MeshError) as e:
        madder.Topology(madder.as_faces([[0, 1, 2], [0, 1, 9]]), 3)
    assert (e.value.face, e.value.vertex, e.value.n_vertices) == (1, 9, 3)
    assert e.value.frame is None and e.value.cell is None
    with pytest.raises(madder.MeshError) as e:
        madder.Topology(madder.as_faces([[0, 1, 2], [2, 2, 1]]), 3)
    assert (e.value.face, e.value.vertex) == (1, 2)


def test_non_finite_position_names_the_vertex_and_counts_mismatch_their_sizes():
    faces, pos = square()
    s = madder.DiffusionStepper(madder.Topology(faces, 4), pos, np.ones(4, np.float32), 0.01)
    bad = pos.copy()
    bad[3, 1] = np.inf
    with pytest.raises(madder.MeshError, match="vertex 3") as e:
        s.step(bad, 0.04)
    assert e.value.vertex == 3 and e.value.face is None
    with pytest.raises(madder.MeshError) as e:
        s.step(pos[:-1], 0.04)
    assert (e.value.expected, e.value.got) == (4, 3)


def test_parameter_errors_name_the_parameter_and_value():
    faces, pos = square()
    s = madder.DiffusionStepper(madder.Topology(faces, 4), pos, np.ones(4, np.float32), 0.01)
    with pytest.raises(madder.ParameterError) as e:
        s.step(pos, -0.5)
    assert e.value.name == "time step" and e.value.value == -0.5
    assert isinstance(e.value, ValueError) and e.value.vertex is None


def test_cache_errors_name_file_and_frame(tmp_path):
    path = tmp_path / "c.madder"
    w = madder.CacheWriter(str(path), 5, ["solute"], 4, 3)
    for k in range(3):
        w.push_frame([np.full(5, k, np.float32)])
    w.finish()
    path.write_bytes(path.read_bytes()[:-3])  # the last frame (6) is cut
    r = madder.CacheReader(str(path))
    with pytest.raises(madder.CacheError) as e:
        r.read_frame(6)
    assert (e.value.frame, e.value.first_cut, e.value.filename) == (6, 6, str(path))
    with pytest.raises(madder.CacheError) as e:
        r.read_frame(9)
    assert (e.value.frame, e.value.first, e.value.last) == (9, 4, 6)
    assert str(e.value).startswith(f"{path}: frame 9 is not in the cache")


def test_missing_files_are_file_not_found_errors(tmp_path):
    missing = str(tmp_path / "nowhere.madder")
    for open_it in (madder.CacheReader, madder.PointCache):
        path = missing if open_it is madder.CacheReader else missing.replace(".madder", ".pc2")
        with pytest.raises(FileNotFoundError) as e:
            open_it(path)
        assert isinstance(e.value, madder.CacheError) and isinstance(e.value, madder.MadderError)
        assert e.value.filename == path and e.value.errno == errno.ENOENT
        # the core's message, not OSError's "[Errno 2] ...: 'path'"
        assert str(e.value).startswith(f"{path}: ") and not str(e.value).startswith("[Errno")
    with pytest.raises(FileNotFoundError) as e:  # a writer into a missing folder
        madder.CacheWriter(str(tmp_path / "no" / "c.madder"), 3, ["solute"], 1, 1)
    assert e.value.errno == errno.ENOENT and e.value.filename.startswith(str(tmp_path / "no"))


def test_a_path_under_a_file_is_not_a_directory_error(tmp_path):
    blocker = tmp_path / "plain"
    blocker.write_text("not a folder")
    with pytest.raises(NotADirectoryError) as e:
        madder.CacheWriter(str(blocker / "c.madder"), 3, ["solute"], 1, 1)
    assert isinstance(e.value, madder.CacheError) and e.value.errno == errno.ENOTDIR
    assert e.value.filename.startswith(str(blocker))


def test_point_cache_errors_carry_frame_and_vertex(tmp_path):
    frames = np.zeros((3, 4, 3), np.float32)
    frames[:, :, 0] = np.arange(4)
    frames[1, 2, 1] = np.nan
    path = tmp_path / "nan.pc2"
    with pytest.raises(madder.CacheError) as e:
        madder.write_pc2(str(path), frames)
    assert (e.value.frame, e.value.vertex) == (1, 2)
    assert not os.path.exists(path)


def test_fabric_errors_name_the_cell():
    with pytest.raises(madder.FabricError) as e:
        madder.homogenize(np.array([[[1.0, 0, 1.0]], [[1.0, 3.0, 1.0]]]))
    assert e.value.cell == (1, 0) and (e.value.row, e.value.col) == (1, 0)
    with pytest.raises(madder.FabricError) as e:
        madder.fabric_tensor("CUSTOM", grid="FF\n..", coefficients=(1, 100, 500, 0.0, 50, 200))
    row, col = e.value.cell
    assert f"row {row}, column {col}" in str(e.value) and e.value.pair == "gap–weft" and e.value.value == 0.0
    with pytest.raises(madder.FabricError) as e:
        madder.fabric_tensor("CUSTOM", grid="Ff\nFx")
    assert (e.value.line, e.value.column, e.value.char) == (2, 2, "x") and e.value.cell is None
