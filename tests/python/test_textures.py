"""The image-sequence output's bpy-free logic (`madder.addon.textures`): names, frame
numbering, Blender's image-user mapping, the staging folder's swap, and the export loop
over a real fine cache."""

import os

import numpy as np
import pytest

import madder
from madder.addon import errors, textures

# -- names and numbering


def test_outputs_sit_beside_the_cache_and_are_numbered_by_frame(tmp_path):
    cache = str(tmp_path / "madder_cache" / "Flag.madder")
    assert textures.fine_cache_path(cache) == str(tmp_path / "madder_cache" / "Flag.fine.madder")
    assert textures.image_folder(cache) == str(tmp_path / "madder_cache" / "Flag_images")
    assert textures.stem(cache) == "Flag"
    folder = textures.image_folder(cache)
    assert textures.frame_file(folder, "Flag", "stain", 7) == os.path.join(folder, "Flag_stain.0007.exr")
    assert textures.frame_file(folder, "Flag", "wet", 0) == os.path.join(folder, "Flag_wet.0000.exr")
    assert textures.file_name("Flag", "wet", 12345) == "Flag_wet.12345.exr"  # more digits when needed
    assert textures.pattern(folder, "Flag", "stain") == os.path.join(folder, "Flag_stain.####.exr")
    with pytest.raises(ValueError):
        textures.file_name("Flag", "stain", -1)


def test_negative_frames_cannot_be_numbered_and_sizes_are_the_listed_ones():
    assert textures.frames_problem(0, 10) is None and textures.frames_problem(1, 1) is None
    why = textures.frames_problem(-5, 10)
    assert "-5" in why and "frame 0" in why
    assert [textures.check_size(s) for s in ("512", 1024, "2048", 4096)] == [512, 1024, 2048, 4096]
    for bad in (256, "8192", "big", None, 1000):
        with pytest.raises(errors.ExportError, match="512, 1024, 2048, 4096"):
            textures.check_size(bad)


@pytest.mark.parametrize("first, last", [(1, 48), (0, 5), (10, 10), (101, 200)])
def test_the_image_user_shows_file_f_at_frame_f_and_clamps_to_the_written_files(first, last):
    user = textures.image_user(first, last)
    shown = {f: textures.shown_file_number(f, **user) for f in range(first - 5, last + 6)}
    for f in range(first, last + 1):
        assert shown[f] == f
    # before the range Blender shows file `frame_offset` = first − 1 (the lead copy of the
    # first frame the exporter writes, when first ≥ 1), after it the last file
    assert all(shown[f] == first - 1 for f in range(first - 5, first))
    assert all(shown[f] == last for f in range(last + 1, last + 6))


def test_the_model_of_blenders_image_user_matches_a_measured_case():
    # measured with bpy 5.0.1 (Cycles, files 3–7, frame_start 3, offset 2, duration 5):
    # frames 0–2 asked for file 2, frames 3–7 files 3–7, frames 8–10 file 7
    shown = [textures.shown_file_number(f, 3, 2, 5) for f in range(11)]
    assert shown == [2, 2, 2, 3, 4, 5, 6, 7, 7, 7, 7]


# -- staging


