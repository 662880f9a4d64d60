"""The "Madder Stain" shader node group, the nodes that feed it, and the one-click
operator that adds them to an object's materials.

The group takes the material's Base Color, Roughness and Specular IOR Level and returns
them stained and wetted (and the film's coat, below), per colour channel (the maths runs
on scalar Math nodes, three times):

**Dye (Kubelka–Munk).** An opaque layer of absorption K and scattering S reflects
R∞ = 1 + K/S − √((K/S)² + 2·K/S), the inverse of K/S = (1 − R)²/2R (Kubelka & Munk
1931; Kubelka 1948); K/S of a mixture is the sum of its parts' K/S. So

    q_cloth = (1 − B)² / 2B                 B: the clean cloth's colour (Base Color)
    q_dye   = (1 − C)² / 2C                 C: the liquid's colour = Stain / min(Coverage, 1)
    q       = q_cloth + a·q_dye             a: the dye amount (Coverage + Excess)
    R_dry   = R∞(q)

with reflectances clamped to [1e-3, 1]. The dye amount counts all the dye, dissolved in
the liquid and bound to the fibres alike (the dye shows either way): it is the total
solute over the solute of fibres saturated with the liquid (`bridge.write_stain`), so
at a = 1 the cloth has the liquid's own colour (plus the cloth's), a thin stain is a
pale tint of the same hue and colour depth grows as K/S does, linearly with the dye. It
is not limited to 1: a tide line, where the drying flow carried the solute, holds two
to six times the dye of a saturated spot and is that much darker. The vertex attributes
carry the whole amount in Coverage; the images carry it up to 1 there (the weave's
detail is clipped at 1) and the rest in Excess (the wet image's blue × 16, core
`io::attributes`), which the group adds back.

**Water.** Wetness w (the liquid in the fibres over what they hold) changes the optics
three ways, each weighted by w so a dry cloth keeps R_dry exactly:

1. water replacing the air between the fibres lowers their scattering:
   q → q·(1 + s·w), s = "Wet Scattering" (0 by default: the film alone already gives
   the measured darkening);
2. the dry fibres' rough surfaces reflect a neutral ρ ("Surface White", 0.06) in every
   direction, which whitens every colour; a water film's smooth surface sends that
   reflection to the specular direction instead (the Principled BSDF's own specular),
   leaving the body's reflectance Rb = (R − ρ)/(1 − ρ);
3. light scattered back by the body reaches the film's surface and, beyond the critical
   angle, is totally internally reflected back to be absorbed again (Lekner & Dorf 1988,
   "Why some things are darker when wet", Appl. Opt. 27, 1278):
   R_film = Rb·(1 − r_i)/(1 − r_i·Rb), with r_i ("Film Reflection") = 1 − (1 − r_e)/n²
   ≈ 0.47 for water (n = 1.33, r_e ≈ 0.066 the diffuse external reflectance).

    R_wet = R + w·(R_film − R)              R = R∞(q·(1 + s·w))
    Base Color = min(Yarn · R_wet, 1)

Darker channels lose proportionally more (R_film/Rb = (1 − r_i)/(1 − r_i·Rb) is smallest
for small Rb) and the neutral ρ is gone, so wet colours are darker *and* more saturated;
the cloth's own colour and the stain's alike.

**The film's gloss** is a layer of its own: the group's Film output (w) is the Principled
BSDF's Coat Weight, with the film's roughness ("Wet Roughness", 0.1) as Coat Roughness and
water's index (1.33) as Coat IOR; the Coat Normal is the surface's own (the film is level
over the yarns, see `weave_shader`). The fibres under it keep their dry Roughness, and
their own surface reflection fades, Specular IOR Level · (1 − w): under the film a
fibre's surface faces water, and what it still reflects (about an eighth of what it did
in air: ((n_f − n_w)/(n_f + n_w))² over ((n_f − 1)/(n_f + 1))² for cellulose 1.55 and
water 1.33) stays under the film, part of the body's light that R_film counts. So the dry
surface's neutral white leaves with the fibres' sheen, and the one gloss left is the
film's. A partly wet cloth is a patchwork of smooth film and rough fibres: its gloss is
two lobes in proportion to w, not one lobe of intermediate roughness (which, halfway
dry, is broad enough to catch a sun near the mirror direction and whiten the stain, so
that a drying stain would look paler than the dry one).

Wet fabric also lets more light through (water fills the gaps between and inside
the yarns and matches the fibres' index, so less is scattered back): the group's
Translucency output, mix("Translucency", "Wet Translucency", w), is the factor of a Mix
Shader that `add_to_material` puts after the Principled BSDF, whose other shader is a
Transparent BSDF tinted by the stained colour, so what lies behind a wet cloth shows
through (Cycles and EEVEE alike; see `_ensure_transmission`).

**Yarn** is the weave's local reflectance factor (mean 1; 1 = no weave): it multiplies
the finished colour, clean cloth and stain alike, since the yarns carry both. The
weave's own node group (`weave_shader`) feeds it. The Deposit input (bound dye) does
not change the colour; it is passed through as an output for the material's own nodes.

**The outline** is drawn at the pixel. With Sharp Outline in the shader (the default
with images) the images carry the stain lifted to its plateau at the front and, in the
wet image's alpha, the front's signed distance D in metres (core `texture::outline`, "At
the pixel"); bilinear filtering reads D linearly, so the group places the front to a
fraction of a pixel, however coarse the texel:

    cover = clamp(½ + (D + n) / e, 0, 1)         e: Edge Width (the fabric's thread pitch)
    n     = Front Roughness · (fBm(p / Front Scale) − ½) / noise_rms(H)

and the dye amount (Coverage + Excess) is multiplied by `cover` (the liquid's colour,
their ratio, is not). `n` is Blender's Noise Texture (fBm, `FRONT_OCTAVES` octaves of
lacunarity 2 and gain 2^−H, H = `FRONT_HURST`) at the point `p` on the cloth in metres
(the UV times the layout's metres per UV along u and v): the front wanders from the
simulated outline by `n`, an RMS of Front Roughness (`noise_rms` calibrates the node's
spread: tests/blender/test_shading.py), self-affine from the Front Scale down to the
finest octave (40 mm / 2^10, the fibres'). Imbibition fronts in paper and fabric are
rough that way, at every scale from the fibres up (Buldyrev et al. 1992: a roughness
exponent about 0.63). H is 0.4, not 0.63: the drawn wander adds to the simulated
outline, whose own centimetre lobes (its curvature: a local exponent above 1 from 5 to
20 mm) dominate the sum above a few millimetres, and the flatter noise carries the
sum's exponent into the measured range. The outline the user renders on the flag
measures 0.71 between 1 and 20 mm (tests/blender/test_presets_look.py, the front's
height over its mean line); with H 0.63, above 0.8. A front 10–90 % over 0.8 e
is 0.3 mm on plain cotton.
Without the distance channel (vertex colours, or images written without it) the input's
default 1 m, or the image's alpha 1, leaves `cover` = 1: nothing is cut. The group's
Dye output is the dye amount after the cut.

`Stain`, `Coverage`, `Wetness` and `Deposit` are inputs of the group, fed in the
material by nodes that `sync_material` places (named "Madder Input: …"):

- *Vertex Colors*: Attribute nodes reading `madder_stain` (Color, Alpha),
  `madder_wetness` and `madder_deposit` (0 where an object has none, so the group is
  harmless on unbaked objects);
- *Image Sequence* (when the object has baked images and wants them): two Image Texture
  nodes on the object's sequences (`images.sequence_image`: non-colour, channel-packed
  alpha, auto refresh, frame start/offset/length so that scene frame f shows file f),
  read through a UV Map node of the UV map they were baked for; the wet image's R and G
  are the wetness and deposit, its B the dye's excess over saturation (× 16: Excess),
  its alpha the Outline Distance; the UV times the layout's metres per UV
  (`weave_shader.metres_per_uv_axes`) is the Outline Position, and the Edge Width
  follows a thread pitch of the material's fabric (or the default fabric's) until the
  user sets it (the value Madder wrote is kept on the node; a socket that differs from
  it is the user's and stays).

A bake, a re-export, Free Bake and switching the output re-run `sync_object`, so a
material that has the group always reads what its object has. A group made by an older
Madder (other sockets, or an older `REVISION` of the maths, kept as the group's custom
property `madder_revision`) is rebuilt in place: its sockets keep their identifiers (the material's links
stay), it gains the inputs it lacks and loses "Wet Darkening" and "Deposit Darkening"
(the old neutral darkening `1 − 0.35·w` and the bound dye's extra darkening, replaced by
the model above), and every material using it gets its input nodes and the Mix Shader
with the Transparent BSDF."""

