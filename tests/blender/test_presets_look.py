"""What a new user gets (issue 34): the flag fixture baked with only the Red Wine preset
chosen (Madder Stain on, the Spill Group, the Liquid: nothing else), then Add Stain
Shader, as a user renders it. The look must be on by default (an Auto Detail above 0, the
image sequence written, the grain of the default fabric, the preset's wicking, Sharp
Outline drawn by the shader), and the dried stain's outline, rendered, must be sharp and
rough as imbibition fronts are: its 10–90 % edge width at most two thread pitches of the
default fabric (plain cotton), and its roughness w(l) ∝ l^α with α in 0.5–0.75 between 1
and 20 mm. The render reads the Madder Stain group's Dye output (the dye amount at the
pixel, what its colour is computed from) through an Emission shader, in six orthographic
close-ups along the front, 40 mm across at 0.08 mm a pixel, on a flat copy of the UV layout at the
cloth's own scale. The images' own modes (Sharp Outline within a texel, and off) are
checked against each other as before: within a texel the edge is at most half the
Detail mesh's, keeping the dye's total."""

import os
import sys

import bpy
import numpy as np
import pytest
from conftest import ADDON, make_active


def stain_alpha(flag, frame):
    """The stain image's alpha (its opacity, the deposit read against the references) at
    `frame`, as a (size, size) array (row 0 at v = 0)."""
    s = flag.madder
    folder = os.path.join(os.path.dirname(bpy.path.abspath(s.cache_file)), f"{flag.name}_images")
    img = bpy.data.images.load(os.path.join(folder, f"{flag.name}_stain.{frame:04d}.exr"))
    n = img.size[0]
    a = np.array(img.pixels[:], dtype=np.float64).reshape(n, n, 4)[..., 3]
    bpy.data.images.remove(img)
    return a


def metres_per_uv(flag):
    """Metres spanned by one UV unit along u and along v: the medians over the faces of
    the lengths of the rest pose's Jacobian columns dX/du, dX/dv (a UV layout that maps
    the flag's 2 × 1.2 m onto the unit square stretches them differently)."""
    mesh = flag.data
    uv = mesh.uv_layers.active.data
    m = flag.matrix_world.to_3x3()
    cols = []
    for p in mesh.polygons:
        li = list(p.loop_indices)[:3]
        x = [np.array(m @ mesh.vertices[mesh.loops[i].vertex_index].co) for i in li]
        u = [np.array(uv[i].uv) for i in li]
        duv = np.array([u[1] - u[0], u[2] - u[0]])
        if abs(np.linalg.det(duv)) < 1e-12:
            continue
        jac = np.linalg.solve(duv, np.array([x[1] - x[0], x[2] - x[0]]))  # rows: dX/du, dX/dv
        cols.append(np.linalg.norm(jac, axis=1))
    return np.median(np.array(cols), axis=0)


def edge_width(alpha, texel):
    """The 10–90 % edge width (m) across the outline: at each texel of the 50 % contour
    of the deposit (its plateau the 99th percentile of the stained texels), a linear
    ramp of the local gradient rises from 10 % to 90 % over 0.8 · plateau / |∇alpha|;
    the median over the contour. `texel` is (metres along u, along v)."""
    top = np.percentile(alpha[alpha > 0.02 * alpha.max()], 99)
    gv, gu = np.gradient(alpha, texel[1], texel[0])  # rows are v, columns u
    inside = alpha > 0.5 * top
    padded = np.pad(inside, 1, mode="edge")  # (the image's border is no edge of the stain)
    contour = inside & ~(padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:])
    slope = np.hypot(gu, gv)[contour]
    return float(np.median(0.8 * top / slope[slope > 0]))


def local_level(dye, pixel, radius):
    """`dye` over its local plateau: its largest value within `radius` metres (a square of
    side 2·radius), where that is above 2 % of the largest; 0 elsewhere. On a close-up the
    stain's level changes across the window (the tide line, a darker pool), so its edge is
    read against the plateau behind it, not the window's."""
    from numpy.lib.stride_tricks import sliding_window_view

    k = int(round(radius / pixel))
    top = np.pad(dye, k, mode="edge")
    top = sliding_window_view(top, 2 * k + 1, axis=0).max(axis=-1)
    top = sliding_window_view(top, 2 * k + 1, axis=1).max(axis=-1)
    out = np.zeros_like(dye)
    on = top > 0.02 * dye.max()
    out[on] = dye[on] / top[on]
    return out


