"""Detail and the image-sequence output, in real Blender: the bake writes a fine cache and
an EXR pair per frame beside the cache, the stain shader reads them through Image
Texture nodes, renders find the stain where the vertex colours put it, an animation
render shows each frame's file, and nothing is lost on failure."""

import os
import sys

import bpy
import numpy as np
import pytest
from conftest import ADDON, make_active, shown

import madder

FRAMES = (1, 12)  # a short bake keeps these tests cheap


def bake_flag(open_fixture, detail=1, size="512", frames=FRAMES, grain=True):
    scene = open_fixture("flag.blend")
    scene.frame_start, scene.frame_end = frames
    flag = make_active(bpy.data.objects["Flag"])
    s = flag.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.liquid = "RED_WINE"
    s.detail = detail
    s.output_images = True
    s.image_size = size
    if not grain:  # a uniform fabric and a graded spill: no detail below the coarse mesh's vertices
        s.grain_from, s.irregularity = "OBJECT", 0.0
        s.spill_shape = "WEIGHTS"  # a pool's sharp edge is such detail too
    assert bpy.ops.madder.bake() == {"FINISHED"}
    return scene, flag


def outputs(obj):
    cache = bpy.path.abspath(obj.madder.cache_file)
    base = os.path.splitext(cache)[0]
    return cache, base + ".fine.madder", base + "_images"


def image_file(obj, kind, frame):
    folder = outputs(obj)[2]
    return os.path.join(folder, f"{obj.name}_{kind}.{frame:04d}.exr")


def snapshot(obj):
    """Every output file of `obj`'s bake and its bytes."""
    cache, fine, folder = outputs(obj)
    files = [cache, fine] + sorted(os.path.join(folder, f) for f in os.listdir(folder))
    return {f: open(f, "rb").read() for f in files}


def input_nodes(mat):
    return {n.name: n for n in mat.node_tree.nodes if n.name.startswith("Madder Input: ")}


def test_a_detail_bake_writes_the_fine_cache_and_an_image_pair_per_frame(open_fixture):
    scene, flag = bake_flag(open_fixture)
    cache, fine, folder = outputs(flag)
    coarse = madder.CacheReader(cache)
    refined = madder.CacheReader(fine)
    flag.data.calc_loop_triangles()
    tris = np.array([t.vertices[:] for t in flag.data.loop_triangles], dtype=np.uint32)
    n_fine = madder.Refinement(madder.Topology(tris, len(flag.data.vertices)), 1).n_vertices
    assert coarse.n_vertices == len(flag.data.vertices) and refined.n_vertices == n_fine > 3 * coarse.n_vertices
    assert refined.fields == coarse.fields == ["solute", "wetness", "deposit"]
    assert (refined.first_frame, refined.last_frame) == FRAMES
    # one stain and one wet image per frame, numbered by scene frame (and the first frame
    # again as file 0, which Blender shows before the range)
    names = sorted(os.listdir(folder))
    assert names == sorted(f"Flag_{k}.{f:04d}.exr" for k in ("stain", "wet") for f in range(0, FRAMES[1] + 1))
    s = flag.madder
    buf = [np.zeros(4 * n_fine, np.float32), np.zeros(n_fine, np.float32), np.zeros(n_fine, np.float32)]
    for f in (1, 12):
        stain, wet = (madder.read_exr(image_file(flag, k, f)) for k in ("stain", "wet"))
        assert stain.shape == (512, 512, 4) and wet.shape[:2] == (512, 512)
        # the images hold the playback values of the fine cache (interpolated, so within
        # their range; the stain's peak is on a vertex's texel to half-float rounding): the
        # dye amount up to 1 in the stain's alpha, the rest over the range in the wet's blue
        refined.read_stain(f, tuple(s.bake_references), tuple(s.stain_color), *buf)
        dye = buf[0][3::4]
        assert dye.max() > 1.0  # the spill is above saturation
        assert stain[..., 3].max() == pytest.approx(1.0, rel=0.002)
        # (the excess peaks at one vertex, between texel centres: interpolated, a little below)
        top = (dye.max() - 1) / madder.DYE_EXCESS_RANGE
        assert 0.95 * top < wet[..., 2].max() < top * (1 + 1e-3)
        # (interpolation rounds: −3e-7 where every vertex of a triangle is 0)
        assert stain[..., 3].min() > -1e-6 and wet[..., 0].max() == pytest.approx(buf[1].max(), rel=0.02)
        np.testing.assert_allclose(stain[..., :3], stain[..., 3:] * np.array(s.stain_color), atol=2e-3)
    # Blender's own read of a wet image: wetness in R, the excess in B (finite, not garbage)
    blender_wet = bpy.data.images.load(image_file(flag, "wet", 12))
    px = np.array(blender_wet.pixels[:], dtype=np.float32).reshape(512, 512, 4)
    bpy.data.images.remove(blender_wet)
    assert np.isfinite(px).all()
    assert px[..., 2].max() == pytest.approx(wet[..., 2].max(), rel=1e-3) and px[..., 2].min() > -1e-6
    assert px[..., 0].max() == pytest.approx(wet[..., 0].max(), rel=1e-3)
    # the vertex colours still play, from the cloth-resolution cache
    scene.frame_set(6)
    attr = shown(flag).attributes["madder_stain"]
    assert len(attr.data) == coarse.n_vertices
    # the stain shader reads the sequences
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    nodes = input_nodes(flag.active_material)
    tex = nodes["Madder Input: Stain Image"]
    img = tex.image
    assert img.source == "SEQUENCE" and img.colorspace_settings.name == "Non-Color"
    assert os.path.samefile(bpy.path.abspath(img.filepath), image_file(flag, "stain", 1))
    user = tex.image_user
    assert (user.frame_start, user.frame_offset, user.frame_duration) == (1, 0, 12) and user.use_auto_refresh
    assert nodes["Madder Input: UV Map"].uv_map == flag.data.uv_layers.active.name
    # switching the output back rewires the shader to the attributes, and on again to the images
    s.output_images = False
    assert set(input_nodes(flag.active_material)) == {f"Madder Input: {k}" for k in ("Stain", "Wetness", "Deposit")}
    s.output_images = True
    assert "Madder Input: Wet Image" in input_nodes(flag.active_material)