import bpy

from . import compat, fabrics, images, stored, weave_shader
from .bridge import DEPOSIT_ATTR, STAIN_ATTR, WETNESS_ATTR

GROUP = "Madder Stain"
INPUT_PREFIX = "Madder Input: "
# the group node's custom property holding the Edge Width Madder last wrote (`_follow_fabric_pitch`)
EDGE_WIDTH_SET = "madder_edge_width"
SEE_THROUGH = "Madder See-Through"  # the material's Transparent BSDF and its Mix Shader
MIX = "Madder Wet Transmission"
# the front's roughness (module doc): fractal noise of Hurst exponent FRONT_HURST, an
# octave's amplitude 2^-H of the one before, FRONT_OCTAVES octaves below the Front Scale
FRONT_HURST = 0.4
FRONT_OCTAVES = 10
# RMS of one octave of Blender's Noise Texture about its mean ½ (its signed Perlin noise,
# halved as the normalized Fac is): 0.046 measured for the normalized sum at H 0.4 over 10⁶
# points of 10² and 40² periods, divided by that sum's factor (`noise_rms`) there, 0.389
OCTAVE_RMS = 0.118
# the group's inputs: name, socket type, default, range, tooltip
_INPUTS = (
    ("Base Color", "NodeSocketColor", (0.8, 0.8, 0.8, 1.0), None, "The clean, dry cloth's colour"),
    ("Roughness", "NodeSocketFloat", 0.5, (0.0, 1.0), "The dry cloth's roughness"),
    ("Specular", "NodeSocketFloat", 0.5, (0.0, 1.0),
     "The dry cloth's Specular IOR Level (its fibres' surface reflection, gone under the liquid's film)"),
    ("Wet Roughness", "NodeSocketFloat", 0.1, (0.0, 1.0),
     "Roughness of the liquid's film (the BSDF's coat, weighted by the wetness): the film is smooth"),
    ("Surface White", "NodeSocketFloat", 0.06, (0.0, 0.5),
     "Neutral reflectance of the dry fibres' surfaces, sent to the specular direction once a water film covers them"),
    ("Wet Scattering", "NodeSocketFloat", 0.0, (0.0, 10.0),
     "How much water in the fibres raises K/S (it replaces the air that scattered): K/S·(1 + this·wetness)"),
    ("Film Reflection", "NodeSocketFloat", 0.47, (0.0, 0.95),
     "Internal reflectance of the water film for diffuse light (Lekner & Dorf 1988; 0.47 for water)"),
    ("Translucency", "NodeSocketFloat", 0.0, (0.0, 1.0),
     "Fraction of the light the dry cloth lets through (0: opaque, and dry cloth costs no transparency rays)"),
    ("Wet Translucency", "NodeSocketFloat", 0.3, (0.0, 1.0), "Fraction the cloth transmits full of liquid"),
    ("Yarn", "NodeSocketFloat", 1.0, (0.0, 2.0),
     "The weave's local reflectance factor, mean 1; 1 = no weave"),
    ("Stain", "NodeSocketColor", (0.0, 0.0, 0.0, 1.0), None,
     "The liquid's colour times the coverage, the dye amount up to 1 (premultiplied)"),
    ("Coverage", "NodeSocketFloat", 0.0, (0.0, 17.0),
     "Dye amount: 1 = a spot saturated with the liquid (the images' part up to 1)"),
    ("Excess", "NodeSocketFloat", 0.0, (0.0, 16.0),
     "Dye amount above 1 that the images carry apart (0 with vertex colors, whose Coverage holds it all)"),
    ("Wetness", "NodeSocketFloat", 0.0, (0.0, 1.0), "Liquid in the fibres: 1 = full"),
    ("Deposit", "NodeSocketFloat", 0.0, (0.0, 1.0), "Bound dye (passed through as an output)"),
    ("Outline Distance", "NodeSocketFloat", 1.0, (-1.0, 1.0),
     "Signed distance (m) to the stain's front, positive behind it (the wet image's alpha with Sharp "
     "Outline in the shader); 1 m: no front near, nothing is cut"),
    ("Outline Position", "NodeSocketVector", (0.0, 0.0, 0.0), None,
     "The point on the cloth in metres (its UV times the layout's metres per UV): where the front's "
     "roughness is drawn"),
    ("Edge Width", "NodeSocketFloat", 0.0004, (0.0, 0.01),
     "Width (m) over which the front rises from dry to stained: a thread pitch (set from the "
     "material's fabric when the material is synced)"),
    ("Front Roughness", "NodeSocketFloat", 0.003, (0.0, 0.01),
     "How far (m, RMS) the front wanders from the simulated outline at the Front Scale; at every "
     f"scale below it, as that scale to the power {FRONT_HURST} (0: the simulated outline, sharp)"),
    ("Front Scale", "NodeSocketFloat", 0.04, (0.0001, 1.0),
     "The largest scale (m) of the front's own roughness (above it the simulation's outline)"),
)
_OUTPUTS = (("Base Color", "NodeSocketColor"), ("Roughness", "NodeSocketFloat"), ("Specular", "NodeSocketFloat"),
            ("Film", "NodeSocketFloat"), ("Film Roughness", "NodeSocketFloat"),
            ("Translucency", "NodeSocketFloat"), ("Deposit", "NodeSocketFloat"), ("Dye", "NodeSocketFloat"))