def outline(alpha, texel):
    """The outer 50 % contour of the deposit (as in `edge_width`) in metres, (K, 2): the
    longest line contourpy traces (holes inside the stain trace shorter ones)."""
    import contourpy

    top = np.percentile(alpha[alpha > 0.02 * alpha.max()], 99)
    lines = contourpy.contour_generator(z=alpha, line_type=contourpy.LineType.Separate).lines(0.5 * top)
    line = max(lines, key=len)  # (x, y) in texel indices: columns are u, rows v
    return line * np.array(texel)


def roughness(alpha, pixel, lengths):
    """Boundary roughness w(l) of the front in a close-up `alpha` (square pixels of `pixel`
    metres): Family–Vicsek's interface width, as imbibition fronts are measured (Buldyrev
    et al. 1992). The front's mean direction t is that of its 50 % contour (`outline`);
    the front's height h(u) at each position u along t is the contour's farthest reach
    toward the dry side (overhangs count once, as the wetted height of a column does);
    w(l) is the RMS of h about its best-fitting line over windows of length l along t,
    averaged over windows starting every l/2. Heights over the mean line, not distances
    along the contour's arc: a front rough down to the pixel has an arc many times its
    span, and windows of arc length see ever less of it as the roughness grows."""
    points = outline(alpha, (pixel, pixel))
    centre = points.mean(axis=0)
    t, m = np.linalg.svd(points - centre, full_matrices=False)[2]  # along, across the front
    rows, cols = np.indices(alpha.shape)
    across = (np.c_[cols.ravel(), rows.ravel()] * pixel - centre) @ m
    if alpha.ravel()[across > 0].mean() > alpha.ravel()[across < 0].mean():
        m = -m  # m points to the dry side
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    step = pixel / 4  # the heights' spacing along t
    fine = np.arange(0.0, s[-1], step / 2)  # the contour resampled finely
    p = np.c_[np.interp(fine, s, points[:, 0]), np.interp(fine, s, points[:, 1])] - centre
    u, v = p @ t, p @ m
    bins = np.floor((u - u.min()) / step).astype(int)
    h = np.full(bins.max() + 1, -np.inf)
    np.maximum.at(h, bins, v)
    return family_vicsek(h, step, lengths)


