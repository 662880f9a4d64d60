"""One convention for the array arguments of `madder._core` (issue 36, part 4).

Every array argument takes any float dtype (float16, float32, float64) in any layout (C or
Fortran order, strided views, nested lists) and every index argument any integer dtype,
converted once: the same values give the same result bit for bit, whatever dtype or layout
holds them. A non-numeric array, a float array where indices are meant, or a negative index
is a `ParameterError` naming the argument.

Each case below calls one function or method with its array arguments made by `A`: `A.f`
for a float argument, `A.i` for an index argument, each with the argument's name (what the
error message must say). The base values are float16-representable, so float16 and float32
hold them exactly."""

import numpy as np
import pytest

import madder

N = 4  # a 4 × 4 grid of the unit square: 25 vertices, 32 faces


def f16(a):
    """`a` as float64 values that float16 holds exactly."""
    return np.asarray(a, np.float64).astype(np.float16).astype(np.float64)


def grid(n=N):
    """(F, 3) uint32 faces and (N, 3) float64 positions of a slightly curved n × n grid."""
    j, i = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    a = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    b, c, d = a + 1, a + n + 2, a + n + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.uint32)
    x, y = j.ravel() / n, i.ravel() / n
    pos = f16(np.stack([x, y, 0.25 * x * y], 1))
    return faces, pos


FACES, POS = grid()
NV, NF = len(POS), len(FACES)
UV = f16(POS[FACES][:, :, :2])  # (F, 3, 2): UV = position
MOVED = f16(POS + [0.0625, 0.0, 0.125])
DENSITY = f16(np.exp(-((POS[:, 0] - 0.5) ** 2 + (POS[:, 1] - 0.5) ** 2) * 8))
TENSORS = f16(np.tile([2e-4, 2.5e-5, 1e-4], (NF, 1)))
ANGLE = f16(np.linspace(0.0, 0.5, NF))
COLORS = f16(np.tile([0.5, 0.25, 0.125], (NV, 1)))
FRAMES = np.stack([POS, MOVED, f16(MOVED * 1.125)])  # (3, N, 3)
TIMES = np.array([0.0, 0.5, 1.0])
VELOCITY = f16(np.tile([0.25, 0.125, 0.0], (3, NV, 1)))


class Maker:
    """Makes the array arguments of one call: as they are (`variant` None), converted by
    `variant`, or (`bad`, a name) with that one argument spoilt by `spoil`."""

    def __init__(self, variant=None, bad=None, spoil=None):
        self.variant, self.bad, self.spoil, self.names = variant, bad, spoil, []

    def f(self, name, a):
        return self.make(name, "f", np.asarray(a, np.float64))

    def i(self, name, a):
        return self.make(name, "i", np.asarray(a, np.uint32))

    def make(self, name, kind, a):
        self.names.append((name, kind))
        if self.bad is not None:
            return self.spoil(a) if name == self.bad else a
        return a if self.variant is None else VARIANTS[self.variant][kind](a)


def strided(a, dtype):
    """`a` as a non-contiguous view: every other row (and, from 2-D, every other column)."""
    big = np.repeat(np.asarray(a, dtype), 2, axis=0)
    if big.ndim > 1:
        big = np.repeat(big, 2, axis=1)[:, ::2]
    out = big[::2]
    assert not out.flags.c_contiguous or out.size <= 1
    return out


VARIANTS = {
    "float32-int64": {"f": lambda a: a.astype(np.float32), "i": lambda a: a.astype(np.int64)},
    "float16-int32": {"f": lambda a: a.astype(np.float16), "i": lambda a: a.astype(np.int32)},
    "strided": {"f": lambda a: strided(a, np.float64), "i": lambda a: strided(a, np.uint32)},
    "strided32-uint16": {"f": lambda a: strided(a, np.float32), "i": lambda a: strided(a, np.uint16)},
    "fortran": {"f": np.asfortranarray, "i": lambda a: np.asfortranarray(a, np.int64)},
    "fortran32-reversed": {
        "f": lambda a: np.asfortranarray(a, np.float32),
        "i": lambda a: np.ascontiguousarray(np.asarray(a, np.int16)[::-1])[::-1],
    },
    "lists": {"f": lambda a: a.tolist(), "i": lambda a: a.tolist()},
}