# defaults of an older Madder's group that this one changed (an upgrade moves a material's
# value still at the old default to the new one)
_OLD_DEFAULTS = {"Wet Roughness": 0.25}
# the group's maths, counted up when it changes (2: the liquid's colour recovered from
# Stain / min(Coverage, 1), as the attributes premultiply by the coverage, not the amount;
# 3: the front drawn at the pixel from Outline Distance)
REVISION = 3
# smallest reflectance the K/S maths sees (K/S = (1 − R)²/2R is infinite at R = 0)
R_MIN = 1e-3
# smallest dye amount the liquid's colour is recovered from (Stain / min(Coverage, 1))
A_MIN = 1e-4


def _sockets(group, in_out):
    return {s.name: s for s in group.interface.items_tree if s.item_type == "SOCKET" and s.in_out == in_out}


def _ensure_sockets(group):
    """Adds the sockets `group` lacks (existing ones keep their identifiers) and removes
    those an older Madder made that this model no longer has ("Wet Darkening", "Deposit
    Darkening"). Returns the names of the inputs it added."""
    names = {name for name, *_ in _INPUTS}
    for s in list(_sockets(group, "INPUT").values()):
        if s.name not in names:
            group.interface.remove(s)
    have, added = _sockets(group, "INPUT"), []
    for name, kind, default, bounds, tip in _INPUTS:
        s = have.get(name)
        if s is None:
            s = group.interface.new_socket(name, in_out="INPUT", socket_type=kind)
            added.append(name)
        s.default_value = default
        if bounds is not None:
            s.min_value, s.max_value = bounds
        s.description = tip
    have = _sockets(group, "OUTPUT")
    for name, kind in _OUTPUTS:
        if name not in have:
            group.interface.new_socket(name, in_out="OUTPUT", socket_type=kind)
    return added