def write(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def read(path):
    with open(path) as f:
        return f.read()


def test_staging_swaps_the_whole_folder_in_only_on_commit(tmp_path):
    final = str(tmp_path / "Flag_images")
    write(os.path.join(final, "Flag_stain.0001.exr"), "old 1")
    write(os.path.join(final, "Flag_stain.0002.exr"), "old 2")
    staging = textures.Staging(final)
    path = staging.begin()
    assert path == final + ".partial" and os.listdir(path) == []
    write(os.path.join(path, "Flag_stain.0001.exr"), "new 1")
    # until the commit the previous sequence is whole
    assert read(os.path.join(final, "Flag_stain.0001.exr")) == "old 1"
    assert staging.commit() == final
    assert sorted(os.listdir(final)) == ["Flag_stain.0001.exr"]  # no stale frame of the old one
    assert read(os.path.join(final, "Flag_stain.0001.exr")) == "new 1"
    assert sorted(os.listdir(tmp_path)) == ["Flag_images"]


def test_a_discarded_or_interrupted_staging_keeps_the_previous_folder(tmp_path):
    final = str(tmp_path / "Flag_images")
    write(os.path.join(final, "a.exr"), "old")
    staging = textures.Staging(final)
    write(os.path.join(staging.begin(), "a.exr"), "half")
    staging.discard()
    assert read(os.path.join(final, "a.exr")) == "old" and sorted(os.listdir(tmp_path)) == ["Flag_images"]
    # a run killed mid-write leaves its partial folder: the next one starts afresh
    write(os.path.join(final + ".partial", "b.exr"), "junk")
    assert os.listdir(textures.Staging(final).begin()) == []
    # a run killed between the two renames of a commit: the old folder comes back
    os.rename(final, final + ".old")
    textures.Staging(final).begin()
    assert read(os.path.join(final, "a.exr")) == "old"


def test_staging_errors_name_the_folder(tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a folder")
    staging = textures.Staging(str(blocker / "Flag_images"))
    with pytest.raises(errors.ExportError) as e:
        staging.begin()
    assert str(blocker / "Flag_images.partial") in str(e.value) and e.value.filename == staging.path


def test_remove_outputs_deletes_the_fine_cache_and_every_image_folder(tmp_path):
    cache = str(tmp_path / "Flag.madder")
    write(cache, "cache")
    write(textures.fine_cache_path(cache), "fine")
    folder = textures.image_folder(cache)
    for f in (folder, folder + ".partial", folder + ".old"):
        write(os.path.join(f, "x.exr"), "x")
    removed = textures.remove_outputs(cache)
    assert sorted(removed) == sorted([textures.fine_cache_path(cache), folder, folder + ".partial", folder + ".old"])
    assert os.listdir(tmp_path) == ["Flag.madder"]
    assert textures.remove_outputs(cache) == []


# -- the export loop


def fine_cache(path, first=1, n_frames=3):
    """A fine cache over a unit square of two triangles (4 vertices), whose densities grow
    with the frame."""
    writer = madder.CacheWriter(str(path), 4, ["solute", "wetness", "deposit"], first, n_frames)
    for k in range(n_frames):
        s = np.array([0.0, 1.0, 2.0, 3.0], dtype=np.float32) * 1e-3 * (k + 1)
        writer.push_frame([s, np.full(4, 0.05 * (k + 1), np.float32), np.full(4, 1e-4 * k, np.float32)])
    writer.finish()
    return madder.CacheReader(str(path))


class FakeCore:
    """Records what the exporter rasterizes and writes (files hold the frame's values)."""

    def __init__(self):
        self.calls = []

    def rasterize(self, faces, uv, values, size, padding=4):
        self.calls.append(("rasterize", values.shape, size, padding))
        return np.broadcast_to(values.mean(axis=0), (size, size, values.shape[1])).copy(), 3

    def write_exr(self, path, image, channels):
        self.calls.append(("write", os.path.basename(path), image.shape, tuple(channels)))
        np.save(path + ".npy", image[0, 0])
        os.rename(path + ".npy", path)


FACES = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)
UV = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], dtype=np.float32)


