"""The "Madder Weave" shader node group: the material's Madder fabric drawn by the shader
over the whole cloth, clean or stained, filtered to the pixel at every distance.

# The pattern

The fabric's tile (`fabrics.tile_rows`: W/w warp up/down, F/f weft up/down, `.` gap) is a
`W × H` grid of cells, `c` cells a thread (2 for a built-in weave with gaps, 1 otherwise,
as `madder.fabric_corrector` counts them). Each cell gets a height profile `h(x, y)`:

    up yarn:   h = 1.00 · (0.35 + 0.65 √(1 − (2d)²))      d: offset across the yarn, in cells
    down yarn: h = 0.55 · (0.35 + 0.65 √(1 − (2d)²))      (−½ ≤ d ≤ ½; a warp yarn runs along
    gap:       h = 0                                       y, a weft yarn along x)

so a yarn's crown is highest, its edges and the yarns passing under are lower, the gaps
lowest. Its Fourier series over the tile (cell coordinates `y = (x, y)`)

    h(y) = h̄ + Σ_k 2 Re(ĥ_k e^{2πi (k_x x / W + k_y y / H)}),
    ĥ_k = ⟨h(y) e^{−2πi (k_x x / W + k_y y / H)}⟩_tile     (midpoint rule, 24 points a cell)

is cut to its `TERMS` strongest frequencies (a half plane: each with its conjugate) and
scaled so the largest excursion is `AMPLITUDE`:

    Yarn(y) = 1 + A Σ_k D_k (a_k cos φ_k + b_k sin φ_k),   φ_k = 2π (k_x x / W + k_y y / H).

Every term has an integer number of periods over the tile, so the mean of Yarn over a tile
is exactly 1 (what the stain group's "Yarn" input multiplies the cloth's colour by: the
weave redistributes light between crowns and gaps, it neither darkens nor lightens the
cloth on average). The same series, over `A`, is the bump's height (crowns raised).

The cloth's UV `u` is turned into thread coordinates as the image sequence's weave is
(`textures.weave_maps`): `t = n s R(−θ) u` with `n` threads per metre, `s` metres of rest
surface per UV unit (measured on the object when the material is synced: the median ratio
of world edge length to UV edge length) and `θ` the weft angle from the u axis; the tile
is anchored at UV (0, 0); cells are `c · t`. The bump's height is the same sum over `A`
(±1) times `RELIEF` thread pitches: a larger relief tilts the shading normals enough to
darken the close-up on average (0.15 pitch: 7 % under a uniform white world, ΔE00 1.7
against the wide shot; 0.05: ΔE00 0.25, tests/blender/test_weave_shader.py).

Where the cloth is wet the bump fades, its strength `1 − w` (`w` the stain group's Wetness,
fed to this node's Wetness input): the liquid fills the valleys between the yarns and its
free surface is level at the thread scale (surface tension flattens a film over a relief
far shorter than the capillary length, 2.7 mm for water, in well under a second). The
film's gloss is the BSDF's coat (`shading`), whose normal is the surface's own, not this
bump: a film that followed the relief would catch a sun on every yarn crown, a regular
grid of glints in a wet stain that the dry cloth beside it does not have
(tests/blender/test_weave_shader.py checks both against each other). The yarns' colour
(Yarn) stays: they are still there, under the film.

# With the image sequence

With the fabric's "Weave in Shader" on (the default) the Image Sequence is baked smooth
(`fabrics.face_weave` skips the fabric) and this node draws the weave on stained and clean
cloth alike: the images' own weave sampled the tile at the texel (1.3 threads a pixel in
the demo's wide shot) and aliased into a speckle, 11 % relative variation at 1 sample a
pixel on the test's flat stain without this filter, and showed yarns only where the stain
has a gradient. Off, the images carry the weave as before and no Weave node is placed.

# The filter

Shader nodes have no screen-space derivatives in Cycles, so the band limit is analytic. A
pixel seen at view distance `z` (Camera Data's View Distance) by a perspective camera of
pixel angle `α` (sensor / focal length / pixels along the fitted axis) covers `Δ = z α`
on a surface facing the camera (an orthographic camera: `Δ` = its pixel size), stretched
by `1 / |N·I|` where the surface is seen obliquely (bounded at 4×). In threads,
`F = Δ · unit · n / max(|N·I|, ¼)`. The pixel's filter is taken as a Gaussian of standard
deviation `σ = 0.6 F` (between a box pixel's `F/√12` and Cycles' default 1.5 px
Blackman–Harris), whose Fourier transform damps a term of frequency `f_k` (cycles a
thread) by

    D_k = exp(−2π² σ² f_k²).

A term whose period spans many pixels keeps its amplitude (`D → 1`: up close the yarns
show); where a thread spans a pixel or less, the plain weave's fundamental (half a cycle a
thread) keeps under 17 % of its amplitude and its harmonics nothing, so a uniform stain
far away is an even tone, the mean unchanged (the filter touches no mean).

`α` and the orthographic pixel size are inputs of each node, kept current from the
scene's active camera (lens, sensor and fit, resolution and its percentage) by handlers
on `render_pre`, `frame_change_pre` (a render runs both) and `load_post`, and when the
material is synced (`update_cameras`); a handler rather than a driver, since a driver
would name one camera object and the scene's active camera may change.

Measured (tests/blender/test_weave_shader.py, Cycles, 5 threads/cm, 64 px, 50 mm lens on
36 mm): wide (1.4 threads a pixel) the stain's relative variation is < 0.01 % (0.107
unfiltered at 1 sample a pixel); close (9 px a thread) 5.4 % stained and 5.5 % clean;
ΔE00 between the wide and close means 0.25 (stain) and 0.27 (clean); the rendered Yarn
averages 0.99998 over 4 × 4 tiles. EEVEE (16 samples), the same shots: wide 0.02 % and
0.01 %, close 4.6 % and 4.6 %, ΔE00 0.02 and 0.05."""