class _Maths:
    """Scalar Math nodes in `nodes`, each call one node (inputs: sockets or numbers)."""

    def __init__(self, nodes, links):
        self.nodes, self.links, self.made = nodes, links, []

    def op(self, operation, *args, clamp=False):
        n = self.nodes.new("ShaderNodeMath")
        n.operation = operation
        n.use_clamp = clamp
        for i, a in enumerate(args):
            if isinstance(a, (int, float)):
                n.inputs[i].default_value = a
            else:
                self.links.new(a, n.inputs[i])
        self.made.append(n)
        return n.outputs[0]

    def ks(self, r):
        """K/S = (1 − R)² / 2R (Kubelka–Munk), R clamped to [R_MIN, 1]."""
        r = self.op("MINIMUM", self.op("MAXIMUM", r, R_MIN), 1.0)
        one_minus = self.op("SUBTRACT", 1.0, r)
        return self.op("DIVIDE", self.op("MULTIPLY", one_minus, one_minus), self.op("MULTIPLY", r, 2.0))

    def reflectance(self, q):
        """R∞ = 1 + K/S − √((K/S)² + 2·K/S), the inverse of `ks`."""
        root = self.op("SQRT", self.op("MULTIPLY_ADD", q, self.op("ADD", q, 2.0), 0.0))
        return self.op("SUBTRACT", self.op("ADD", q, 1.0), root)

    def mix(self, a, b, t):
        """a + t·(b − a)."""
        return self.op("MULTIPLY_ADD", t, self.op("SUBTRACT", b, a), a)


def noise_rms(hurst):
    """RMS of the front's Noise Texture about ½ at Hurst exponent `hurst`: its normalized
    fBm is Σ aᵢ nᵢ / Σ aᵢ over FRONT_OCTAVES + 1 octaves of amplitude aᵢ = 2^(−i·hurst),
    the octaves' noises nᵢ independent, each of RMS OCTAVE_RMS."""
    amplitudes = [2.0 ** (-i * hurst) for i in range(FRONT_OCTAVES + 1)]
    return OCTAVE_RMS * sum(a * a for a in amplitudes) ** 0.5 / sum(amplitudes)