def test_the_exporter_writes_the_playback_values_of_each_frame(tmp_path):
    reader = fine_cache(tmp_path / "Flag.fine.madder", first=1)
    core = FakeCore()
    refs, color = (4e-3, 0.1, 2e-4), (0.5, 0.25, 1.0)
    out = tmp_path / "images"
    out.mkdir()
    ex = textures.Exporter(core, reader, FACES, UV, refs, color, "512", str(out), "Flag")
    assert list(ex.frames()) == [1, 2, 3]
    rgba, wet = ex.values(2)
    # what playback writes into the attributes for that frame, the dye amount (solute over
    # its reference: 0, 0.5, 1, 1.5) split at 1: the rest over the range in the wet's blue
    want = [np.zeros(16, np.float32), np.zeros(4, np.float32), np.zeros(4, np.float32)]
    madder.CacheReader(str(tmp_path / "Flag.fine.madder")).read_stain(2, refs, color, *want)
    dye = np.array([0.0, 0.5, 1.0, 1.5], np.float32)
    np.testing.assert_allclose(want[0][3::4], dye, rtol=1e-6)  # playback: all of it
    np.testing.assert_allclose(rgba[:, 3], np.minimum(dye, 1.0), rtol=1e-6)
    np.testing.assert_allclose(rgba[:, :3], np.minimum(dye, 1.0)[:, None] * np.array(color), rtol=1e-6)
    np.testing.assert_allclose(wet[:, 2], [0.0, 0.0, 0.0, 0.5 / madder.DYE_EXCESS_RANGE], rtol=1e-6)
    np.testing.assert_array_equal(wet[:, 0], want[1])
    np.testing.assert_array_equal(wet[:, 1], want[2])
    for f in ex.frames():
        ex.export(f)
    assert ex.overlapping == 3
    names = sorted(os.listdir(out))
    # every frame's two images, plus the lead copies of the first frame as file 0
    assert names == [f"Flag_{k}.{f:04d}.exr" for k in ("stain", "wet") for f in range(4)]
    assert ("write", "Flag_stain.0001.exr", (512, 512, 4), ("R", "G", "B", "A")) in core.calls
    assert ("write", "Flag_wet.0003.exr", (512, 512, 3), ("R", "G", "B")) in core.calls
    for kind in ("stain", "wet"):
        lead, first = (np.load(out / f"Flag_{kind}.{f:04d}.exr", allow_pickle=False) for f in (0, 1))
        np.testing.assert_array_equal(lead, first)
        assert os.path.samefile(out / f"Flag_{kind}.0000.exr", out / f"Flag_{kind}.0001.exr")
    last = np.load(out / "Flag_stain.0003.exr", allow_pickle=False)
    np.testing.assert_allclose(last, madder_values(tmp_path / "Flag.fine.madder", 3, refs, color)[0].mean(axis=0))


def madder_values(path, frame, refs, color):
    """The images' stain values (RGBA, the dye amount within 1) and dye excess of `frame`."""
    buf = [np.zeros(16, np.float32), np.zeros(4, np.float32), np.zeros(4, np.float32)]
    excess = np.zeros(4, np.float32)
    madder.CacheReader(str(path)).read_stain(frame, refs, color, *buf, excess=excess)
    return buf[0].reshape(4, 4), excess


def test_a_sequence_from_frame_0_has_no_lead_file(tmp_path):
    reader = fine_cache(tmp_path / "f.madder", first=0, n_frames=2)
    out = tmp_path / "images"
    out.mkdir()
    ex = textures.Exporter(FakeCore(), reader, FACES, UV, (1, 1, 1), (1, 1, 1), 512, str(out), "Cloth")
    for f in ex.frames():
        ex.export(f)
    assert sorted(os.listdir(out)) == [f"Cloth_{k}.{f:04d}.exr" for k in ("stain", "wet") for f in (0, 1)]


def test_the_exporter_refuses_mismatched_arrays_and_sizes(tmp_path):
    reader = fine_cache(tmp_path / "f.madder")
    with pytest.raises(ValueError):
        textures.Exporter(FakeCore(), reader, FACES, UV[:1], (1, 1, 1), (1, 1, 1), 512, str(tmp_path), "x")
    with pytest.raises(errors.ExportError):
        textures.Exporter(FakeCore(), reader, FACES, UV, (1, 1, 1), (1, 1, 1), 300, str(tmp_path), "x")


