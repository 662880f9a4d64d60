"""The stain and wetness shading model (addon/shading.py, issue 35) measured on renders:
calibrated swatches (flat squares whose "Madder Stain" group is fed known dye amounts,
wetness and colours on its sockets) rendered in Cycles and in EEVEE with the Standard view
transform, and measured in CIE L*a*b* (blend_fixtures/colour.py, from the CIE and
IEC 61966-2-1 formulas). The expected colours are computed here, independently, with
numpy from the Kubelka–Munk and Lekner–Dorf equations the module doc states."""

import sys

import bpy
import numpy as np
import pytest
from colour import lab as lab_linear, srgb_decode
from conftest import ADDON, eevee_on_newest_only

shading = sys.modules[ADDON + ".shading"]
compat = sys.modules[ADDON + ".compat"]

COTTON = (0.86, 0.85, 0.82)  # white cotton, the gallery's
WINE = (0.30, 0.02, 0.07)  # the Red Wine preset's colour
COFFEE = (0.25, 0.13, 0.05)
R_I = 0.47  # the water film's internal reflectance, the group's default
SCATTER = 0.0  # Wet Scattering, the group's default
WHITE = 0.06  # Surface White, the group's default
CELL, SIDE = 0.12, 0.1  # swatch spacing and size (m)

# --- colour science ------------------------------------------------------------------------

def lab(srgb):
    """CIE 1976 L*a*b* (D65) of display sRGB values (..., 3)."""
    return lab_linear(srgb_decode(srgb))


def chroma(v):
    return float(np.hypot(v[1], v[2]))


# --- the model, independently --------------------------------------------------------------


def ks(r):
    r = np.clip(np.asarray(r, dtype=np.float64), 1e-3, 1.0)
    return (1 - r) ** 2 / (2 * r)


def km(q):
    return 1 + q - np.sqrt(q * q + 2 * q)


def model(base, colour, amount, wetness, yarn=1.0):
    """Kubelka–Munk (cloth + amount × dye), water in the fibres scaling K/S by
    1 + s·w; wet, the dry surface's neutral reflection goes specular and the body under it
    is seen through the water film (Lekner & Dorf), weighted by the wetness."""
    r = km((ks(base) + amount * ks(colour)) * (1 + SCATTER * wetness))
    body = np.clip((r - WHITE) / (1 - WHITE), 0.0, 1.0)
    film = body * (1 - R_I) / (1 - R_I * body)
    return np.minimum(yarn * (r + wetness * (film - r)), 1.0)


# --- the swatch scene ----------------------------------------------------------------------

# name: (column, row, mode, base, liquid colour, dye amount, wetness, yarn, backing); the dye
# amount is Coverage alone (the vertex colours), or (Coverage, Excess) as the images split it
SWATCHES = {}
for i, a in enumerate((0.1, 0.3, 0.6, 1.0)):
    SWATCHES[f"km wine {a}"] = (i, 0, "EMIT", COTTON, WINE, a, 0.0, 1.0, None)
SWATCHES["km coffee 0.5"] = (4, 0, "EMIT", COTTON, COFFEE, 0.5, 0.0, 1.0, None)
SWATCHES["km wet wine"] = (5, 0, "EMIT", COTTON, WINE, 0.6, 1.0, 1.0, None)
SWATCHES["km yarn"] = (6, 0, "EMIT", COTTON, WINE, 0.3, 0.5, 0.8, None)
for i, w in enumerate((0.0, 0.25, 0.5, 0.75, 1.0)):
    SWATCHES[f"water {w}"] = (i, 1, "LIT", COTTON, (1.0, 1.0, 1.0), 0.0, w, 1.0, None)
# a tide line's dye, three times a saturated spot's
SWATCHES["km wine ring"] = (5, 1, "EMIT", COTTON, WINE, 3.0, 0.0, 1.0, None)
SWATCHES["km wine ring, images"] = (6, 1, "EMIT", COTTON, WINE, (1.0, 2.0), 0.0, 1.0, None)
for i, (a, w) in enumerate(((0.3, 0.0), (0.3, 1.0), (1.0, 0.0), (1.0, 1.0))):
    SWATCHES[f"wine {a} {w}"] = (i, 2, "LIT", COTTON, WINE, a, w, 1.0, None)