def family_vicsek(h, step, lengths):
    """w(l) of a profile h sampled `step` apart (−inf where it has no value): the RMS of h
    about its best-fitting line over windows of l, starting every l/2, averaged over the
    windows at least 90 % sampled; NaN where there are none."""
    covered = np.isfinite(h)
    x = np.arange(len(h)) * step
    w = []
    for ell in lengths:
        n = int(round(ell / step))
        values = []
        for start in range(0, len(h) - n + 1, max(n // 2, 1)):
            ok = covered[start:start + n]
            if ok.mean() > 0.9:
                xs, hs = x[start:start + n][ok], h[start:start + n][ok]
                values.append(np.std(hs - np.polyval(np.polyfit(xs, hs, 1), xs)))
        w.append(np.mean(values) if values else np.nan)
    return np.array(w)


PIXEL = 0.08e-3  # metres a pixel of the close-ups
WINDOW = 40e-3  # metres across a close-up
CLOSE_UPS = 6  # along the front


def wet_alpha(flag, frame):
    """The wet image's alpha at `frame` (the front's signed distance, metres; 1 where the
    image has no alpha channel)."""
    return wet_channel(flag, frame, 3)


def wet_channel(flag, frame, channel):
    """Channel `channel` of the wet image at `frame`, (size, size), row 0 at v = 0."""
    s = flag.madder
    folder = os.path.join(os.path.dirname(bpy.path.abspath(s.cache_file)), f"{flag.name}_images")
    img = bpy.data.images.load(os.path.join(folder, f"{flag.name}_wet.{frame:04d}.exr"))
    n = img.size[0]
    px = np.array(img.pixels[:], dtype=np.float64).reshape(n, n, 4)
    bpy.data.images.remove(img)
    return px[..., channel]


def front_points(distance, count):
    """`count` points (UV) spaced evenly by arc length along the longest zero contour of
    the wet image's distance channel (the simulated front)."""
    import contourpy

    n = distance.shape[0]
    lines = contourpy.contour_generator(z=distance, line_type=contourpy.LineType.Separate).lines(0.0)
    line = max(lines, key=len)
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(seg)]
    t = (np.arange(count) + 0.5) / count * arc[-1]
    return np.c_[np.interp(t, arc, line[:, 0]), np.interp(t, arc, line[:, 1])] / n  # texel index -> UV
    # (a texel's centre is at (i + ½)/n: the half texel is far below a window's size)


def render_dye(flag, material, frame, centre, scales, path):
    """Renders the Madder Stain group's Dye output of `material` (the flag's, its group
    reading the flag's images) on a flat square of UV layout around `centre` (UV), laid
    out at the cloth's metres per UV `scales`, WINDOW across at PIXEL a pixel: an
    orthographic Cycles render, one point sample a pixel, of an Emission shader fed the
    Dye. Returns the (pixels, pixels) dye, row 0 at low v."""
    scene = bpy.context.scene
    half = np.array([WINDOW / 2 / scales[0], WINDOW / 2 / scales[1]])
    corners = [centre + half * np.array(c) for c in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    mesh = bpy.data.meshes.new("Close-up")
    mesh.from_pydata([(u * scales[0], v * scales[1], 0.0) for u, v in corners], [], [(0, 1, 2, 3)])
    layer = mesh.uv_layers.new(name=flag.madder.image_uv_map)
    for loop, (u, v) in zip(layer.data, corners, strict=True):
        loop.uv = (u, v)
    mat = material.copy()
    nt = mat.node_tree
    group = next(n for n in nt.nodes if n.type == "GROUP" and n.node_tree.name == "Madder Stain")
    emit, out = nt.nodes.new("ShaderNodeEmission"), next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
    nt.links.new(group.outputs["Dye"], emit.inputs["Color"])
    nt.links.new(emit.outputs[0], out.inputs["Surface"])
    mesh.materials.append(mat)
    plane = bpy.data.objects.new("Close-up", mesh)
    scene.collection.objects.link(plane)
    cam = bpy.data.objects.new("Close-up camera", bpy.data.cameras.new("Close-up camera"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", WINDOW
    mid = [centre[0] * scales[0], centre[1] * scales[1]]
    cam.location = (mid[0], mid[1], 1.0)
    scene.collection.objects.link(cam)
    hidden = {o.name: o.hide_render for o in scene.objects}
    for o in scene.objects:
        o.hide_render = o not in (plane, cam)
    saved = (scene.camera, scene.render.engine, scene.render.resolution_x, scene.render.resolution_y,
             scene.render.resolution_percentage, scene.render.filepath, scene.view_settings.view_transform)
    try:
        scene.camera, scene.render.engine = cam, "CYCLES"
        scene.cycles.samples, scene.cycles.device, scene.cycles.max_bounces = 1, "CPU", 0
        scene.render.filter_size = 0.01
        pixels = round(WINDOW / PIXEL)
        scene.render.resolution_x = scene.render.resolution_y = pixels
        scene.render.resolution_percentage = 100
        scene.view_settings.view_transform = "Standard"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.filepath = str(path)
        scene.frame_set(frame)
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(str(path))
        dye = np.array(img.pixels[:], dtype=np.float64).reshape(pixels, pixels, 4)[..., 0]
        bpy.data.images.remove(img)
    finally:
        (scene.camera, scene.render.engine, scene.render.resolution_x, scene.render.resolution_y,
         scene.render.resolution_percentage, scene.render.filepath, scene.view_settings.view_transform) = saved
        for o in scene.objects:
            if o.name in hidden:
                o.hide_render = hidden[o.name]
        bpy.data.objects.remove(plane)
        bpy.data.objects.remove(cam)
        bpy.data.materials.remove(mat)
    return dye


def bilinear(image, uv):
    """`image` (n, n) sampled bilinearly at UV points `uv` (..., 2), as a texture reads it
    (texel centres at (i + ½)/n, the border extended)."""
    n = image.shape[0]
    x = np.clip(uv[..., 0] * n - 0.5, 0, n - 1)
    y = np.clip(uv[..., 1] * n - 0.5, 0, n - 1)
    x0, y0 = np.minimum(x.astype(int), n - 2), np.minimum(y.astype(int), n - 2)
    fx, fy = x - x0, y - y0
    return ((1 - fx) * (1 - fy) * image[y0, x0] + fx * (1 - fy) * image[y0, x0 + 1]
            + (1 - fx) * fy * image[y0 + 1, x0] + fx * fy * image[y0 + 1, x0 + 1])


def self_affine(hurst, rms, count, step, largest, seed):
    """A self-affine profile h (count,) on points `step` m apart: random phases under the
    spectrum |ĥ(k)|² ∝ k^−(2H+1) from 1/`largest` to the grid's Nyquist, scaled to `rms`."""
    k = np.fft.rfftfreq(count, step)
    amplitude = np.where(k > 1.0 / largest, np.maximum(k, 1e-12) ** -(hurst + 0.5), 0.0)
    phase = np.exp(2j * np.pi * np.random.default_rng(seed).random(len(k)))
    h = np.fft.irfft(amplitude * phase, count)
    return h * rms / h.std()


@pytest.mark.parametrize("hurst", [0.4, 0.63])
def test_the_roughness_measure_recovers_a_fronts_exponent(hurst):
    """`roughness` on drawn fronts of known roughness: a front x = h(y), h self-affine of
    Hurst exponent H, rendered as the shader draws an edge (clamp(½ + (x − h)/e), e 0.4
    mm, 0.08 mm pixels) in 40 mm close-ups. Its exponent between 1 and 20 mm is that of
    h's own w(l) (`family_vicsek` on h itself, the same close-ups) within 0.05, gently rough (0.3
    mm RMS at 40 mm) and as rough as the shader's default (3 mm), where the fronts are
    steep at the pixel. (Windows of arc length along the contour, the measure this one
    replaced, gave 0.96 for H 0.63 at 3 mm RMS: the arc grows with the roughness.)"""
    lengths = np.geomspace(1e-3, 20e-3, 8)
    side = int(round(WINDOW / PIXEL))
    x = (np.arange(side) + 0.5) * PIXEL - WINDOW / 2
    for rms in (0.3e-3, 3e-3):
        h = self_affine(hurst, rms, 4 * side, PIXEL, 0.04, seed=7)
        measured, truth = [], []
        for k in range(4):
            front = h[k * side:(k + 1) * side] - h[k * side:(k + 1) * side].mean()
            dye = np.clip(0.5 + (x[None, :] - front[:, None]) / 0.4e-3, 0.0, 1.0)  # rows along y
            measured.append(roughness(dye, PIXEL, lengths))
            truth.append(family_vicsek(front, PIXEL, lengths))
        fit = [np.polyfit(np.log(lengths), np.log(np.mean(w, axis=0)), 1)[0] for w in (measured, truth)]
        print(f"H {hurst}, {rms * 1e3:.1f} mm RMS: roughness's exponent {fit[0]:.3f}, the profile's {fit[1]:.3f}")
        assert fit[0] == pytest.approx(fit[1], abs=0.05)


def test_only_a_preset_gives_a_sharp_stain(open_fixture, tmp_path):
    presets, bake = sys.modules[ADDON + ".presets"], sys.modules[ADDON + ".bake"]
    scene = open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    s = flag.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.liquid = "RED_WINE"
    assert flag.data.uv_layers.active is not None
    assert bpy.ops.madder.bake() == {"FINISHED"}
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    # the look is on
    assert s.bake_detail > 0
    assert s.image_baked and s.image_baked_size > 0
    assert s.wicking == presets.WICKING["RED_WINE"] > 0
    assert s.spill_shape == "POOL"  # the soft group's liquid lands as a pool
    assert s.sharp_outline and s.outline_in_shader and s.image_baked_outline and s.image_baked_outline_shader
    cotton = presets.FABRIC_PRESETS[presets.DEFAULT_FABRIC]
    kw = bake.simulator_settings(scene, flag)
    assert kw["irregularity"] == cotton["irregularity"] > 0
    assert kw["irregularity_length"] == pytest.approx(cotton["irregularity_length"] * 1e-3)
    pitch = 0.01 / cotton["thread_count"]
    frame = s.image_frames[1]  # the dried stain
    scales = metres_per_uv(flag)
    texel = scales / s.image_baked_size  # (u, v) metres per texel

    # what the user renders: close-ups of the front at four places along it
    distance = wet_alpha(flag, frame)
    assert np.all(np.abs(distance) <= 0.02 + 1e-5)  # metres (core `texture::outline::DISTANCE_LIMIT`)
    material = flag.material_slots[0].material
    lengths = np.geomspace(1e-3, 20e-3, 8)
    widths, rough, rendered, expected = [], [], 0.0, 0.0
    centres = front_points(distance, CLOSE_UPS)
    for k, centre in enumerate(centres):
        dye = render_dye(flag, material, frame, centre, scales, tmp_path / f"close-up-{k}.exr")
        level = local_level(dye, PIXEL, 2e-3)
        widths.append(edge_width(level, (PIXEL, PIXEL)))
        rough.append(roughness(level, PIXEL, lengths))
        rendered += dye.sum()
        print(f"close-up {k} at UV ({centre[0]:.3f}, {centre[1]:.3f}): edge width {widths[-1] * 1e3:.2f} mm")
    width = float(np.median(widths))
    w = np.nanmean(np.array(rough), axis=0)
    ok = np.isfinite(w) & (w > 0)
    alpha_fit = np.polyfit(np.log(lengths[ok]), np.log(w[ok]), 1)[0]
    print(f"\nflag, Red Wine only: Detail {s.bake_detail}, {s.image_baked_size} px images "
          f"({texel[0] * 1e3:.2f} × {texel[1] * 1e3:.2f} mm texels); rendered at {PIXEL * 1e3:.2f} mm: "
          f"10-90 % edge width {width * 1e3:.2f} mm ({width / pitch:.2f} thread pitches of {pitch * 1e3:.2f} mm); "
          "roughness w(l) "
          + ", ".join(f"{ell * 1e3:.1f} mm: {v * 1e3:.3f} mm" for ell, v in zip(lengths, w, strict=True))
          + f"; exponent {alpha_fit:.2f}")
    assert width <= 2 * pitch
    assert 0.5 <= alpha_fit <= 0.75

    # the images' own outline: within a texel, against as the Detail mesh resolves them
    s.outline_in_shader = False
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert s.image_baked_outline and not s.image_baked_outline_shader
    sharp = stain_alpha(flag, frame)
    assert np.all(wet_alpha(flag, frame) == 1.0)  # no distance channel
    s.sharp_outline = False
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert not s.image_baked_outline
    soft = stain_alpha(flag, frame)
    soft_dye = soft + 16.0 * wet_channel(flag, frame, 2)  # the dye amount: coverage and excess
    sharp_width, soft_width = edge_width(sharp, texel), edge_width(soft, texel)
    print(f"images: edge width within a texel {sharp_width * 1e3:.2f} mm, as resolved {soft_width * 1e3:.2f} mm; "
          f"dye total {sharp.sum() / soft.sum():.4f} of it")
    assert sharp_width < 0.6 * soft_width
    assert abs(sharp.sum() / soft.sum() - 1) < 0.02
    # the shader's front keeps the dye: the close-ups' total against the soft images' there
    for centre in centres:
        pixels = round(WINDOW / PIXEL)
        t = (np.arange(pixels) + 0.5) / pixels - 0.5
        uv = np.stack(np.meshgrid(centre[0] + t * WINDOW / scales[0], centre[1] + t * WINDOW / scales[1]), axis=-1)
        expected += bilinear(soft_dye, uv).sum()
    print(f"rendered dye in the close-ups: {rendered / expected:.4f} of the soft images'")
    assert abs(rendered / expected - 1) < 0.05
    # on again: the bake's images bit for bit
    s.sharp_outline = s.outline_in_shader = True
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert s.image_baked_outline_shader
    assert np.array_equal(wet_alpha(flag, frame), distance)