def test_no_uv_map_is_refused_before_anything_is_written(open_fixture):
    open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.source_group = "stain_source"
    flag.madder.output_images = True
    while flag.data.uv_layers:
        flag.data.uv_layers.remove(flag.data.uv_layers[0])
    folder = bpy.path.abspath(flag.madder.cache_dir)
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    assert "'Flag' has no UV map" in str(e.value) and "Image Sequence" in str(e.value)
    assert not os.path.exists(folder) and flag.madder.cache_file == ""


def test_overlapping_uv_islands_bake_with_a_warning_naming_the_object(open_fixture, capsys):
    scene = open_fixture("flag.blend")
    scene.frame_start, scene.frame_end = 1, 2
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.source_group = "stain_source"
    flag.madder.output_images = True
    flag.madder.image_size = "512"
    layer = flag.data.uv_layers.active
    uv = np.empty(2 * len(layer.data), dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    layer.data.foreach_set("uv", (uv * 2.0) % 1.0001)  # four copies of the layout, stacked
    capsys.readouterr()
    assert bpy.ops.madder.bake() == {"FINISHED"}
    out = capsys.readouterr().out
    assert "'Flag': its UV islands overlap" in out, out


def test_a_failure_mid_sequence_keeps_the_previous_sequence_and_caches(open_fixture, monkeypatch):
    scene, flag = bake_flag(open_fixture, detail=0)
    before = snapshot(flag)
    written = []
    real = madder.write_exr

    def full_disk(path, image, channels=("R", "G", "B", "A")):
        if len(written) == 7:
            raise madder.CacheError(f"cannot write {path}: No space left on device (os error 28)")
        written.append(path)
        return real(path, image, channels)

    monkeypatch.setattr(madder, "write_exr", full_disk)
    flag.madder.liquid = "INK"  # another stain: every file would change
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    msg = str(e.value)
    assert "'Flag' at frame 4" in msg and "No space left on device" in msg and "_images.partial" in msg
    # the previous bake, its fine cache and its images are byte for byte what they were,
    # and nothing of the failed one is left
    assert snapshot(flag) == before
    assert sorted(os.listdir(os.path.dirname(outputs(flag)[0]))) == ["Flag.fine.madder", "Flag.madder", "Flag_images"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions")
def test_an_unwritable_folder_names_it_and_keeps_the_previous_sequence(open_fixture):
    scene, flag = bake_flag(open_fixture, detail=0)
    before = snapshot(flag)
    folder = os.path.dirname(outputs(flag)[0])
    os.chmod(folder, 0o555)
    try:
        with pytest.raises(RuntimeError) as e:
            bpy.ops.madder.bake()
    finally:
        os.chmod(folder, 0o755)
    assert folder in str(e.value) and "Flag" in str(e.value)
    assert snapshot(flag) == before


def test_reexport_at_another_size_needs_no_bake_and_free_bake_removes_everything(open_fixture):
    scene, flag = bake_flag(open_fixture, detail=1)
    cache, fine, folder = outputs(flag)
    caches = {p: (open(p, "rb").read(), os.stat(p).st_mtime_ns) for p in (cache, fine)}
    bpy.ops.madder.add_stain_shader()
    img = input_nodes(flag.active_material)["Madder Input: Stain Image"].image
    flag.madder.image_size = "1024"
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert madder.read_exr(image_file(flag, "stain", 7)).shape == (1024, 1024, 4)
    assert len(os.listdir(folder)) == 2 * (FRAMES[1] + 1)
    assert flag.madder.image_baked_size == 1024
    # the caches were only read
    assert {p: (open(p, "rb").read(), os.stat(p).st_mtime_ns) for p in (cache, fine)} == caches
    # the same images, reloaded
    assert input_nodes(flag.active_material)["Madder Input: Stain Image"].image == img
    scene.frame_set(7)
    assert tuple(img.size) == (1024, 1024)

    assert bpy.ops.madder.free_bake() == {"FINISHED"}
    parent = os.path.dirname(cache)
    assert os.listdir(parent) == []
    assert flag.madder.cache_file == "" and not flag.madder.image_baked
    # the shader falls back to the (absent, so harmless) attributes, and the images go
    assert set(input_nodes(flag.active_material)) == {f"Madder Input: {k}" for k in ("Stain", "Wetness", "Deposit")}
    assert not [i for i in bpy.data.images if i.name.startswith("Madder Flag")]
    with pytest.raises(RuntimeError):  # nothing to re-export from
        bpy.ops.madder.export_textures()


def test_the_edge_width_follows_the_fabric_until_the_user_sets_it(open_fixture):
    """The group's Edge Width is a thread pitch of the material's fabric (the default
    fabric's without one), set again at each sync while it holds what Madder wrote; a
    value the user typed stays through re-exports and a fabric change."""
    presets = sys.modules[ADDON + ".presets"]
    _, flag = bake_flag(open_fixture, detail=0, size="512", frames=(1, 3))
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    mat = flag.active_material
    node = next(n for n in mat.node_tree.nodes if n.type == "GROUP" and n.node_tree.name == "Madder Stain")
    width = node.inputs["Edge Width"]
    cotton = presets.FABRIC_PRESETS[presets.DEFAULT_FABRIC]["thread_count"]
    assert width.default_value == pytest.approx(0.01 / cotton, rel=1e-6)
    fab = mat.madder_fabric
    fab.enabled, fab.preset = True, "LINEN_PLAIN"
    fab.thread_count = 5.0
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert width.default_value == pytest.approx(0.002, rel=1e-6)  # 5 threads a cm
    width.default_value = 0.0007
    fab.thread_count = 8.0
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert width.default_value == pytest.approx(0.0007, rel=1e-6)  # the user's


def test_a_shader_group_of_an_older_madder_is_upgraded_in_place(open_fixture):
    """Before image sequences, the group read the attributes itself and had five inputs."""
    open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    mat = flag.active_material
    group = bpy.data.node_groups.new("Madder Stain", "ShaderNodeTree")
    for name, kind in (("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat"),
                       ("Wet Darkening", "NodeSocketFloat"), ("Wet Roughness", "NodeSocketFloat"),
                       ("Deposit Darkening", "NodeSocketFloat")):
        group.interface.new_socket(name, in_out="INPUT", socket_type=kind)
    for name, kind in (("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat")):
        group.interface.new_socket(name, in_out="OUTPUT", socket_type=kind)
    group.nodes.new("ShaderNodeAttribute").attribute_name = "madder_stain"
    node = mat.node_tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    mat.node_tree.links.new(node.outputs["Base Color"], bsdf.inputs["Base Color"])
    mat.node_tree.links.new(node.outputs["Roughness"], bsdf.inputs["Roughness"])
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    assert bpy.data.node_groups["Madder Stain"] == group and len(bpy.data.node_groups) == 1
    assert not [n for n in group.nodes if n.type == "ATTRIBUTE"]  # the inputs come from outside now
    # the material keeps its links and gets the attribute inputs
    assert bsdf.inputs["Base Color"].links[0].from_node == node
    assert bsdf.inputs["Roughness"].links[0].from_node == node
    assert node.inputs["Coverage"].links[0].from_node.attribute_name == "madder_stain"
    assert node.inputs["Wetness"].links[0].from_node.attribute_name == "madder_wetness"
    assert sum(n.type == "GROUP" for n in mat.node_tree.nodes) == 1


# -- renders


def setup_render(scene, size=(96, 64), samples=4):
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y = size
    r.resolution_percentage = 100
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.seed = 0
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"


def read_render(path):
    img = bpy.data.images.load(path)
    px = np.empty(len(img.pixels), dtype=np.float32)
    img.pixels.foreach_get(px)
    out = px.reshape(img.size[1], img.size[0], 4)[..., :3].copy()
    bpy.data.images.remove(img)
    return out


def render_still(scene, path):
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return read_render(path)


def stain_measures(stained, bare):
    """The stain in a render, against the bare cloth's: its area (pixels where the
    difference exceeds half its peak) and its centroid (x, y), weighted by the difference.
    The vertex colours of a Detail bake are the fine stain restricted to the cloth's
    vertices (exact in mass), so they spread its faint rim over one cloth cell: a fixed
    low threshold would measure that rim, not the stain."""
    d = np.abs(stained - bare).max(axis=2)
    ys, xs = np.mgrid[: d.shape[0], : d.shape[1]]
    return int((d > 0.5 * d.max()).sum()), np.array([(xs * d).sum(), (ys * d).sum()]) / d.sum()


def show_dye(material, group):
    """Makes `material` emit the dye amount its group reads (its Coverage input's source
    plus its Excess input's, the images' dye above saturation), whichever nodes feed them
    now: the stain's shading is not linear in the dye (Kubelka–Munk, test_shading.py), so
    a half-peak contour of the shaded colour would sit in the faint rim, which the vertex
    colours spread over one cloth cell."""
    nt = material.node_tree
    emit = nt.nodes.get("dye") or nt.nodes.new("ShaderNodeEmission")
    emit.name = "dye"
    total = nt.nodes.get("dye total") or nt.nodes.new("ShaderNodeMath")
    total.name, total.operation = "dye total", "ADD"
    for socket in (emit.inputs["Color"], *total.inputs[:2]):
        for link in socket.links:
            nt.links.remove(link)
        socket.default_value = (0.0, 0.0, 0.0, 1.0) if socket == emit.inputs["Color"] else 0.0
    for name, socket in (("Coverage", total.inputs[0]), ("Excess", total.inputs[1])):
        if group.inputs[name].is_linked:
            nt.links.new(group.inputs[name].links[0].from_socket, socket)
    nt.links.new(total.outputs[0], emit.inputs["Color"])
    out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    nt.links.new(emit.outputs[0], out.inputs["Surface"])


def test_renders_of_the_vertex_colours_and_of_the_images_agree(open_fixture, tmp_path):
    # the two outputs of one smooth field: the default fabric's grain (3 mm) puts detail
    # between the flag's 5 cm vertices that its vertex colours cannot show
    scene, flag = bake_flag(open_fixture, detail=1, grain=False)
    bpy.ops.madder.add_stain_shader()
    setup_render(scene, (160, 96), samples=8)
    scene.frame_set(8)
    mat = flag.active_material
    group = next(n for n in mat.node_tree.nodes if n.type == "GROUP")
    show_dye(mat, group)
    images = render_still(scene, str(tmp_path / "images.exr"))
    flag.madder.output_images = False  # the same material, fed by the attributes
    show_dye(mat, group)
    colours = render_still(scene, str(tmp_path / "colours.exr"))
    nt = mat.node_tree
    for name in ("Stain", "Coverage", "Wetness", "Deposit"):  # unfed, they are 0: the bare cloth
        for link in group.inputs[name].links:
            nt.links.remove(link)
    show_dye(mat, group)
    bare = render_still(scene, str(tmp_path / "bare.exr"))
    area_c, centre_c = stain_measures(colours, bare)
    area_i, centre_i = stain_measures(images, bare)
    print(f"stain: vertex colours {area_c} px at {centre_c}, images {area_i} px at {centre_i}")
    assert area_c > 100, area_c  # a stain a render can measure
    assert abs(area_i - area_c) < 0.04 * area_c, (area_i, area_c)
    assert np.abs(centre_i - centre_c).max() < 1.0, (centre_i, centre_c)  # pixels, of 160 × 96


def test_an_animation_render_shows_each_frames_image(open_fixture, tmp_path):
    """The images of frames 4–100 are replaced by a code (fully stained or bare, per frame):
    each rendered frame must show its own file's code, frames before the bake the first
    frame's, and frames after it the last's."""
    scene = open_fixture("disk.blend")
    disk = make_active(bpy.data.objects["Disk"])
    disk.animation_data_clear()  # still: only the images change between frames
    s = disk.madder
    s.source_group = "stain_source"
    s.liquid = "RED_WINE"
    s.output_images = True
    s.output_vertex_colors = False
    s.image_size = "512"
    first, last = 3, 100  # scene frames start at 0: 1 and 2 come before the bake
    scene.frame_start, scene.frame_end = first, last
    assert bpy.ops.madder.bake() == {"FINISHED"}
    bpy.ops.madder.add_stain_shader()
    rng = np.random.default_rng(12)
    code = {f: int(rng.integers(0, 2)) for f in range(first + 1, last + 1)}
    code[last] = 1
    full = np.zeros((512, 512, 4), np.float32)
    full[...] = (0.3, 0.02, 0.07, 1.0)
    for f, stained in code.items():
        madder.write_exr(image_file(disk, "stain", f), full if stained else np.zeros_like(full))
        madder.write_exr(image_file(disk, "wet", f), np.zeros((512, 512, 3), np.float32), ("R", "G", "B"))
    setup_render(scene, (24, 24), samples=1)
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(tmp_path / "f####")
    scene.frame_start, scene.frame_end = first - 2, last + 2
    bpy.ops.render.render(animation=True)
    frames = {}
    for f in range(first - 2, last + 3):
        img = bpy.data.images.load(str(tmp_path / f"f{f:04d}.png"))
        px = np.empty(len(img.pixels), dtype=np.float32)
        img.pixels.foreach_get(px)
        frames[f] = px.reshape(24, 24, 4)[..., :3]
        bpy.data.images.remove(img)
    # the disk fills the middle of the picture: its mean redness tells stained from bare
    red = {f: float((im[6:18, 6:18, 0] - im[6:18, 6:18, 1]).mean()) for f, im in frames.items()}
    bare = max(red[f] for f, c in code.items() if not c)
    stained = min(red[f] for f, c in code.items() if c)
    assert stained > bare + 0.1, (stained, bare)
    for f, c in code.items():
        assert (red[f] > (bare + stained) / 2) == bool(c), (f, red[f])
    # before the bake: the first frame's file; after it: the last's
    for f in (first - 2, first - 1):
        np.testing.assert_array_equal(frames[f], frames[first])
    for f in (last + 1, last + 2):
        np.testing.assert_array_equal(frames[f], frames[last])