for i, (w, back) in enumerate(((0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0))):
    SWATCHES[f"backed {w} {back}"] = (i, 3, "LIT", COTTON, (1.0, 1.0, 1.0), 0.0, w, 1.0, back)
COLUMNS, ROWS = 7, 4
PX = 50  # pixels per cell


def _plane(name, location, size, material):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(material)
    return obj


def _plain(name, colour):
    mat = bpy.data.materials.new(name)
    bsdf = next(n for n in compat.ensure_node_tree(mat).nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    return mat


def dye(amount):
    """A swatch's whole dye amount (Coverage + Excess)."""
    return sum(amount) if isinstance(amount, tuple) else amount


def _swatch_material(name, mode, base, colour, amount, wetness, yarn):
    coverage, excess = amount if isinstance(amount, tuple) else (amount, 0.0)
    mat = bpy.data.materials.new(name)
    nt = compat.ensure_node_tree(mat)
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    assert shading.add_to_material(mat)
    for n in [n for n in nt.nodes if n.name.startswith(shading.INPUT_PREFIX)]:
        nt.nodes.remove(n)  # fed on the sockets instead of the attributes
    group = next(n for n in nt.nodes if n.type == "GROUP")
    # premultiplied by the coverage, the amount up to 1 (core `io::attributes`)
    group.inputs["Stain"].default_value = (*(min(coverage, 1.0) * np.asarray(colour)), 1.0)
    group.inputs["Coverage"].default_value = coverage
    group.inputs["Excess"].default_value = excess
    group.inputs["Wetness"].default_value = wetness
    group.inputs["Yarn"].default_value = yarn
    if mode == "EMIT":  # the pixel is the node maths
        emit = nt.nodes.new("ShaderNodeEmission")
        emit.inputs["Strength"].default_value = 1.0
        nt.links.new(group.outputs["Base Color"], emit.inputs["Color"])
        out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
        nt.links.new(emit.outputs[0], out.inputs["Surface"])
    return mat


def build_swatches():
    # not read_factory_settings: that also resets the preferences, disabling the add-on
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    for name, (col, row, mode, base, colour, amount, wet, yarn, back) in SWATCHES.items():
        x, y = (col - (COLUMNS - 1) / 2) * CELL, ((ROWS - 1) / 2 - row) * CELL
        _plane(name, (x, y, 0.0), SIDE, _swatch_material(name, mode, base, colour, amount, wet, yarn))
        if back is not None:  # a backing just behind the cloth
            _plane(f"backing {name}", (x, y, -0.003), CELL, _plain(f"backing {name}", (back,) * 3))
    _plane("Backdrop", (0, 0, -0.02), 3.0, _plain("Backdrop", (0.5, 0.5, 0.5)))
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.type, cam_data.ortho_scale = "ORTHO", COLUMNS * CELL
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = (0, 0, 1.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, 0.05
    sun.rotation_euler = (np.radians(30), 0.0, np.radians(20))
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("World")
    compat.ensure_node_tree(world).nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = COLUMNS * PX, ROWS * PX, 100
    r.image_settings.file_format, r.image_settings.color_depth = "PNG", "16"
    r.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
    return scene


def render(scene, path):
    """Renders `scene` to a 16-bit PNG and returns its display values (rows from the top)."""
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    img.colorspace_settings.name = "Non-Color"  # the stored (display) values, not linearised
    px = np.empty(len(img.pixels), dtype=np.float32)
    img.pixels.foreach_get(px)
    w, h = img.size
    bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3]


def cell(px, name, margin=12):
    col, row = SWATCHES[name][:2]
    return px[row * PX + margin:(row + 1) * PX - margin, col * PX + margin:(col + 1) * PX - margin].reshape(-1, 3)


@pytest.fixture(scope="module", params=["CYCLES", "EEVEE"])
def swatches(request, tmp_path_factory, addon):
    scene = build_swatches()
    if request.param == "CYCLES":
        scene.render.engine = "CYCLES"
        scene.cycles.samples, scene.cycles.use_denoising = 64, False
        scene.cycles.device = "CPU"
    else:
        eevee_on_newest_only()
        scene.render.engine = compat.eevee_engine()
        scene.eevee.taa_render_samples = 16
    px = render(scene, str(tmp_path_factory.mktemp("swatches") / f"{request.param}.png"))
    return request.param, {name: cell(px, name).mean(axis=0) for name in SWATCHES}


def test_stain_colour_follows_kubelka_munk(swatches):
    engine, means = swatches
    for name, (_c, _r, mode, base, colour, amount, wet, yarn, _b) in SWATCHES.items():
        if mode != "EMIT":
            continue
        want = model(np.array(base), np.array(colour), dye(amount), wet, yarn)
        got = srgb_decode(means[name])
        np.testing.assert_allclose(got, want, rtol=0.02, atol=2e-4, err_msg=f"{engine} {name}")
    # a thin stain is a pale tint of the same hue, the reference amount is the liquid's colour
    thin, full = srgb_decode(means["km wine 0.1"]), srgb_decode(means["km wine 1.0"])
    assert np.argmin(thin) == np.argmin(WINE) and np.argmax(thin) == np.argmax(WINE)
    assert np.all(thin > full)


def test_a_tide_line_above_saturation_is_darker_from_either_output(swatches):
    """The dye amount is not limited to a saturated spot's (1): a ring with three times the
    dye is visibly darker (ΔE*ab > 5) than the saturated spot, whether the amount arrives
    whole in Coverage (vertex colours) or split into Coverage 1 and Excess 2 (images)."""
    engine, means = swatches
    full, ring, split = (lab(means[n]) for n in ("km wine 1.0", "km wine ring", "km wine ring, images"))
    print(f"{engine}: L* saturated {full[0]:.1f}, ring {ring[0]:.1f} / {split[0]:.1f}")
    assert np.linalg.norm(ring - full) > 5.0 and ring[0] < full[0]
    assert np.linalg.norm(ring - split) < 0.5


def test_wet_is_darker_and_more_saturated(swatches):
    engine, means = swatches
    for a in (0.3, 1.0):
        dry, wet = lab(means[f"wine {a} 0.0"]), lab(means[f"wine {a} 1.0"])
        print(f"{engine} wine {a}: dry L*a*b* {np.round(dry, 2)} C* {chroma(dry):.2f}, "
              f"wet {np.round(wet, 2)} C* {chroma(wet):.2f}")
        assert wet[0] < dry[0], (engine, a, dry, wet)
        assert chroma(wet) >= chroma(dry), (engine, a, dry, wet)


def test_water_on_white_cotton_darkens_linearly(swatches):
    engine, means = swatches
    w = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    lstar = np.array([lab(means[f"water {x}"])[0] for x in w])
    dl = lstar[0] - lstar
    assert dl[-1] >= 5.0, (engine, lstar)
    fit = np.polyfit(w, dl, 1)
    r2 = 1 - np.sum((dl - np.polyval(fit, w)) ** 2) / np.sum((dl - dl.mean()) ** 2)
    assert r2 > 0.9, (engine, dl, r2)


def test_wet_cloth_shows_its_backing(swatches):
    engine, means = swatches
    contrast = {w: lab(means[f"backed {w} 1.0"])[0] - lab(means[f"backed {w} 0.0"])[0] for w in (0.0, 1.0)}
    assert contrast[1.0] > 0 and contrast[1.0] >= 2 * abs(contrast[0.0]), (engine, contrast)


def test_red_wine_dries_lighter(tmp_path):
    """The gallery's Red Wine square (its spill, cloth and image sequence, `gallery.py`),
    rendered lit in Cycles (the gallery's sun, 12° off the camera's axis) 1, 15 and 60
    minutes after the spill: the centre's L* rises all the way, halfway dry included (a
    partly wet cloth's gloss is the film's lobe in proportion, not a broad one of
    intermediate roughness that catches the sun)."""
    import gallery
    import harness

    blend = str(tmp_path / "wine.blend")
    gallery.build_scene(blend, ("RED_WINE", "PLAIN"))  # factory settings: the add-on again below
    harness.install_extension(harness.default_zip())
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    obj = bpy.data.objects[gallery.square_name("RED_WINE", "PLAIN")]
    gallery.configure(obj, "RED_WINE", "PLAIN", gallery.SUBSTEPS, "512")
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    cam = scene.camera
    cam.location = (obj.location.x, obj.location.y, 1.0)
    cam.data.ortho_scale = gallery.SIZE
    r = scene.render
    r.resolution_x = r.resolution_y = 64
    scene.cycles.samples, scene.cycles.use_denoising = 32, False
    r.image_settings.file_format, r.image_settings.color_depth = "PNG", "16"
    scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
    lstar = {}
    wetness = {}
    for frame in (2, 16, 61):  # 1, 15 and 60 minutes after the spill (frame 1)
        scene.frame_set(frame)
        px = render(scene, str(tmp_path / f"wine{frame}.png"))
        lstar[frame] = lab(px[28:36, 28:36].reshape(-1, 3).mean(axis=0))[0]
        wetness[frame] = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.attributes[
            "madder_wetness"].data[len(obj.data.vertices) // 2].value
    print(f"Red Wine centre L* {lstar}, wetness {wetness}")
    assert wetness[2] > wetness[16] > wetness[61]  # the water leaves
    assert lstar[61] > lstar[16] + 1.0 and lstar[16] > lstar[2] + 1.0, lstar


def test_the_previous_group_is_upgraded_in_place(open_fixture):
    """The group of the Madder before this model (its nine inputs, a neutral wet
    darkening, no Yarn, no transmission) becomes this one on Add Stain Shader: the
    material keeps its links, gains the see-through Mix Shader between its BSDF and its
    output, and a Wet Roughness left at the old default takes the new one."""
    from conftest import make_active

    open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    mat = flag.active_material
    nt = mat.node_tree
    group = bpy.data.node_groups.new("Madder Stain", "ShaderNodeTree")
    old = (("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat"), ("Wet Darkening", "NodeSocketFloat"),
           ("Wet Roughness", "NodeSocketFloat"), ("Deposit Darkening", "NodeSocketFloat"),
           ("Stain", "NodeSocketColor"), ("Coverage", "NodeSocketFloat"), ("Wetness", "NodeSocketFloat"),
           ("Deposit", "NodeSocketFloat"))
    for name, kind in old:
        group.interface.new_socket(name, in_out="INPUT", socket_type=kind)
    for name, kind in (("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat")):
        group.interface.new_socket(name, in_out="OUTPUT", socket_type=kind)
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.inputs["Wet Roughness"].default_value = 0.25
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    output = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    nt.links.new(node.outputs["Base Color"], bsdf.inputs["Base Color"])
    nt.links.new(node.outputs["Roughness"], bsdf.inputs["Roughness"])
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    assert bpy.data.node_groups["Madder Stain"] == group and len(bpy.data.node_groups) == 1
    assert "Yarn" in node.inputs and "Wet Darkening" not in node.inputs and "Deposit Darkening" not in node.inputs
    assert node.inputs["Yarn"].default_value == 1.0
    assert node.inputs["Wet Roughness"].default_value == pytest.approx(0.1)
    assert bsdf.inputs["Base Color"].links[0].from_node == node
    assert node.inputs["Wetness"].links[0].from_node.attribute_name == "madder_wetness"
    # the liquid's film is the BSDF's coat: weight and roughness from the group, water's index
    assert bsdf.inputs["Coat Weight"].links[0].from_socket == node.outputs["Film"]
    assert bsdf.inputs["Coat Roughness"].links[0].from_socket == node.outputs["Film Roughness"]
    assert bsdf.inputs["Coat IOR"].default_value == pytest.approx(1.33)
    mix = output.inputs["Surface"].links[0].from_node
    assert mix.type == "MIX_SHADER" and mix.inputs[0].links[0].from_socket == node.outputs["Translucency"]
    assert mix.inputs[1].links[0].from_node == bsdf and mix.inputs[2].links[0].from_node.type == "BSDF_TRANSPARENT"
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}  # idempotent
    assert sum(n.type == "MIX_SHADER" for n in nt.nodes) == 1
    # a group with today's sockets but an older revision of the maths is rebuilt too
    assert group["madder_revision"] == shading.REVISION
    group["madder_revision"] = shading.REVISION - 1
    n_nodes = len(group.nodes)
    group.nodes.new("ShaderNodeMath")
    assert shading.stain_group() == group and group["madder_revision"] == shading.REVISION
    assert len(group.nodes) == n_nodes


def _front_render(tmp_path, name, edge, roughness, size=0.4, pixels=1000):
    """The group's Dye output rendered (Cycles, orthographic, one point sample a pixel,
    32-bit EXR) on a `size` m square centred at the origin, the group fed Coverage 1, an
    Outline Distance of x (metres: the front along x = 0, the stain at x > 0), the Outline
    Position the point itself, and `edge`, `roughness`. Returns the (pixels, pixels) dye,
    row 0 at low y, and the pixels' centres' x (metres)."""
    bpy.ops.wm.read_homefile(use_empty=True)  # (as build_swatches: the add-on stays enabled)
    scene = bpy.context.scene
    mat = bpy.data.materials.new(name)
    nt = compat.ensure_node_tree(mat)
    nt.nodes.clear()
    group = nt.nodes.new("ShaderNodeGroup")
    group.node_tree = shading.stain_group()
    coords, split = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(coords.outputs["Object"], split.inputs[0])
    nt.links.new(split.outputs["X"], group.inputs["Outline Distance"])
    nt.links.new(coords.outputs["Object"], group.inputs["Outline Position"])
    group.inputs["Coverage"].default_value = 1.0
    group.inputs["Edge Width"].default_value = edge
    group.inputs["Front Roughness"].default_value = roughness
    emit, out = nt.nodes.new("ShaderNodeEmission"), nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(group.outputs["Dye"], emit.inputs["Color"])
    nt.links.new(emit.outputs[0], out.inputs["Surface"])
    _plane(name, (0.0, 0.0, 0.0), size, mat)
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", size
    cam.location = (0.0, 0.0, 1.0)
    scene.collection.objects.link(cam)
    scene.camera, scene.render.engine = cam, "CYCLES"
    scene.cycles.samples, scene.cycles.device, scene.cycles.max_bounces = 1, "CPU", 0
    scene.render.filter_size = 0.01
    scene.render.resolution_x = scene.render.resolution_y = pixels
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(tmp_path / f"{name}.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(scene.render.filepath)
    px = np.array(img.pixels[:], dtype=np.float64).reshape(pixels, pixels, 4)[..., 0]
    bpy.data.images.remove(img)
    return px, (np.arange(pixels) + 0.5) * size / pixels - size / 2


def test_the_front_is_drawn_at_the_pixel_with_its_roughness(addon, tmp_path):
    """The group's front (module doc, "The outline"): with no roughness, the dye across a
    front at x = 0 rises as clamp(½ + x/e), 10–90 % over 0.8 e, centred on the front;
    with the Edge Width far above the roughness the cover is linear in the noise, so the
    image gives the front's wander itself, whose RMS is the default Front Roughness (the
    noise's calibration, `shading.noise_rms`) and whose mean is 0 (the front is not moved
    on average)."""
    e = 4e-3
    px, x = _front_render(tmp_path, "smooth", e, 0.0, size=0.04, pixels=400)
    # (the rows along the square's top and bottom edges, which Cycles samples at the
    # plane's very border, are left out)
    np.testing.assert_allclose(px[4:-4], np.broadcast_to(np.clip(0.5 + x / e, 0, 1), px[4:-4].shape), atol=0.01)
    # the wander: cover = ½ + n/e for |n| far below e/2
    wide, rough = 1.0, shading.stain_group().interface.items_tree["Front Roughness"].default_value
    assert rough > 0
    px, x = _front_render(tmp_path, "rough", wide, rough)
    wander = (px[4:-4] - (0.5 + x / wide)) * wide
    rms = wander.std()
    print(f"front wander: RMS {rms * 1e3:.2f} mm for a Front Roughness of {rough * 1e3:.1f} mm, "
          f"mean {wander.mean() * 1e3:.3f} mm")
    assert rms == pytest.approx(rough, rel=0.15)
    # the mean, to the sampling error of the largest octave over ten periods (~RMS/10
    # a period-row, 0.78 mm measured); an offset of Fac's mean by 0.05 would be 3 mm
    assert abs(wander.mean()) < 1.2e-3
