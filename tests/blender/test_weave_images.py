"""The weave's fine scale in a real bake's image sequence (issue 13 part 4): a fabric with a
Thread Count writes images whose detail (against the same bake at Thread Count 0) has its
spectrum's peak on the tile's repeat at the flag's physical scale and keeps the coverage's
total, Re-export Textures applies the current Thread Count (0: the smooth images, bit for
bit), and a Thread Count finer than a texel bakes with a warning naming the object and the
fabric, the weave left out rather than aliased."""

import os

import bpy
import numpy as np
from conftest import make_active

import madder

FRAMES = (1, 6)
# 1024 px: 13 texels a tile. At 512 (6.6) the wine's stain (issue 34's presets: carried to a
# rim, bound over minutes) put the tile's harmonic below the low-frequency part of the
# detail: the woven coverage is ~1 % above the smooth one (1.02 % at 512 px, 0.87 % at
# 1024, the same share in every channel), a bias of the uptake's sampling not found yet.
# With the presets' run holdup it is 1.95 % at 1024 px and that low-frequency part, not the
# tile's harmonic, is the detail's spectral peak; with the default pool (Spill Shape) 2.34 %.
# Both sharpen the stain's edge: the bias grows with the field's gradients. These bakes turn
# the holdup off and lay the spill by its weights, so that they test the thread count (the
# bias is an open question in ARCHITECTURE.md)
SIZE = 1024


def bake(open_fixture, thread_count, size=str(SIZE)):
    scene = open_fixture("flag.blend")
    scene.frame_start, scene.frame_end = FRAMES
    flag = make_active(bpy.data.objects["Flag"])
    mat = bpy.data.materials.new("Cotton")
    fab = mat.madder_fabric
    fab.enabled = True
    fab.weave = "PLAIN"
    fab.gaps = True
    fab.thread_count = thread_count
    fab.shader_weave = False  # the images' own weave (on: the shader draws it, test_weave_shader)
    flag.data.materials.clear()
    flag.data.materials.append(mat)
    s = flag.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.liquid = "RED_WINE"
    s.holdup = 0.0  # see SIZE
    s.spill_shape = "WEIGHTS"  # see SIZE
    s.detail = 1
    s.output_images = True
    s.image_size = size
    # the outline drawn in the images (within a texel): in the shader's mode they carry the
    # stain lifted to its plateau at the front, re-clipped with the weave, not the final stain
    s.outline_in_shader = False
    assert bpy.ops.madder.bake() == {"FINISHED"}
    return flag


def stain_image(flag, frame):
    cache = bpy.path.abspath(flag.madder.cache_file)
    folder = os.path.splitext(cache)[0] + "_images"
    return madder.read_exr(os.path.join(folder, f"{flag.name}_stain.{frame:04d}.exr"))


def metres_per_uv(flag):
    """√(world area / UV area) over the whole flag, from its mesh (world space, metres)."""
    mesh = flag.data
    mesh.calc_loop_triangles()
    m = np.array(flag.matrix_world)
    co = np.array([(m @ np.r_[v.co[:], 1.0])[:3] for v in mesh.vertices])
    uv = mesh.uv_layers.active.data
    world = uvs = 0.0
    for t in mesh.loop_triangles:
        p = co[list(t.vertices)]
        q = np.array([uv[i].uv[:] for i in t.loops])
        world += 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
        e1, e2 = q[1] - q[0], q[2] - q[0]
        uvs += 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])
    return np.sqrt(world / uvs) * bpy.context.scene.unit_settings.scale_length


def test_the_weave_shows_in_the_images_at_its_thread_count(open_fixture, capsys):
    smooth = stain_image(bake(open_fixture, 0.0), FRAMES[1])
    capsys.readouterr()
    flag = bake(open_fixture, 1.0)  # 1 thread/cm: 6.6 texels a thread at 1024 px
    assert "cannot be resolved" not in capsys.readouterr().out
    woven = stain_image(flag, FRAMES[1])
    d = (woven - smooth)[..., 3].astype(np.float64)
    assert np.abs(d).max() > 1e-3
    # the same coverage on average (the detail has no mean over the tiles)
    assert abs(woven[..., 3].astype(np.float64).sum() / smooth[..., 3].astype(np.float64).sum() - 1) < 0.01
    # spectrum: the strongest component is a repeat of the tile along the UV axes (weft
    # angle 0): tile = 2 threads of 1 cm, so 100·s/2 tiles per UV unit, s metres per UV
    f = np.abs(np.fft.fft2(d - d.mean()))
    f[0, 0] = 0.0
    iv, iu = np.unravel_index(np.argmax(f), f.shape)
    fu, fv = (i if i <= SIZE // 2 else SIZE - i for i in (iu, iv))  # |frequency|, cycles per UV
    tile = 100.0 * metres_per_uv(flag) / 2.0
    m, n = round(fu / tile), round(fv / tile)
    print(f"peak at ({fu}, {fv}) cycles/UV; tile repeat {tile:.2f}/UV: harmonic ({m}, {n})")
    assert (m, n) != (0, 0)
    assert abs(fu - m * tile) <= 1.0 + 0.03 * fu and abs(fv - n * tile) <= 1.0 + 0.03 * fv


def test_threads_finer_than_a_texel_bake_with_a_warning_naming_object_and_fabric(open_fixture, capsys):
    smooth = stain_image(bake(open_fixture, 0.0), FRAMES[1])
    capsys.readouterr()
    flag = bake(open_fixture, 60.0)
    out = capsys.readouterr().out
    assert "'Flag': the Thread Count of fabric 'Cotton'" in out and "cannot be resolved" in out, out
    # and left out, rather than aliased into a moiré
    assert np.array_equal(stain_image(flag, FRAMES[1]), smooth)


def test_reexport_applies_the_current_thread_count(open_fixture):
    smooth = stain_image(bake(open_fixture, 0.0), FRAMES[1])
    flag = bake(open_fixture, 1.0)
    woven = stain_image(flag, FRAMES[1])
    assert not np.array_equal(woven, smooth)
    # re-exporting from the fine cache gives the bake's images, with or without the weave
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert np.array_equal(stain_image(flag, FRAMES[1]), woven)
    flag.active_material.madder_fabric.thread_count = 0.0
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert np.array_equal(stain_image(flag, FRAMES[1]), smooth)