def _front(m, nodes, links, g):
    """The front's cover at the point (module doc, "The outline"): clamp(½ + (D + n) / e),
    D the Outline Distance, n the fractal roughness at the Outline Position, e the Edge
    Width."""
    where = nodes.new("ShaderNodeVectorMath")
    where.operation = "SCALE"
    links.new(g.outputs["Outline Position"], where.inputs[0])
    links.new(m.op("DIVIDE", 1.0, m.op("MAXIMUM", g.outputs["Front Scale"], 1e-6)), where.inputs["Scale"])
    noise = nodes.new("ShaderNodeTexNoise")
    noise.noise_dimensions, noise.noise_type, noise.normalize = "3D", "FBM", True  # (Blender 4.1+)
    noise.inputs["Scale"].default_value = 1.0
    noise.inputs["Detail"].default_value = float(FRONT_OCTAVES)
    noise.inputs["Roughness"].default_value = 2.0 ** -FRONT_HURST
    noise.inputs["Lacunarity"].default_value = 2.0
    noise.inputs["Distortion"].default_value = 0.0
    links.new(where.outputs["Vector"], noise.inputs["Vector"])
    m.made += [where, noise]
    wander = m.op("MULTIPLY", m.op("SUBTRACT", noise.outputs["Fac"], 0.5),
                  m.op("DIVIDE", g.outputs["Front Roughness"], noise_rms(FRONT_HURST)))
    ahead = m.op("ADD", g.outputs["Outline Distance"], wander)
    return m.op("ADD", 0.5, m.op("DIVIDE", ahead, m.op("MAXIMUM", g.outputs["Edge Width"], 1e-6)), clamp=True)


def _channel(m, base, stain, g, cover):
    """One colour channel of the group's maths (module doc): `base` and `stain` the
    channel's sockets, `g` the group input node, `cover` the front's (`_front`)."""
    coverage = m.op("MAXIMUM", g.outputs["Coverage"], 0.0)
    # the liquid's colour: Stain is premultiplied by the coverage, the amount up to 1
    dye = m.op("DIVIDE", stain, m.op("MAXIMUM", m.op("MINIMUM", coverage, 1.0), A_MIN))
    amount = m.op("MULTIPLY", m.op("ADD", coverage, m.op("MAXIMUM", g.outputs["Excess"], 0.0)), cover)
    q = m.op("MULTIPLY_ADD", amount, m.ks(dye), m.ks(base))  # K/S, cloth + dye
    wet = g.outputs["Wetness"]
    q = m.op("MULTIPLY", q, m.op("MULTIPLY_ADD", g.outputs["Wet Scattering"], wet, 1.0))
    r = m.reflectance(q)
    white = g.outputs["Surface White"]  # the body under the dry surface's neutral reflection
    body = m.op("DIVIDE", m.op("SUBTRACT", r, white), m.op("SUBTRACT", 1.0, white), clamp=True)
    ri = g.outputs["Film Reflection"]  # Lekner & Dorf: B (1 − r_i) / (1 − r_i B)
    film = m.op("DIVIDE", m.op("MULTIPLY", body, m.op("SUBTRACT", 1.0, ri)),
                m.op("SUBTRACT", 1.0, m.op("MULTIPLY", ri, body)))
    r = m.mix(r, film, wet)
    return m.op("MINIMUM", m.op("MULTIPLY", r, g.outputs["Yarn"]), 1.0)