import math
import statistics

import bpy
import numpy as np
from bpy.app.handlers import persistent

GROUP = "Madder Weave"
NODE = "Weave"  # the node's name in a material, after shading.INPUT_PREFIX
TERMS = 10
AMPLITUDE = 0.12
SIGMA = 0.6  # the pixel filter's standard deviation, in pixel footprints
RELIEF = 0.05  # the bump's height at Relief 1, in thread pitches
MIN_COSINE = 0.25
SAMPLES = 24  # midpoint rule, per cell and axis
VERSION = 2  # of the group's layout: a group built by an older Madder is rebuilt (2: Wetness levels the bump)

_INPUTS = (
    ("UV", "NodeSocketVector", (0.0, 0.0, 0.0)),
    ("Threads per UV", "NodeSocketFloat", 0.0),
    ("Threads per Metre", "NodeSocketFloat", 0.0),
    ("Weft Angle", "NodeSocketFloat", 0.0),
    ("Pixel Angle", "NodeSocketFloat", 0.0),
    ("Pixel Size", "NodeSocketFloat", 0.0),
    ("Unit", "NodeSocketFloat", 1.0),
    ("Relief", "NodeSocketFloat", 1.0),
    ("Wetness", "NodeSocketFloat", 0.0),
)
_OUTPUTS = (("Yarn", "NodeSocketFloat"), ("Normal", "NodeSocketVector"), ("Height", "NodeSocketFloat"))


def cells_per_thread(fabric):
    """Cells a thread takes in the fabric's tile (as `madder.fabric_corrector` counts)."""
    return 2 if fabric.weave != "CUSTOM" and fabric.gaps else 1