def test_a_lead_file_that_cannot_be_written_is_an_export_error_naming_it(tmp_path):
    reader = fine_cache(tmp_path / "f.madder")
    out = tmp_path / "images"
    out.mkdir()
    (out / "Flag_stain.0000.exr").mkdir()  # a folder where the lead file goes
    (out / "Flag_stain.0000.exr" / "x").write_text("x")
    ex = textures.Exporter(FakeCore(), reader, FACES, UV, (1, 1, 1), (1, 1, 1), 512, str(out), "Flag")
    with pytest.raises(errors.ExportError) as e:
        ex.export(1)
    assert e.value.filename == str(out / "Flag_stain.0000.exr") and e.value.filename in str(e.value)


def test_real_images_hold_the_values_at_texel_centres(tmp_path):
    """With the native rasterizer and EXR writer: a frame's stain image reads back (half
    float) as the barycentric interpolation of the playback values."""
    reader = fine_cache(tmp_path / "f.madder")
    refs, color = (4e-3, 0.1, 2e-4), (0.5, 0.25, 1.0)
    out = tmp_path / "images"
    out.mkdir()
    ex = textures.Exporter(madder, reader, FACES, UV, refs, color, 512, str(out), "Flag")
    ex.export(3)
    assert ex.overlapping == 0
    image = madder.read_exr(str(out / "Flag_stain.0003.exr"))
    assert image.shape == (512, 512, 4)
    v, excess = madder_values(tmp_path / "f.madder", 3, refs, color)
    # texel (x, y) has its centre at ((x + ½)/512, (y + ½)/512), row 0 at the bottom; in
    # the lower triangle (0, 1, 2) the barycentric weights are (1 − s, s − t, t)
    for x, y in ((400, 100), (511, 0), (300, 299), (10, 5)):
        s, t = (x + 0.5) / 512, (y + 0.5) / 512
        want = (1 - s) * v[0] + (s - t) * v[1] + t * v[2]
        np.testing.assert_allclose(image[y, x], want, rtol=1e-3, atol=1e-5)  # half float
    wet = madder.read_exr(str(out / "Flag_wet.0003.exr"))
    assert wet.shape == (512, 512, 3)
    # wetness 0.15 kg/m² over the reference 0.1 reads as full; deposit 2e-4 / 2e-4 too
    np.testing.assert_allclose(wet[..., 0], 1.0)
    np.testing.assert_allclose(wet[..., 1], 1.0)
    # the dye amounts 0, 0.75, 1.5, 2.25: the excess over 1 (over the range) interpolated
    np.testing.assert_allclose(excess, np.array([0.0, 0.0, 0.5, 1.25]) / madder.DYE_EXCESS_RANGE, rtol=1e-6)
    for x, y in ((400, 100), (511, 0), (300, 299), (10, 5)):
        s, t = (x + 0.5) / 512, (y + 0.5) / 512
        want = (1 - s) * excess[0] + (s - t) * excess[1] + t * excess[2]
        assert wet[y, x, 2] == pytest.approx(want, rel=1e-3, abs=1e-5)