def _build(group):
    """The group's maths, from its inputs (see the module doc). Returns the names of the
    inputs it added to an existing group."""
    added = _ensure_sockets(group)
    group["madder_revision"] = REVISION
    nodes, links = group.nodes, group.links
    nodes.clear()
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    m = _Maths(nodes, links)
    split_base, split_stain = nodes.new("ShaderNodeSeparateColor"), nodes.new("ShaderNodeSeparateColor")
    links.new(gin.outputs["Base Color"], split_base.inputs[0])
    links.new(gin.outputs["Stain"], split_stain.inputs[0])
    join = nodes.new("ShaderNodeCombineColor")
    cover = _front(m, nodes, links, gin)
    for i in range(3):
        links.new(_channel(m, split_base.outputs[i], split_stain.outputs[i], gin, cover), join.inputs[i])
    dye = m.op("ADD", m.op("MAXIMUM", gin.outputs["Coverage"], 0.0), m.op("MAXIMUM", gin.outputs["Excess"], 0.0))
    links.new(m.op("MULTIPLY", dye, cover), gout.inputs["Dye"])
    links.new(join.outputs[0], gout.inputs["Base Color"])
    wet = gin.outputs["Wetness"]
    links.new(gin.outputs["Roughness"], gout.inputs["Roughness"])  # the fibres under the film
    # the fibres' surfaces under the film: Specular · (1 − w)
    links.new(m.op("MULTIPLY", gin.outputs["Specular"], m.op("SUBTRACT", 1.0, wet, clamp=True)),
              gout.inputs["Specular"])
    links.new(m.op("MAXIMUM", m.op("MINIMUM", wet, 1.0), 0.0), gout.inputs["Film"])
    links.new(gin.outputs["Wet Roughness"], gout.inputs["Film Roughness"])
    links.new(m.mix(gin.outputs["Translucency"], gin.outputs["Wet Translucency"], wet), gout.inputs["Translucency"])
    links.new(gin.outputs["Deposit"], gout.inputs["Deposit"])
    gin.location, split_base.location, split_stain.location = (-400, 0), (-200, 100), (-200, -100)
    for i, n in enumerate(m.made):
        n.location, n.hide = (40 * (i % 40), -40 * (i // 40) - 300), True
    join.location, gout.location = (1700, 0), (1900, 0)
    return added


def _current(group):
    return (group.get("madder_revision") == REVISION
            and set(_sockets(group, "INPUT")) == {name for name, *_ in _INPUTS}
            and set(_sockets(group, "OUTPUT")) >= {name for name, _ in _OUTPUTS})


def stain_group():
    """The node group, created once per file (and upgraded once, when an older Madder
    made it: see the module doc)."""
    group = bpy.data.node_groups.get(GROUP)
    if group is not None and _current(group):
        return group
    if group is None:
        group = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
        _build(group)
        return group
    added = _build(group)
    defaults = {name: default for name, _kind, default, *_ in _INPUTS}
    for mat in bpy.data.materials:  # an old group read the attributes itself, or had no transmission
        node = _group_node(mat)
        if node is not None:
            sync_material(mat, _owner(mat))
            _ensure_transmission(mat)
            for name in added:  # a socket added to a group leaves its nodes' values at 0
                node.inputs[name].default_value = defaults[name]
            _ensure_film(mat)  # (after: it routes the BSDF's own specular through the group)
            for name, value in _OLD_DEFAULTS.items():  # values nobody changed take the new default
                socket = node.inputs.get(name)
                if socket is not None and not socket.is_linked and abs(socket.default_value - value) < 1e-6:
                    socket.default_value = defaults[name]
    return group


def _group_node(material):
    nt = material.node_tree
    if nt is None:
        return None
    return next((n for n in nt.nodes if n.type == "GROUP" and n.node_tree and n.node_tree.name == GROUP), None)


def _owner(material):
    """A Madder object using `material` (the first), or None."""
    return next((o for o in bpy.data.objects if o.type == "MESH" and o.madder.enabled
                 and any(s.material == material for s in o.material_slots)), None)


def sync_material(material, obj):
    """Replaces the input nodes of the material's Madder Stain group by those `obj` needs
    (images when it has baked images and wants them, attributes otherwise; attributes for
    no object). Does nothing to a material without the group."""
    node = _group_node(material)
    if node is None:
        return False
    nt = material.node_tree
    kept_normal = weave_shader.user_normal(nt)
    for n in [n for n in nt.nodes if n.name.startswith(INPUT_PREFIX)]:
        nt.nodes.remove(n)
    x, y = node.location.x - 300, node.location.y
    if obj is not None and stored.uses_images(obj):
        _image_inputs(nt, node, obj, x, y, material)
    else:
        _attribute_inputs(nt, node, x, y)
    weave_shader.place(material, obj, node, INPUT_PREFIX, x, y, kept_normal)
    return True


def _new(nt, kind, name, x, y):
    n = nt.nodes.new(kind)
    n.name = n.label = INPUT_PREFIX + name
    n.location = (x, y)
    n.hide = True
    return n


def _attribute_inputs(nt, node, x, y):
    stain = _new(nt, "ShaderNodeAttribute", "Stain", x, y - 260)
    stain.attribute_name = STAIN_ATTR
    wet = _new(nt, "ShaderNodeAttribute", "Wetness", x, y - 300)
    wet.attribute_name = WETNESS_ATTR
    deposit = _new(nt, "ShaderNodeAttribute", "Deposit", x, y - 340)
    deposit.attribute_name = DEPOSIT_ATTR
    nt.links.new(stain.outputs["Color"], node.inputs["Stain"])
    nt.links.new(stain.outputs["Alpha"], node.inputs["Coverage"])
    nt.links.new(wet.outputs["Fac"], node.inputs["Wetness"])
    nt.links.new(deposit.outputs["Fac"], node.inputs["Deposit"])


def _image_inputs(nt, node, obj, x, y, material):
    import madder

    uv = _new(nt, "ShaderNodeUVMap", "UV Map", x - 500, y - 280)
    uv.uv_map = obj.madder.image_uv_map
    textures = {}
    for i, kind in enumerate(("stain", "wet")):
        tex = _new(nt, "ShaderNodeTexImage", f"{kind.capitalize()} Image", x - 250, y - 260 - 40 * i)
        tex.image = images.sequence_image(obj, kind)
        tex.interpolation = "Linear"
        tex.extension = "EXTEND"
        images.set_image_user(tex.image_user, obj)
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        textures[kind] = tex
    channels = _new(nt, "ShaderNodeSeparateColor", "Wetness and Deposit", x, y - 300)
    nt.links.new(textures["wet"].outputs["Color"], channels.inputs["Color"])
    excess = _new(nt, "ShaderNodeMath", "Excess", x, y - 340)
    excess.operation = "MULTIPLY"
    excess.inputs[1].default_value = madder.DYE_EXCESS_RANGE
    nt.links.new(channels.outputs["Blue"], excess.inputs[0])
    nt.links.new(textures["stain"].outputs["Color"], node.inputs["Stain"])
    nt.links.new(textures["stain"].outputs["Alpha"], node.inputs["Coverage"])
    nt.links.new(excess.outputs[0], node.inputs["Excess"])
    nt.links.new(channels.outputs["Red"], node.inputs["Wetness"])
    nt.links.new(channels.outputs["Green"], node.inputs["Deposit"])
    # the front's distance (a wet image without it reads alpha 1: 1 m, nothing cut) and
    # where the point lies on the cloth, in metres
    nt.links.new(textures["wet"].outputs["Alpha"], node.inputs["Outline Distance"])
    scales = weave_shader.metres_per_uv_axes(obj, obj.madder.image_uv_map or "")
    if scales is not None:
        metres = _new(nt, "ShaderNodeVectorMath", "Outline Position", x, y - 380)
        metres.operation = "MULTIPLY"
        metres.inputs[1].default_value = (scales[0], scales[1], 0.0)
        nt.links.new(uv.outputs["UV"], metres.inputs[0])
        nt.links.new(metres.outputs["Vector"], node.inputs["Outline Position"])
    _follow_fabric_pitch(node, material)


def _follow_fabric_pitch(node, material):
    """Sets the group node's Edge Width to a thread pitch of `material`'s fabric, unless the
    user has set it: the value Madder last wrote is kept on the node (`EDGE_WIDTH_SET`),
    and a socket that no longer holds it keeps the user's value through every sync."""
    socket = node.inputs["Edge Width"]
    written = node.get(EDGE_WIDTH_SET)
    if written is not None and socket.default_value != written:
        return
    socket.default_value = _thread_pitch(material)
    node[EDGE_WIDTH_SET] = socket.default_value  # as the socket holds it (single precision)


def _thread_pitch(material):
    """A thread pitch (m) of `material`'s Madder fabric, or of the default fabric (the one
    a cloth without a fabric is simulated with)."""
    from . import presets

    fab = getattr(material, "madder_fabric", None)
    count = fab.thread_count if fab is not None and fab.enabled and fab.thread_count > 0 else \
        presets.FABRIC_PRESETS[presets.DEFAULT_FABRIC]["thread_count"]
    return 0.01 / count


def sync_object(obj):
    """`sync_material` for each of `obj`'s materials that has the group; returns their names."""
    done = []
    for slot in obj.material_slots:
        mat = slot.material
        if mat is not None and mat.name not in done and sync_material(mat, obj):
            done.append(mat.name)
    return done


def add_to_material(material, obj=None):
    """Inserts the group in front of the material's Principled BSDF (Base Color, Roughness,
    Specular IOR Level; `THROUGH`), keeping whatever fed them, its input nodes for `obj`, and the wet cloth's
    transmission behind it (`_ensure_transmission`). Returns False when the group was
    already there (its inputs are synced again) or the material has no Principled BSDF."""
    nt = material.node_tree
    if nt is None:
        return False
    bsdf = _principled(material)
    if bsdf is None:
        return False
    group = stain_group()
    if _group_node(material) is not None:
        sync_material(material, obj)
        _ensure_transmission(material)
        _ensure_film(material)
        return False
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.name = node.label = GROUP
    node.location = (bsdf.location.x - 250, bsdf.location.y)
    for name, socket in THROUGH:
        _route(nt, bsdf, node, name, socket)
    sync_material(material, obj)
    _ensure_transmission(material)
    _ensure_film(material)
    return True


# the BSDF's inputs the group sits in front of: (group socket, BSDF socket)
THROUGH = (("Base Color", "Base Color"), ("Roughness", "Roughness"), ("Specular", "Specular IOR Level"))


def _route(nt, bsdf, node, name, socket):
    """Puts the group's `name` between the BSDF's input `socket` and whatever fed it (a
    link, or its value), unless the group feeds it already."""
    src = bsdf.inputs[socket]
    if src.is_linked:
        feed = src.links[0].from_socket
        if feed.node == node:
            return
        nt.links.new(feed, node.inputs[name])
    else:
        node.inputs[name].default_value = src.default_value
    nt.links.new(node.outputs[name], src)


def _principled(material):
    return next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


WATER_IOR = 1.33


def _ensure_film(material):
    """Makes the group's Film and Film Roughness the Principled BSDF's Coat Weight and Coat
    Roughness, with water's Coat IOR (the module doc: the liquid's film as a layer over
    the fibres), and routes the BSDF's Specular IOR Level through the group. Leaves a
    coat the material's own nodes drive alone; does nothing when the material has no
    group or no Principled BSDF. Returns True when it linked them."""
    nt, node = material.node_tree, _group_node(material)
    bsdf = _principled(material) if nt is not None else None
    if node is None or bsdf is None or "Film" not in node.outputs:
        return False
    _route(nt, bsdf, node, "Specular", "Specular IOR Level")  # a group from before the film had none
    weight = bsdf.inputs["Coat Weight"]
    if weight.is_linked:
        return False
    nt.links.new(node.outputs["Film"], weight)
    if not bsdf.inputs["Coat Roughness"].is_linked:
        nt.links.new(node.outputs["Film Roughness"], bsdf.inputs["Coat Roughness"])
    bsdf.inputs["Coat IOR"].default_value = WATER_IOR
    return True


def _ensure_transmission(material):
    """Makes the Principled BSDF's output pass through a Mix Shader (factor: the group's
    Translucency) with a Transparent BSDF tinted by the group's colour, wherever the BSDF
    fed (the Material Output, usually), so that a wet cloth shows what is behind it.
    Transparent rather than Translucent: EEVEE's Translucent BSDF is lit by lights alone,
    so a backing would not show through it; a Transparent BSDF shows it in Cycles and in
    EEVEE (its default Dithered render method) alike, and the light that reaches the
    backing through the cloth and comes back through it is Cycles' and EEVEE's own
    (transparent shadows). Does nothing when the material has them already, or has no
    Principled BSDF or group."""
    nt, node = material.node_tree, _group_node(material)
    bsdf = _principled(material) if nt is not None else None
    if node is None or bsdf is None or nt.nodes.get(MIX) is not None:
        return False
    out = compat.shader_output(bsdf)
    targets = [link.to_socket for link in out.links]
    through = nt.nodes.new("ShaderNodeBsdfTransparent")
    through.name = through.label = SEE_THROUGH
    through.location = (bsdf.location.x, bsdf.location.y - 700)
    nt.links.new(node.outputs["Base Color"], through.inputs["Color"])
    mix = nt.nodes.new("ShaderNodeMixShader")
    mix.name = mix.label = MIX
    mix.location = (bsdf.location.x + 300, bsdf.location.y)
    nt.links.new(node.outputs["Translucency"], mix.inputs[0])  # "Fac" (4.x) / "Factor" (5.x)
    nt.links.new(out, mix.inputs[1])
    nt.links.new(through.outputs[0], mix.inputs[2])
    for target in targets:
        nt.links.new(mix.outputs[0], target)
    return True


class MADDER_OT_add_stain_shader(bpy.types.Operator):
    """Add the Madder Stain node group (stained, wet and see-through cloth) to every material of the active object"""

    bl_idname = "madder.add_stain_shader"
    bl_label = "Add Stain Shader"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def execute(self, context):
        obj = context.object
        mats = [s.material for s in obj.material_slots if s.material is not None]
        if not mats:
            mat = bpy.data.materials.new(f"{obj.name} Cloth")
            compat.ensure_node_tree(mat)
            obj.data.materials.append(mat)
            mats = [mat]
        added = [m.name for m in mats if add_to_material(m, obj)]
        source = "its image sequence" if stored.uses_images(obj) else "its vertex colors"
        if added:
            self.report({"INFO"}, f"Madder: stain shader added to {', '.join(added)}, reading {source}")
        else:
            self.report({"INFO"}, f"Madder: the stain shader reads {source} (materials without a "
                        "Principled BSDF are left alone)")
        for mat in mats:
            # images are per object: a material shared with another stained object shows one of them
            other = next((o for o in bpy.data.objects if o != obj and o.type == "MESH" and o.madder.enabled
                          and (stored.uses_images(o) or stored.uses_images(obj))
                          and any(s.material == mat for s in o.material_slots)), None)
            if other is not None:
                self.report({"WARNING"}, f"Madder: material '{mat.name}' is shared with '{other.name}': its "
                            "stain inputs follow one object only; give each object its own material")
        return {"FINISHED"}


def _resync_material(material):
    """A fabric of `material` changed: its input nodes (the Madder Weave's) follow."""
    if _group_node(material) is not None:
        sync_material(material, _owner(material))


def register():
    bpy.utils.register_class(MADDER_OT_add_stain_shader)
    weave_shader.register()
    fabrics.resync_hooks.append(_resync_material)


def unregister():
    if _resync_material in fabrics.resync_hooks:
        fabrics.resync_hooks.remove(_resync_material)
    weave_shader.unregister()
    bpy.utils.unregister_class(MADDER_OT_add_stain_shader)