def topology(A):
    t = madder.Topology(A.i("faces", FACES), NV, face_polygon=A.i("face_polygon", np.arange(NF) // 2))
    return [t.n_edges, t.n_polygons, t.boundary_edges()]


def weft_directions(A):
    t = madder.Topology(FACES, NV)
    return madder.weft_directions(t, A.f("positions", MOVED), A.f("face_uv", UV), A.f("face_angle", ANGLE))


def distances_within(A):
    points = f16(POS[::3] + [0.0, 0.0, 0.25])
    return madder.distances_within(A.f("points_", points), A.f("vertices", POS), A.i("triangles", FACES), 0.5)


def refinement_face_uv(A):
    return madder.Refinement(madder.Topology(FACES, NV), 1).face_uv(A.f("face_uv", UV))


def diffusion_stepper(A):
    t = madder.Topology(FACES, NV)
    s = madder.DiffusionStepper(t, A.f("positions", POS), A.f("density", DENSITY), 1e-3)
    s.enable_color(A.f("colors", COLORS))
    s.add_liquid(A.f("delta", DENSITY[::-1].copy()), color=(0.0, 0.5, 1.0))
    s.step(A.f("positions", MOVED), 0.1)
    return [s.density, s.color, s.vertex_area]


def diffusion_stepper_woven(A):
    t = madder.Topology(FACES, NV)
    s = madder.DiffusionStepper(
        t, POS, DENSITY, face_tensors=A.f("face_tensors", TENSORS), face_uv=A.f("face_uv", UV),
        face_angle=A.f("face_angle", ANGLE),
    )
    s.step(MOVED, 0.1)
    return [s.density]


def simulator(A):
    sim = madder.Simulator(
        A.i("topology", FACES), A.f("rest", POS), A.f("positions", POS), face_tensors=A.f("face_tensors", TENSORS),
        face_uv=A.f("face_uv", UV), face_angle=A.f("face_angle", ANGLE),
    )
    sim.add_liquid(A.f("solvent", 0.5 * DENSITY))
    sim.splash((0.5, 0.5, 0.0), 0.25, 7, A.f("weights", DENSITY))
    sim.velocity = A.f("velocity", np.tile([0.125, 0.0625, 0.0], (NV, 1)))
    sim.step(A.f("positions", MOVED), 1 / 24, after=A.f("after", FRAMES[2]))
    return [sim.stain(), sim.wetness(), sim.velocity, *sim.densities().values()]


def ftle(A):
    return madder.ftle(
        A.i("faces", FACES), A.f("positions", FRAMES), A.f("velocity", VELOCITY), 0.0, 0.75, steps=4,
        times=A.f("times", TIMES),
    )


def ridges(A):
    field = f16(np.sin(3 * POS[:, 0]) * np.cos(2 * POS[:, 1]))
    r = madder.ridges(A.i("faces", FACES), A.f("positions", MOVED), A.f("field", field), min_edges=0, min_branch=0)
    return [r[k] for k in sorted(r)]


def encode_angles(A):
    return list(madder.encode_angles(A.i("faces", FACES), A.f("positions", MOVED)))


def decode_angles(A):
    corners, dihedrals, _ = madder.encode_angles(FACES, MOVED)
    return madder.decode_angles(
        A.i("faces", FACES), A.f("corners", f16(corners)), A.f("dihedrals", f16(dihedrals)), reference_face=0,
        reference_positions=A.f("reference_positions", POS[FACES[0]]), previous=A.f("previous", MOVED),
    )


def homogenize(A):
    tensors = f16([[[1.0, 0.0, 1.0], [2.0, 0.25, 1.0]], [[1.0, -0.25, 2.0], [0.5, 0.0, 0.5]]])
    return madder.homogenize(A.f("tensors", tensors))


def rasterize(A):
    values = f16(np.c_[DENSITY, COLORS[:, :2]])
    image, overlapping = madder.rasterize(A.i("faces", FACES), A.f("uv", UV), A.f("values", values), 16, 2)
    return [image, overlapping]


def rasterize_weave(A):
    detail = madder.WeaveDetail(
        [madder.fabric_corrector("PLAIN")], A.i("face_fabric", np.zeros(NF)),
        A.f("face_map", np.tile(np.eye(2) * 8, (NF, 1, 1))), [True],
    )
    image, _ = madder.rasterize(FACES, UV, DENSITY.astype(np.float32), 16, 0, weave=detail)
    return image


# a stain with dry cloth round it (float16 holds its values): the outline has a front
STAINED = np.where(DENSITY > 0.3, DENSITY, 0.0)


def outline(A):
    return madder.Outline(A.i("faces", FACES), NV, 1).fields(A.f("coverage", STAINED))


def sharpen_outline(A):
    fields = f16(madder.rasterize(FACES, UV, madder.Outline(FACES, NV, 1).fields(STAINED), 16, 2)[0])
    stain, _ = madder.rasterize(FACES, UV, np.c_[STAINED, STAINED, STAINED, STAINED], 16, 2)
    madder.sharpen_outline(A.f("fields", fields), stain)
    return stain


def lift_outline(A):
    fields = f16(madder.rasterize(FACES, UV, madder.Outline(FACES, NV, 1).fields(STAINED), 16, 2)[0])
    stain, _ = madder.rasterize(FACES, UV, np.c_[STAINED, STAINED, STAINED, STAINED], 16, 2)
    madder.lift_outline(A.f("fields", fields), (0.01, 0.02), stain)
    return stain


def write_exr(A, path):
    image = f16(np.stack([np.outer(np.linspace(0, 1, 4), np.linspace(1, 2, 5))] * 3, -1))
    madder.write_exr(path, A.f("image", image), ["R", "G", "B"])
    return path.read_bytes()


def cache_writer(A, path):
    w = madder.CacheWriter(str(path), NV, ["a", "b"], 1, 1)
    w.push_frame([A.f("fields[0]", DENSITY), A.f("fields[1]", DENSITY[::-1].copy())])
    w.finish()
    return path.read_bytes()


def write_pc2(A, path):
    madder.write_pc2(path, A.f("frames", FRAMES))
    return path.read_bytes()


def write_mdd(A, path):
    madder.write_mdd(path, A.f("frames", FRAMES), [0.0, 0.5, 1.0])
    return path.read_bytes()


def pc2_writer(A, path):
    w = madder.Pc2Writer(path, NV)
    w.add_frame(A.f("positions", MOVED))
    w.finish()
    return path.read_bytes()


def motion_encoder(A, path):
    enc = madder.MotionEncoder(path, A.i("faces", FACES))
    out = [enc.add_frame(A.f("positions", frame)) for frame in FRAMES]
    enc.finish()
    return [*out, path.read_bytes()]


def position_baseline_stats(A):
    s = madder.position_baseline_stats(A.f("frames", FRAMES), 8)
    return [s[k] for k in sorted(s)]


CASES = {
    f.__name__: f
    for f in [
        topology, weft_directions, distances_within, refinement_face_uv, diffusion_stepper, diffusion_stepper_woven,
        simulator, ftle, ridges, encode_angles, decode_angles, homogenize, rasterize, rasterize_weave,
        outline, sharpen_outline, lift_outline, position_baseline_stats,
    ]
}
FILE_CASES = {f.__name__: f for f in [write_exr, cache_writer, write_pc2, write_mdd, pc2_writer, motion_encoder]}
ALL = {**CASES, **FILE_CASES}


def call(name, A, tmp_path, tag):
    if name in FILE_CASES:
        return FILE_CASES[name](A, tmp_path / f"{tag}.{name}")
    return CASES[name](A)


def flat(result):
    """The result as a list of numpy arrays (and bytes), to compare exactly."""
    items = result if isinstance(result, list) else [result]
    return [r if isinstance(r, bytes) else np.asarray(r) for r in items]


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("name", list(ALL))
def test_any_float_dtype_and_layout_give_the_same_result(name, variant, tmp_path):
    expected = flat(call(name, Maker(), tmp_path, "base"))
    got = flat(call(name, Maker(variant), tmp_path, variant))
    assert len(got) == len(expected)
    for g, e in zip(got, expected, strict=True):
        if isinstance(e, bytes):
            assert g == e
        else:
            assert g.dtype == e.dtype
            np.testing.assert_array_equal(g, e)


# the array arguments of every case, `name:kind` (f float, i index): every function and
# method of `madder._core` that takes arrays (output buffers, `rasterize(out=)` and
# `CacheReader.read_stain`'s, are not arguments of this kind)
ARGS = {
    "topology": "faces:i face_polygon:i",
    "weft_directions": "positions:f face_uv:f face_angle:f",
    "distances_within": "points_:f vertices:f triangles:i",
    "refinement_face_uv": "face_uv:f",
    "diffusion_stepper": "positions:f density:f colors:f delta:f",
    "diffusion_stepper_woven": "face_tensors:f face_uv:f face_angle:f",
    "simulator": "topology:i rest:f positions:f face_tensors:f face_uv:f face_angle:f solvent:f weights:f "
                 "velocity:f after:f",
    "ftle": "faces:i positions:f velocity:f times:f",
    "ridges": "faces:i positions:f field:f",
    "encode_angles": "faces:i positions:f",
    "decode_angles": "faces:i corners:f dihedrals:f reference_positions:f previous:f",
    "homogenize": "tensors:f",
    "rasterize": "faces:i uv:f values:f",
    "rasterize_weave": "face_fabric:i face_map:f",
    "outline": "faces:i coverage:f",
    "sharpen_outline": "fields:f",
    "lift_outline": "fields:f",
    "position_baseline_stats": "frames:f",
    "write_exr": "image:f",
    "cache_writer": "fields[0]:f fields[1]:f",
    "write_pc2": "frames:f",
    "write_mdd": "frames:f",
    "pc2_writer": "positions:f",
    "motion_encoder": "faces:i positions:f",
}


def declared(name):
    return dict(a.split(":") for a in ARGS[name].split())


@pytest.mark.parametrize("name", list(ALL))
def test_the_table_lists_every_array_argument_of_the_case(name, tmp_path):
    A = Maker()
    call(name, A, tmp_path, "names")
    assert dict(A.names) == declared(name)


def spoilt_cases():
    """(case, argument, spoil, words the error must hold) for every array argument."""
    out = []
    for name in ALL:
        for arg, kind in declared(name).items():
            spoils = [("strings", lambda a: a.astype(str), "got a <U")]
            if kind == "f":
                spoils.append(("integers", lambda a: a.astype(np.int32), "float array (any float dtype)"))
            else:
                spoils.append(("negative", negative, "must hold non-negative indices, got -1"))
                spoils.append(("floats", lambda a: a.astype(np.float64), "integer array (any integer dtype)"))
            out += [pytest.param(name, arg, spoil, [arg, words], id=f"{name}-{arg}-{what}")
                    for what, spoil, words in spoils]
    return out


def negative(a):
    b = np.array(a, np.int64)
    b.flat[-1] = -1
    return b


@pytest.mark.parametrize("name, arg, spoil, words", spoilt_cases())
def test_a_wrong_array_is_a_parameter_error_naming_the_argument(name, arg, spoil, words, tmp_path):
    with pytest.raises(madder.ParameterError) as e:
        call(name, Maker(bad=arg, spoil=spoil), tmp_path, "bad")
    for w in words:
        assert w in str(e.value), (w, str(e.value))
    assert e.value.name == arg


def test_a_ragged_list_names_the_argument():
    with pytest.raises(madder.ParameterError, match="positions must be an array"):
        madder.encode_angles(FACES, [[0.0, 0.0, 0.0], [1.0, 0.0]])


def test_the_wrong_number_of_dimensions_names_the_argument():
    with pytest.raises(madder.ParameterError, match=r"dihedrals must be .* with 1 dimensions, got a float64 array"):
        madder.decode_angles(FACES, np.zeros((NF, 3)), np.zeros((2, 2)))


def test_an_index_beyond_uint32_is_refused():
    with pytest.raises(madder.ParameterError, match="faces must hold indices that fit uint32, got 4294967296"):
        madder.Topology(np.array([[0, 1, 2**32]]), 3)


def test_float32_arguments_are_read_in_place_and_float64_ones_rounded_to_nearest(tmp_path):
    """Where the core reads float32 (point caches), float64 is rounded as numpy rounds it."""
    x = np.array([[[0.1, 1 / 3, 2.0**-30]]])
    madder.write_pc2(tmp_path / "a.pc2", x)
    madder.write_pc2(tmp_path / "b.pc2", x.astype(np.float32))
    assert (tmp_path / "a.pc2").read_bytes() == (tmp_path / "b.pc2").read_bytes()
    np.testing.assert_array_equal(madder.PointCache(tmp_path / "a.pc2").read_frame(0), x[0].astype(np.float32))