def test_with_the_weave_a_saturated_stain_shows_every_thread_full_and_a_faint_one_the_weave(tmp_path):
    """With the weave's detail the exporter reads the fractions unclamped and clips each
    finished texel (premultiplied: a texel over 1 keeps its colour at coverage 1). A stain
    at 3–12× its reference is saturated on every thread, gaps included (the uptake's
    0.74 × 3 is still over 1), in the stain's own colour; one at a tenth of it shows the
    weave (coverage varying by the uptake's contrast) and stays within [0, 1]."""
    path = tmp_path / "Flag.fine.madder"
    writer = madder.CacheWriter(str(path), 4, ["solute", "wetness", "deposit"], 1, 2)
    for s in (np.array([3.0, 6.0, 9.0, 12.0]), np.array([0.1, 0.1, 0.1, 0.1])):
        writer.push_frame([(s * 1e-3).astype(np.float32), np.full(4, 0.05, np.float32), np.zeros(4, np.float32)])
    writer.finish()
    refs, color = (1e-3, 0.1, 2e-4), (0.5, 0.25, 1.0)
    corr = madder.fabric_corrector("PLAIN", gaps=True)
    maps = np.ascontiguousarray(np.repeat((16.0 * np.eye(2))[None], 2, axis=0))
    weave = {kind: madder.WeaveDetail([corr], np.zeros(2, np.uint32), maps, list(textures.UPTAKE[kind]))
             for kind in textures.KINDS}
    out = tmp_path / "images"
    out.mkdir()
    ex = textures.Exporter(madder, madder.CacheReader(str(path)), FACES, UV, refs, color, "512", str(out), "Flag",
                           padding=0, weave=weave)
    rgba, _ = ex.values(1)
    assert rgba[:, 3].min() == 3.0  # unclamped
    # what the exporter writes, rasterized the same way, read back through the binding
    for frame in (1, 2):
        ex.values(frame)
        image, _ = madder.rasterize(FACES, UV, ex._rgba.reshape(-1, 4), 512, 0, weave=weave["stain"],
                                    clip="premultiplied")
        a = image[..., 3]
        if frame == 1:
            assert a.min() == 1.0 == a.max()
            np.testing.assert_allclose(image[..., :3], np.broadcast_to(color, image[..., :3].shape), rtol=1e-6)
        else:
            assert 0.0 <= a.min() and a.max() <= 1.0
            assert a.max() / a.min() > 1.3  # the weave: yarn over gap
    unclipped, _ = madder.rasterize(FACES, UV, np.tile([0.5, 0.25, 1.0, 1.0], (4, 1)).astype(np.float32) * 3, 64, 0,
                                    weave=weave["stain"])
    assert unclipped[..., 3].min() > 1.0  # without the clip the values run over 1
    with pytest.raises(madder.ParameterError, match="clip"):
        madder.rasterize(FACES, UV, ex._rgba.reshape(-1, 4), 64, 0, clip="over")


def _square(n):
    """The unit square as an n × n grid of triangle pairs: faces (uint32), the vertices'
    UVs, the faces' corner UVs (float32)."""
    j, i = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    a = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    uv_v = np.stack([j.ravel() / n, i.ravel() / n], 1)
    return faces.astype(np.uint32), uv_v, uv_v[faces].astype(np.float32)


def test_sharp_outline_draws_the_front_in_both_images_from_one_raster_of_its_fields(tmp_path):
    """With `outline` (Sharp Outline) the exporter writes the images as rasterized, then
    drawn by `madder.sharpen_outline` from the fields of `madder.Outline` (core
    `texture::outline`): the stain's edge within a texel, the wet image's excess only cut,
    wetness and deposit left; the fields are rasterized once for a frame's two images.
    Without it the images are the plain rasterization's."""
    n = 16
    faces, uv_v, uv = _square(n)
    ramp = np.clip(0.5 + (0.5 - uv_v[:, 0]) * n / 3, 0, 1)  # a front smeared over three cells
    path = tmp_path / "Flag.fine.madder"
    writer = madder.CacheWriter(str(path), len(uv_v), ["solute", "wetness", "deposit"], 1, 2)
    # frame 1: twice saturation on the plateau; frame 2: ten times, so that the last cell
    # goes from above saturation to dry
    for k in (2, 10):
        writer.push_frame([(k * 1e-3 * ramp).astype(np.float32), (0.1 * ramp).astype(np.float32),
                           np.zeros(len(uv_v), np.float32)])
    writer.finish()
    refs, color = (1e-3, 0.1, 2e-4), (0.5, 0.25, 1.0)

    class Counting:
        def __getattr__(self, name):
            return getattr(madder, name)

        def rasterize(self, *args, **kw):
            calls.append(args[2].shape[1])
            return madder.rasterize(*args, **kw)

    images = {}
    for outline in (0, 3):
        calls = []
        out = tmp_path / f"images{outline}"
        out.mkdir()
        ex = textures.Exporter(Counting(), madder.CacheReader(str(path)), faces, uv, refs, color, 512, str(out),
                               "Flag", outline=outline)
        for f in (1, 2):
            ex.export(f)
        assert calls == 2 * ([4, 3] if not outline else [4, 2, 3])  # stain, (fields,) wet
        images[outline] = [madder.read_exr(str(out / f"Flag_{k}.{f:04d}.exr")) for f in (1, 2)
                           for k in textures.KINDS]
    (stain0, wet0, _, wet0_ten), (stain3, wet3, _, wet3_ten) = images[0], images[3]
    ramp_texels = ((stain0[..., 3] > 0.1) & (stain0[..., 3] < 0.9)).sum(axis=1).max()
    edge_texels = ((stain3[..., 3] > 0.1) & (stain3[..., 3] < 0.9)).sum(axis=1).max()
    assert ramp_texels > 40 and edge_texels <= 2  # 3 cells of 32 texels, then one texel
    assert abs(stain3[..., 3].sum() / stain0[..., 3].sum() - 1) < 0.01
    np.testing.assert_allclose(stain3[..., 0], 0.5 * stain3[..., 3], atol=2e-3)  # the hue (half float)
    assert np.array_equal(wet3[..., :2], wet0[..., :2]) and np.array_equal(wet3_ten[..., :2], wet0_ten[..., :2])
    assert (wet3_ten[..., 2] <= wet0_ten[..., 2]).all() and (wet3_ten[..., 2] < wet0_ten[..., 2]).any()


