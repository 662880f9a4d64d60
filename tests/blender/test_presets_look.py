"""What a new user gets (issue 34): the flag fixture baked with only the Red Wine preset
chosen (Madder Stain on, the Spill Group, the Liquid: nothing else). The look must be on
by default (an Auto Detail above 0, the image sequence written, the grain of the default
fabric, the preset's wicking), and the dried stain's outline must be sharp: its 10–90 %
edge width at most two thread pitches of the default fabric (plain cotton)."""

import os

import bpy
import numpy as np
import pytest
from conftest import make_active

from madder.addon import presets


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
    """Metres spanned by one UV unit: sqrt(rest area / UV area) (a uniform UV layout)."""
    mesh = flag.data
    area = sum(p.area for p in mesh.polygons) * abs(flag.matrix_world.to_3x3().determinant()) ** (2 / 3)
    uv = mesh.uv_layers.active.data
    uv_area = 0.0
    for p in mesh.polygons:
        pts = [uv[i].uv for i in p.loop_indices]
        uv_area += 0.5 * abs(sum(pts[i - 1].x * pts[i].y - pts[i].x * pts[i - 1].y for i in range(len(pts))))
    return float(np.sqrt(area / uv_area))


def boundary_length(mask):
    """Length of the boundary of a pixel mask in pixels: the pixel edges between inside
    and outside, times π/4 (the mean ratio of a staircase to the curve it follows)."""
    steps = np.count_nonzero(mask[1:] != mask[:-1]) + np.count_nonzero(mask[:, 1:] != mask[:, :-1])
    return steps * np.pi / 4


def edge_width(alpha, texel):
    """The 10–90 % edge width (m): the area between the 10 % and 90 % contours of the
    deposit (its plateau the 99th percentile of the stained texels) over the length of
    the 50 % contour."""
    top = np.percentile(alpha[alpha > 0.02 * alpha.max()], 99)
    a10, a90 = np.count_nonzero(alpha > 0.1 * top), np.count_nonzero(alpha > 0.9 * top)
    return (a10 - a90) / boundary_length(alpha > 0.5 * top) * texel


def roughness(alpha, texel, lengths):
    """Boundary roughness of the 50 % contour: the contour's pixels in polar coordinates
    about the stain's centroid, r(s) along the arc length s; w(l) the RMS of r about its
    mean over windows of arc length l, averaged over the windows."""
    top = np.percentile(alpha[alpha > 0.02 * alpha.max()], 99)
    inside = alpha > 0.5 * top
    edge = inside & ~(np.roll(inside, 1, 0) & np.roll(inside, -1, 0) & np.roll(inside, 1, 1) & np.roll(inside, -1, 1))
    y, x = np.nonzero(inside)
    cy, cx = y.mean(), x.mean()
    ey, ex = np.nonzero(edge)
    theta = np.arctan2(ey - cy, ex - cx)
    order = np.argsort(theta)
    r = np.hypot(ey - cy, ex - cx)[order] * texel
    s = theta[order] * r.mean()  # arc length about the mean radius
    w = []
    for ell in lengths:
        values = []
        for start in np.arange(s[0], s[-1] - ell, ell / 2):
            window = r[(s >= start) & (s < start + ell)]
            if len(window) >= 3:
                values.append(window.std())
        w.append(np.mean(values) if values else np.nan)
    return np.array(w)


def test_only_a_preset_gives_a_sharp_stain(open_fixture):
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
    from madder.addon import bake

    cotton = presets.FABRIC_PRESETS[presets.DEFAULT_FABRIC]
    kw = bake.simulator_settings(scene, flag)
    assert kw["irregularity"] == cotton["irregularity"] > 0
    assert kw["irregularity_length"] == pytest.approx(cotton["irregularity_length"] * 1e-3)
    # the dried stain's edge
    alpha = stain_alpha(flag, s.image_frames[1])
    texel = metres_per_uv(flag) / alpha.shape[0]
    width = edge_width(alpha, texel)
    pitch = 0.01 / cotton["thread_count"]
    lengths = np.geomspace(1e-3, 20e-3, 8)
    w = roughness(alpha, texel, lengths)
    ok = np.isfinite(w) & (w > 0)
    alpha_fit = np.polyfit(np.log(lengths[ok]), np.log(w[ok]), 1)[0] if ok.sum() >= 3 else float("nan")
    print(f"\nflag, Red Wine only: Detail {s.bake_detail}, {s.image_baked_size} px images "
          f"({texel * 1e3:.2f} mm texels), 10-90 % edge width {width * 1e3:.2f} mm "
          f"({width / pitch:.2f} thread pitches of {pitch * 1e3:.2f} mm); roughness w(l) "
          + ", ".join(f"{ell * 1e3:.1f} mm: {v * 1e3:.3f} mm" for ell, v in zip(lengths, w, strict=True))
          + f"; exponent {alpha_fit:.2f}")
    assert width <= 2 * pitch
