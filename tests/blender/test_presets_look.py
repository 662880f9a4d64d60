"""What a new user gets (issue 34): the flag fixture baked with only the Red Wine preset
chosen (Madder Stain on, the Spill Group, the Liquid: nothing else). The look must be on
by default (an Auto Detail above 0, the image sequence written, the grain of the default
fabric, the preset's wicking, Sharp Outline), and the dried stain's outline must be
sharp: its 10–90 % edge width at most two thread pitches of the default fabric (plain
cotton). That is not met yet: the test reports the width and the boundary roughness, and
asserts that Sharp Outline at least halves the width the Detail mesh gives, keeping the
dye's total, before it is marked xfail when the width is over."""

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
    contour = inside & ~(np.roll(inside, 1, 0) & np.roll(inside, -1, 0) & np.roll(inside, 1, 1)
                         & np.roll(inside, -1, 1))
    slope = np.hypot(gu, gv)[contour]
    return float(np.median(0.8 * top / slope[slope > 0]))


def outline(alpha, texel):
    """The outer 50 % contour of the deposit (as in `edge_width`) in metres, (K, 2): the
    longest line contourpy traces (holes inside the stain trace shorter ones)."""
    import contourpy

    top = np.percentile(alpha[alpha > 0.02 * alpha.max()], 99)
    lines = contourpy.contour_generator(z=alpha, line_type=contourpy.LineType.Separate).lines(0.5 * top)
    line = max(lines, key=len)  # (x, y) in texel indices: columns are u, rows v
    return line * np.array(texel)


def roughness(points, lengths):
    """Boundary roughness of the outline `points` (K, 2) metres: w(l) the RMS distance of
    the outline from its best-fitting straight line over stretches of arc length l,
    averaged over stretches starting every l/2 (Family–Vicsek's interface width, without
    assuming the outline star-shaped). Reported, not asserted."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    t = np.arange(0.0, s[-1], lengths[0] / 8)  # resampled evenly along the arc
    p = np.c_[np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])]
    w = []
    for ell in lengths:
        values = []
        for start in np.arange(0.0, s[-1] - ell, ell / 2):
            q = p[(t >= start) & (t < start + ell)]
            if len(q) >= 3:
                q = q - q.mean(axis=0)
                values.append(np.linalg.svd(q, compute_uv=False)[-1] / np.sqrt(len(q)))
        w.append(np.mean(values) if values else np.nan)
    return np.array(w)


def test_only_a_preset_gives_a_sharp_stain(open_fixture):
    presets, bake = sys.modules[ADDON + ".presets"], sys.modules[ADDON + ".bake"]
    scene = open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    s = flag.madder
    s.enabled = True
    s.source_group = "stain_source"
    s.liquid = "RED_WINE"
    assert flag.data.uv_layers.active is not None
    assert bpy.ops.madder.bake() == {"FINISHED"}
    # the look is on
    assert s.bake_detail > 0
    assert s.image_baked and s.image_baked_size > 0
    assert s.wicking == presets.WICKING["RED_WINE"] > 0
    assert s.spill_shape == "POOL"  # the soft group's liquid lands as a pool
    cotton = presets.FABRIC_PRESETS[presets.DEFAULT_FABRIC]
    kw = bake.simulator_settings(scene, flag)
    assert kw["irregularity"] == cotton["irregularity"] > 0
    assert kw["irregularity_length"] == pytest.approx(cotton["irregularity_length"] * 1e-3)
    # the dried stain's edge
    alpha = stain_alpha(flag, s.image_frames[1])
    texel = metres_per_uv(flag) / alpha.shape[0]  # (u, v) metres per texel
    width = edge_width(alpha, texel)
    pitch = 0.01 / cotton["thread_count"]
    lengths = np.geomspace(1e-3, 20e-3, 8)
    w = roughness(outline(alpha, texel), lengths)
    ok = np.isfinite(w) & (w > 0)
    alpha_fit = np.polyfit(np.log(lengths[ok]), np.log(w[ok]), 1)[0] if ok.sum() >= 3 else float("nan")
    print(f"\nflag, Red Wine only: Detail {s.bake_detail}, {s.image_baked_size} px images "
          f"({texel[0] * 1e3:.2f} × {texel[1] * 1e3:.2f} mm texels), 10-90 % edge width {width * 1e3:.2f} mm "
          f"({width / pitch:.2f} thread pitches of {pitch * 1e3:.2f} mm); roughness w(l) "
          + ", ".join(f"{ell * 1e3:.1f} mm: {v * 1e3:.3f} mm" for ell, v in zip(lengths, w, strict=True))
          + f"; exponent {alpha_fit:.2f}")
    # Sharp Outline (on by default) drew that edge within a texel: against the images as the
    # Detail mesh resolves them (Re-export Textures without it), the edge is at most half as
    # wide and the dye's total within 2 %; with it again, the bake's images bit for bit
    assert s.sharp_outline and s.image_baked_outline  # (the panel compares them)
    s.sharp_outline = False
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert not s.image_baked_outline
    soft = stain_alpha(flag, s.image_frames[1])
    soft_width = edge_width(soft, texel)
    print(f"without Sharp Outline: edge width {soft_width * 1e3:.2f} mm; "
          f"dye total {alpha.sum() / soft.sum():.4f} of it")
    assert width < 0.6 * soft_width
    assert abs(alpha.sum() / soft.sum() - 1) < 0.02
    s.sharp_outline = True
    assert bpy.ops.madder.export_textures() == {"FINISHED"}
    assert np.array_equal(stain_alpha(flag, s.image_frames[1]), alpha)
    if width > 2 * pitch:
        # not met yet (issue 34): the edge is drawn within a texel, and Auto's texel is half
        # the Detail's 6.25 mm edge on the 2 m flag (512 px: 3.9 × 2.3 mm)
        pytest.xfail(f"10-90 % edge width {width * 1e3:.1f} mm > 2 thread pitches ({2 * pitch * 1e3:.1f} mm)")