def height_field(rows, samples=SAMPLES):
    """The tile's height profile (module doc) at the midpoints of `samples²` points a cell:
    an (H·samples, W·samples) array, row 0 at cell row 0 (the tile's bottom row; `rows` is
    top row first)."""
    rows = list(rows)
    if not rows or any(len(r) != len(rows[0]) for r in rows):
        raise ValueError(f"the weave's tile is not a rectangle: {rows!r}")
    d = (np.arange(samples) + 0.5) / samples - 0.5
    profile = 0.35 + 0.65 * np.sqrt(np.clip(1.0 - (2.0 * d) ** 2, 0.0, None))
    cells = {}
    for level, up in ((1.0, True), (0.55, False)):
        across_x = np.tile(level * profile, (samples, 1))  # a warp yarn runs along y: varies with x
        cells["W" if up else "w"] = across_x
        cells["F" if up else "f"] = across_x.T
    cells["."] = np.zeros((samples, samples))
    out = []
    for r in reversed(rows):
        try:
            out.append(np.hstack([cells[ch] for ch in r]))
        except KeyError as e:
            raise ValueError(f"the weave's tile has an unknown cell {e.args[0]!r}") from None
    return np.vstack(out)


def series(rows, terms=TERMS, amplitude=AMPLITUDE, samples=SAMPLES):
    """The truncated Fourier series of the tile's height (module doc): a list of
    `(kx, ky, a, b)`, the term `a cos φ + b sin φ` with `φ = 2π (kx x / W + ky y / H)`,
    scaled so the largest excursion of the sum over the tile is `amplitude`."""
    h = height_field(rows, samples)
    ny, nx = h.shape
    H, W = ny // samples, nx // samples
    c = np.fft.fft2(h) / h.size
    y = (np.arange(ny) + 0.5) / samples
    x = (np.arange(nx) + 0.5) / samples
    found = []
    for ky in range(-(H * samples // 2) + 1, H * samples // 2):
        for kx in range(0, W * samples // 2):
            if kx == 0 and ky <= 0:
                continue  # the mean, and the other half of the plane (conjugates)
            ck = c[ky % ny, kx]
            if abs(ck) < 1e-12:
                continue
            found.append((abs(ck), kx, ky, ck))
    found.sort(key=lambda t: (-t[0], t[1], t[2]))
    picked = []
    for _, kx, ky, ck in found[:terms]:
        # fft2's samples sit at cell offsets (i + ½)/samples: shift the phase back to the origin
        shift = np.exp(-2j * np.pi * (kx * 0.5 / nx + ky * 0.5 / ny))
        ck = ck * shift
        picked.append((kx, ky, 2.0 * ck.real, -2.0 * ck.imag))
    if not picked:
        raise ValueError(f"the weave's tile is uniform, it has no pattern: {rows!r}")
    X, Y = np.meshgrid(x, y)
    total = sum(a * np.cos(2 * np.pi * (kx * X / W + ky * Y / H)) + b * np.sin(2 * np.pi * (kx * X / W + ky * Y / H))
                for kx, ky, a, b in picked)
    scale = amplitude / np.abs(total).max()
    return W, H, [(kx, ky, a * scale, b * scale) for kx, ky, a, b in picked]


def evaluate(rows, cpt, t, footprint=0.0):
    """Yarn at thread coordinates `t` (…, 2) for a pixel footprint of `footprint` threads:
    the group's maths in numpy (for tests and the docs)."""
    W, H, terms = series(rows)
    t = np.asarray(t, dtype=np.float64)
    x, y = cpt * t[..., 0], cpt * t[..., 1]
    out = np.ones(x.shape)
    for kx, ky, a, b in terms:
        f2 = (kx * cpt / W) ** 2 + (ky * cpt / H) ** 2
        d = math.exp(-2 * math.pi ** 2 * (SIGMA * footprint) ** 2 * f2)
        phi = 2 * np.pi * (kx * x / W + ky * y / H)
        out += d * (a * np.cos(phi) + b * np.sin(phi))
    return out


# --- the node group ------------------------------------------------------------------------


def _math(nodes, op, a=None, b=None, links=None, x=0, y=0):
    n = nodes.new("ShaderNodeMath")
    n.operation = op
    n.location = (x, y)
    for i, v in enumerate((a, b)):
        if v is None:
            continue
        if isinstance(v, (int, float)):
            n.inputs[i].default_value = float(v)
        else:
            links.new(v, n.inputs[i])
    return n.outputs[0]


def _vmath(nodes, op, a, b, links, x=0, y=0):
    n = nodes.new("ShaderNodeVectorMath")
    n.operation = op
    n.location = (x, y)
    for i, v in enumerate((a, b)):
        if v is None:
            continue
        if isinstance(v, tuple):
            n.inputs[i].default_value = v
        else:
            links.new(v, n.inputs[i])
    return n


def group_name(fabric):
    key = f"CUSTOM {fabric.grid}" if fabric.weave == "CUSTOM" else f"{fabric.weave}{' gaps' if fabric.gaps else ''}"
    return f"{GROUP} ({key})"


def build(group, rows, cpt):
    """(Re)builds `group`'s nodes for the tile `rows` at `cpt` cells a thread."""
    W, H, terms = series(rows)
    have_in = {s.name for s in group.interface.items_tree if s.item_type == "SOCKET" and s.in_out == "INPUT"}
    have_out = {s.name for s in group.interface.items_tree if s.item_type == "SOCKET" and s.in_out == "OUTPUT"}
    for name, kind, default in _INPUTS:
        if name not in have_in:
            s = group.interface.new_socket(name, in_out="INPUT", socket_type=kind)
            s.default_value = default
            if name == "UV":
                s.hide_value = True
    for name, kind in _OUTPUTS:
        if name not in have_out:
            group.interface.new_socket(name, in_out="OUTPUT", socket_type=kind)
    group["madder_rows"] = "/".join(rows)
    group["madder_cpt"] = cpt
    group["madder_version"] = VERSION
    nodes, links = group.nodes, group.links
    nodes.clear()
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1200, 0), (1800, 0)
    # cells: c · n s R(−θ) u
    rot = nodes.new("ShaderNodeVectorRotate")
    rot.rotation_type = "Z_AXIS"
    rot.invert = True
    rot.location = (-1000, 200)
    links.new(gin.outputs["UV"], rot.inputs["Vector"])
    links.new(gin.outputs["Weft Angle"], rot.inputs["Angle"])
    k = _math(nodes, "MULTIPLY", gin.outputs["Threads per UV"], float(cpt), links, -1000, 0)
    cells = _vmath(nodes, "SCALE", rot.outputs["Vector"], None, links, -800, 200)
    links.new(rot.outputs["Vector"], cells.inputs[0])
    links.new(k, cells.inputs["Scale"])
    # footprint in threads: (z α + pixel size) · unit · n / max(|N·I|, ¼); s = (σ F)²
    cam = nodes.new("ShaderNodeCameraData")
    geo = nodes.new("ShaderNodeNewGeometry")
    cam.location, geo.location = (-1000, -300), (-1000, -500)
    pix = _math(nodes, "MULTIPLY_ADD", cam.outputs["View Distance"], gin.outputs["Pixel Angle"], links, -800, -300)
    links.new(gin.outputs["Pixel Size"], pix.node.inputs[2])
    ni = _vmath(nodes, "DOT_PRODUCT", geo.outputs["Normal"], geo.outputs["Incoming"], links, -800, -500)
    cosine = _math(nodes, "ABSOLUTE", ni.outputs["Value"], None, links, -600, -500)
    cosine = _math(nodes, "MAXIMUM", cosine, MIN_COSINE, links, -400, -500)
    f = _math(nodes, "MULTIPLY", pix, gin.outputs["Unit"], links, -600, -300)
    f = _math(nodes, "MULTIPLY", f, gin.outputs["Threads per Metre"], links, -400, -300)
    f = _math(nodes, "DIVIDE", f, cosine, links, -200, -300)
    f = _math(nodes, "MULTIPLY", f, SIGMA, links, 0, -300)
    s = _math(nodes, "POWER", f, 2.0, links, 200, -300)
    total = None
    for i, (kx, ky, a, b) in enumerate(terms):
        y0 = 600 - 220 * i
        w = (2 * math.pi * kx / W, 2 * math.pi * ky / H, 0.0)
        phase = _vmath(nodes, "DOT_PRODUCT", cells.outputs["Vector"], w, links, 0, y0).outputs["Value"]
        cos = _math(nodes, "COSINE", phase, None, links, 200, y0)
        sin = _math(nodes, "SINE", phase, None, links, 200, y0 - 60)
        sb = _math(nodes, "MULTIPLY", sin, b, links, 400, y0 - 60)
        term = _math(nodes, "MULTIPLY_ADD", cos, a, links, 600, y0)
        links.new(sb, term.node.inputs[2])
        f2 = (kx * cpt / W) ** 2 + (ky * cpt / H) ** 2  # cycles a thread, squared
        damp = _math(nodes, "MULTIPLY", s, -2 * math.pi ** 2 * f2, links, 800, y0)
        damp = _math(nodes, "EXPONENT", damp, None, links, 1000, y0)
        term = _math(nodes, "MULTIPLY", term, damp, links, 1200, y0)
        total = term if total is None else _math(nodes, "ADD", total, term, links, 1400, y0)
    yarn = _math(nodes, "ADD", total, 1.0, links, 1600, 200)
    links.new(yarn, gout.inputs["Yarn"])
    height = _math(nodes, "DIVIDE", total, AMPLITUDE, links, 1600, 0)
    links.new(height, gout.inputs["Height"])
    # bump: height ±1 over RELIEF · Relief thread pitches (pitch in Blender units: 1 / (n · unit))
    pitch = _math(nodes, "MULTIPLY", gin.outputs["Threads per Metre"], gin.outputs["Unit"], links, 1400, -300)
    pitch = _math(nodes, "DIVIDE", RELIEF, pitch, links, 1500, -300)
    pitch = _math(nodes, "MULTIPLY", pitch, gin.outputs["Relief"], links, 1600, -300)
    bump = nodes.new("ShaderNodeBump")
    bump.location = (1600, -100)
    # the film levels the relief: strength 1 − clamp(Wetness)
    level = _math(nodes, "SUBTRACT", 1.0, gin.outputs["Wetness"], links, 1400, -500)
    level.node.use_clamp = True
    links.new(level, bump.inputs["Strength"])
    links.new(pitch, bump.inputs["Distance"])
    links.new(height, bump.inputs["Height"])
    links.new(bump.outputs["Normal"], gout.inputs["Normal"])
    return group


def weave_group(fabric):
    """The node group drawing `fabric`'s tile, built once per tile (and rebuilt when the
    tile it was built for changed)."""
    from . import fabrics

    rows = list(fabrics.tile_rows(fabric))
    cpt = cells_per_thread(fabric)
    name = group_name(fabric)
    group = bpy.data.node_groups.get(name)
    if (group is not None and group.get("madder_rows") == "/".join(rows) and group.get("madder_cpt") == cpt
            and group.get("madder_version") == VERSION):
        return group
    if group is None:
        group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    return build(group, rows, cpt)


def _rest_uv(obj, uv_name):
    """`obj`'s corners on UV map `uv_name` (the active render map when empty: what a UV
    Map node without a name reads): `(uv (L, 2), world positions of the corners' vertices
    (L, 3), each polygon's loop start and loop total)`, or None without the map or loops."""
    mesh = obj.data
    if uv_name:
        layer = mesh.uv_layers.get(uv_name)
    else:
        layer = next((u for u in mesh.uv_layers if u.active_render), mesh.uv_layers.active)
    if layer is None or not mesh.loops:
        return None
    n = len(mesh.loops)
    uv = np.empty(2 * n)
    layer.data.foreach_get("uv", uv)
    vi = np.empty(n, dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", vi)
    co = np.empty(3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ np.array(obj.matrix_world)[:3, :3].T
    start = np.empty(len(mesh.polygons), dtype=np.int64)
    total = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("loop_start", start)
    mesh.polygons.foreach_get("loop_total", total)
    return uv.reshape(-1, 2), co[vi], start, total


def metres_per_uv(obj, uv_name=""):
    """Metres of rest surface per UV unit of `obj`: the median over its edges (of non-zero
    UV length) of world edge length / UV edge length, on UV map `uv_name` (the active
    render map when empty). None when no edge has a UV length."""
    corners = _rest_uv(obj, uv_name)
    if corners is None:
        return None
    uv, co, start, total = corners
    # each polygon's corner i to corner i+1
    a = np.arange(len(uv))
    poly = np.repeat(np.arange(len(start)), total)
    b = start[poly] + (a - start[poly] + 1) % total[poly]
    duv = np.linalg.norm(uv[b] - uv[a], axis=1)
    dco = np.linalg.norm(co[b] - co[a], axis=1)
    ok = duv > 1e-9
    if not ok.any():
        return None
    return statistics.median((dco[ok] / duv[ok]).tolist()) * bpy.context.scene.unit_settings.scale_length


def metres_per_uv_axes(obj, uv_name=""):
    """Metres of rest surface per UV unit of `obj` along u and along v, `(s_u, s_v)`: the
    medians over its polygons of the lengths of the rest pose's Jacobian columns dX/du and
    dX/dv, from each polygon's first three corners (a layout that maps a 2 × 1.2 m cloth
    onto the unit square stretches the two axes differently; `metres_per_uv` is their
    one-number summary). On UV map `uv_name` (the active render map when empty); None when
    no polygon has UV area."""
    corners = _rest_uv(obj, uv_name)
    if corners is None:
        return None
    uv, co, start, _ = corners
    first = start[:, None] + np.arange(3)
    duv = uv[first[:, 1:]] - uv[first[:, :1]]  # (P, 2 edges, 2)
    dx = co[first[:, 1:]] - co[first[:, :1]]  # (P, 2 edges, 3)
    det = duv[:, 0, 0] * duv[:, 1, 1] - duv[:, 0, 1] * duv[:, 1, 0]
    ok = np.abs(det) > 1e-12
    if not ok.any():
        return None
    jac = np.linalg.solve(duv[ok], dx[ok])  # rows: dX/du, dX/dv
    unit = bpy.context.scene.unit_settings.scale_length
    return tuple(float(np.median(np.linalg.norm(jac[:, k], axis=1))) * unit for k in range(2))


def camera_pixel(scene):
    """`(pixel angle in radians, orthographic pixel size in Blender units)` of the scene's
    active camera at its render resolution; (0, 0) without a camera (no filtering)."""
    cam = scene.camera
    if cam is None or cam.type != "CAMERA":
        return 0.0, 0.0
    c, r = cam.data, scene.render
    pct = r.resolution_percentage / 100.0
    rx, ry = r.resolution_x * pct * r.pixel_aspect_x, r.resolution_y * pct * r.pixel_aspect_y
    fit = c.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if rx >= ry else "VERTICAL"
    pixels = rx if fit == "HORIZONTAL" else ry
    scale = max(abs(s) for s in cam.matrix_world.to_scale())
    if c.type == "ORTHO":
        return 0.0, c.ortho_scale * scale / max(rx, ry) if c.sensor_fit == "AUTO" else c.ortho_scale * scale / pixels
    sensor = c.sensor_width if fit == "HORIZONTAL" or c.sensor_fit == "AUTO" else c.sensor_height
    return 2.0 * math.atan(0.5 * sensor / c.lens) / pixels, 0.0


def _weave_nodes():
    for mat in bpy.data.materials:
        nt = mat.node_tree
        if nt is None:
            continue
        for n in nt.nodes:
            if n.type == "GROUP" and n.node_tree is not None and n.node_tree.name.startswith(GROUP):
                yield n


def update_cameras(scene):
    """Sets every Madder Weave node's Pixel Angle, Pixel Size and Unit from `scene`'s camera
    (only where they changed: a write re-evaluates the material)."""
    angle, size = camera_pixel(scene)
    unit = scene.unit_settings.scale_length
    for n in _weave_nodes():
        for name, v in (("Pixel Angle", angle), ("Pixel Size", size), ("Unit", unit)):
            if abs(n.inputs[name].default_value - v) > 1e-9 * max(abs(v), 1e-12):
                n.inputs[name].default_value = v


@persistent
def _on_frame(scene, *_):
    update_cameras(scene)


@persistent
def _on_load(*_):
    if bpy.context.scene is not None:
        update_cameras(bpy.context.scene)


_HANDLERS = (("render_pre", _on_frame), ("frame_change_pre", _on_frame), ("load_post", _on_load))


def user_normal(nt):
    """The socket feeding the Principled BSDF's Normal when it is not Madder's weave (the
    weave then leaves the material's own normal alone), else None."""
    bsdf = next((n for n in nt.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None or not bsdf.inputs["Normal"].is_linked:
        return None
    src = bsdf.inputs["Normal"].links[0].from_node
    return None if src.type == "GROUP" and src.node_tree and src.node_tree.name.startswith(GROUP) else src


def place(material, obj, stain_node, prefix, x, y, kept_normal):
    """Adds the material's Madder Weave node (named `prefix` + "Weave") when `material` has
    an enabled Madder fabric with a Thread Count and `obj` (its owner) is known: UV from the
    map the images use (or the active one), threads per UV from the object's surface, its
    Yarn into the stain group's "Yarn" and its Normal into the BSDF's Normal (unless
    `kept_normal`, a node of the user's, feeds it). Returns the node or None."""
    # no owner, or a material without Madder's fabric (its classes not registered): no weave
    fab = getattr(material, "madder_fabric", None) if obj is not None else None
    if fab is None or not fab.enabled or fab.thread_count <= 0.0 or not getattr(fab, "shader_weave", True):
        return None
    uv_name = obj.madder.image_uv_map or ""
    s = metres_per_uv(obj, uv_name)
    if s is None:
        return None
    try:
        group = weave_group(fab)
    except Exception as e:  # an invalid custom grid: the fabric panel names the problem
        print(f"Madder: material '{material.name}': no weave in the shader: {e}")
        return None
    nt = material.node_tree
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.name = node.label = prefix + NODE
    node.location = (x - 250, y - 420)
    node.hide = True
    uv = nt.nodes.new("ShaderNodeUVMap")
    uv.name = uv.label = prefix + "Weave UV"
    uv.uv_map = uv_name
    uv.location = (x - 450, y - 420)
    uv.hide = True
    nt.links.new(uv.outputs["UV"], node.inputs["UV"])
    n = 100.0 * fab.thread_count
    node.inputs["Threads per Metre"].default_value = n
    node.inputs["Threads per UV"].default_value = n * s
    node.inputs["Weft Angle"].default_value = fab.angle
    scene = bpy.context.scene
    angle, size = camera_pixel(scene)
    node.inputs["Pixel Angle"].default_value = angle
    node.inputs["Pixel Size"].default_value = size
    node.inputs["Unit"].default_value = scene.unit_settings.scale_length
    if "Yarn" in stain_node.inputs:
        nt.links.new(node.outputs["Yarn"], stain_node.inputs["Yarn"])
    wet = stain_node.inputs.get("Wetness")
    if wet is not None and wet.is_linked:
        nt.links.new(wet.links[0].from_socket, node.inputs["Wetness"])
    bsdf = next((b for b in nt.nodes if b.type == "BSDF_PRINCIPLED"), None)
    if bsdf is not None and kept_normal is None:
        nt.links.new(node.outputs["Normal"], bsdf.inputs["Normal"])
    return node


def register():
    for name, fn in _HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn not in lst:
            lst.append(fn)


def unregister():
    for name, fn in _HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn in lst:
            lst.remove(fn)
