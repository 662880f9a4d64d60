"""The Coherent Structures tool's bpy-free logic (`madder.addon.lcs`), without Blender: the
checks of a request against a cache (each failure names the object, the frame and the
file), the flow read back as written, FTLE through `compute` against a direct
`madder.ftle` call on the same arrays, and the ridge graph split into polylines."""

import numpy as np
import pytest
from test_lcs import grid

import madder
from madder.addon import bridge, lcs
from madder.addon.errors import LcsError

DT = 1.0 / 24.0
FIRST, N_FRAMES = 5, 9


def swirl(t, pos):
    """A time-dependent tangent flow in the plane z = 0 (a slowly turning saddle)."""
    x, y = pos[:, 0] - 1.0, pos[:, 1] - 0.5
    a = 0.8 + 0.3 * np.sin(2.0 * t)
    return np.stack([a * x, -a * y + 0.2 * x, np.zeros_like(x)], axis=1)


def flow_cache(path, flow=True, frame_time=DT):
    faces, rest = grid(20, 10)
    n = len(rest)
    fields = bridge.FIELDS + (bridge.FLOW_FIELDS if flow else [])
    w = madder.CacheWriter(str(path), n, fields, FIRST, N_FRAMES, frame_time)
    positions, velocity = [], []
    for k in range(N_FRAMES):
        t = (FIRST + k) * DT
        pos = rest + np.array([0.0, 0.0, 0.1 * k])  # the cloth rises: a rigid motion
        vel = swirl(t, rest)
        positions.append(pos.astype(np.float32))
        velocity.append(vel.astype(np.float32))
        stain = [np.zeros(n, np.float32) for _ in bridge.FIELDS]
        extra = [np.ascontiguousarray(a[:, c]) for a in (velocity[-1], positions[-1]) for c in range(3)]
        w.push_frame(stain + (extra if flow else []))
    w.finish()
    return faces, np.array(positions, dtype=np.float64), np.array(velocity, dtype=np.float64)


def test_flow_reads_back_and_ftle_matches_a_direct_call(tmp_path):
    path = tmp_path / "c.madder"
    faces, positions, velocity = flow_cache(path)
    r = madder.CacheReader(str(path))
    assert r.version == 2 and r.frame_time == pytest.approx(DT, rel=0, abs=0)
    times, pos, vel = lcs.read_flow(r, FIRST + 2, FIRST + 6)
    np.testing.assert_array_equal(pos, positions[2:7])
    np.testing.assert_array_equal(vel, velocity[2:7])
    np.testing.assert_array_equal(times, np.arange(FIRST + 2, FIRST + 7) * DT)
    seen = []
    out = lcs.compute(madder, "Cloth", str(path), r, faces, FIRST + 6, 4, lcs.BACKWARD, 3,
                      {"min_edges": 0, "min_branch": 0}, progress=lambda d, t: seen.append((d, t)))
    want = madder.ftle(faces, positions[2:7], velocity[2:7], (FIRST + 6) * DT, -4 * DT, steps=12,
                       times=np.arange(FIRST + 2, FIRST + 7) * DT)
    np.testing.assert_array_equal(out.sigma, want)
    assert np.isfinite(out.sigma).all() and out.sigma.max() > 0.5  # the saddle stretches
    assert (out.first, out.last) == (FIRST + 2, FIRST + 6)
    np.testing.assert_array_equal(out.positions, positions[6])
    assert seen[-1] == (7, 7) and [d for d, _ in seen] == sorted(d for d, _ in seen)


@pytest.mark.parametrize(
    "frame, span, direction, match",
    [
        (FIRST, 0, lcs.FORWARD, "span is 0 frames"),
        (FIRST - 1, 2, lcs.FORWARD, f"frame {FIRST - 1} is outside the bake \\(frames {FIRST}–{FIRST + 8}\\)"),
        (FIRST + 8, 1, lcs.FORWARD, f"needs frames {FIRST + 8}–{FIRST + 9}, the bake has {FIRST}–{FIRST + 8}"),
        (FIRST + 1, 2, lcs.BACKWARD, f"needs frames {FIRST - 1}–{FIRST + 1}"),
    ],
)
def test_bad_requests_name_object_and_frame(tmp_path, frame, span, direction, match):
    path = tmp_path / "c.madder"
    flow_cache(path)
    r = madder.CacheReader(str(path))
    with pytest.raises(LcsError, match=match) as e:
        lcs.check("Cloth", str(path), r, frame, span, direction)
    assert "'Cloth'" in str(e.value) and (e.value.object, e.value.frame) == ("Cloth", frame)


def test_a_cache_without_velocity_says_rebake_with_velocity(tmp_path):
    path = tmp_path / "c.madder"
    flow_cache(path, flow=False)
    r = madder.CacheReader(str(path))
    with pytest.raises(LcsError, match="has no velocity.*rebake with velocity") as e:
        lcs.check("Cloth", str(path), r, FIRST, 2, lcs.FORWARD)
    assert e.value.filename == str(path) and str(path) in str(e.value)
    flow_cache(path, frame_time=0.0)
    with pytest.raises(LcsError, match="records no single frame time"):
        lcs.check("Cloth", str(path), madder.CacheReader(str(path)), FIRST, 2, lcs.FORWARD)


def test_polylines_cover_every_edge_once():
    # a T (0-1-2, 1-3-4), a closed square 5-6-7-8 and a lone edge 9-10
    edges = [(0, 1), (1, 2), (1, 3), (3, 4), (5, 6), (6, 7), (7, 8), (8, 5), (9, 10)]
    lines = lcs.polylines(11, edges)
    seen = []
    for chain, cyclic in lines:
        pairs = list(zip(chain, chain[1:] + (chain[:1] if cyclic else []), strict=False))
        seen += [tuple(sorted(p)) for p in pairs]
    assert sorted(seen) == sorted(tuple(sorted(e)) for e in edges)
    assert sum(c for _, c in lines) == 1 and len(lines) == 5  # 3 branches at the junction, the loop, the edge
    loop = next(ch for ch, c in lines if c)
    assert sorted(loop) == [5, 6, 7, 8]
    assert lcs.polylines(3, np.zeros((0, 2))) == []


def test_binding_is_the_triangle_corners_and_weights():
    faces = np.array([[0, 1, 2], [2, 1, 3]], dtype=np.uint32)
    v, w = lcs.binding(faces, np.array([1, 0]), np.array([[0.2, 0.3, 0.5], [1.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(v, [[2, 1, 3], [0, 1, 2]])
    np.testing.assert_allclose(w, [[0.2, 0.3, 0.5], [1.0, 0.0, 0.0]])