def test_outline_in_shader_lifts_the_stain_and_writes_the_front_distance_as_the_wet_alpha(tmp_path):
    """With `shader` (Sharp Outline in the shader) the exporter lifts the stain to its
    plateau (`madder.lift_outline`) and writes the front's signed distance in metres as a
    fourth channel of the wet image (`DISTANCE_CHANNEL`), wetness, deposit and excess as
    rasterized; the texel's size in metres is required."""
    n = 16
    faces, uv_v, uv = _square(n)
    ramp = np.clip(0.5 + (0.5 - uv_v[:, 0]) * n / 3, 0, 1)  # a front smeared over three cells at u = ½
    path = tmp_path / "Flag.fine.madder"
    writer = madder.CacheWriter(str(path), len(uv_v), ["solute", "wetness", "deposit"], 1, 1)
    writer.push_frame([(1e-3 * ramp).astype(np.float32), (0.1 * ramp).astype(np.float32),
                       np.zeros(len(uv_v), np.float32)])
    writer.finish()
    refs, color = (1e-3, 0.1, 2e-4), (0.5, 0.25, 1.0)
    with pytest.raises(ValueError, match="texel's size in metres"):
        textures.Exporter(madder, madder.CacheReader(str(path)), faces, uv, refs, color, 512, str(tmp_path),
                          "Flag", outline=3, shader=True)
    images = {}
    for shader in (False, True):
        out = tmp_path / f"images{shader}"
        out.mkdir()
        size = 512
        ex = textures.Exporter(madder, madder.CacheReader(str(path)), faces, uv, refs, color, size, str(out), "Flag",
                               outline=3 if shader else 0, shader=shader, texel=(0.1 / size, 0.05 / size))
        ex.export(1)
        images[shader] = [madder.read_exr(str(out / f"Flag_{k}.0001.exr")) for k in textures.KINDS]
    (stain0, wet0), (stain1, wet1) = images[False], images[True]
    assert wet0.shape[2] == 3 and wet1.shape[2] == 4
    assert np.array_equal(wet1[..., :3], wet0)
    x = (np.arange(size) + 0.5) / size
    exact = 0.1 * (0.5 - x)  # metres behind the front (a 10 cm wide cloth)
    near = np.abs(exact) < 5e-4
    np.testing.assert_allclose(wet1[:, near, 3], np.broadcast_to(exact[near], (size, near.sum())), atol=1e-4)
    zone = (stain0[..., 3] > 0.01) & (x > 0.5 - 1 / n)  # stained, every vertex near the dry cloth
    assert np.all(stain1[..., 3][zone] > 0.99)  # lifted to the plateau (half float)
    np.testing.assert_allclose(stain1[..., 0], 0.5 * stain1[..., 3], atol=2e-3)
