"""`demo.py --measure`: issue 35's checks on the demo itself, after its two renders.

1. **The shader's cost.** The wide frame rendered again with the cloth's materials
   swapped for plain Principled BSDFs of the cloth's own colour and roughness (no
   Madder nodes), timed against the render with them.
2. **Wide and close agree.** Points of the tablecloth on the table top, in the stain's
   uniform core (coverage above 90 % of its peak, seen in both shots) and on clean cloth
   around it (coverage below 0.1 %, within 25 cm of the spill), are projected into the
   wide picture and the close-up; the mean colour of each set, read from the pictures
   (display sRGB → CIE L*a*b*, D65), compared by CIEDE2000 (the formulas are
   tests/blender/test_weave_shader.py's, loaded from there).
3. **No speckle far away.** In the wide shot a thread of the 5/cm linen spans less than a
   pixel; the ratio of the wide render with the weave to the one without it (the same
   seed) at the stain's points is the weave's own contribution there: its relative
   spread is the variation the weave adds inside the stain.
4. **The yarns in both.** In the close-up, the weave's modulation in the stain and on the
   clean cloth: the relative spread of the same ratio (with / without the weave) at each
   set's pixels.

Prints the figures; asserts nothing (the checks with thresholds are the Blender tests)."""

import os
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def _colour_science():
    path = os.path.join(HERE, "..", "tests", "blender", "test_weave_shader.py")
    src = open(path).read()
    # the pure-numpy half of the test module (its colour science), without its bpy imports
    start, end = src.index("def srgb_encode"), src.index("# --- the scene")
    ns = {"np": np, "math": __import__("math")}
    exec(compile(src[start:end], path, "exec"), ns)
    return ns["lab"], ns["ciede2000"]


def _load(bpy, path):
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[..., :3]
    bpy.data.images.remove(img)
    return px


def _decode(v):
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _points(bpy, cloth, table_height, centre):
    """World positions of (core, clean) points of the evaluated cloth on the table top."""
    dg = bpy.context.evaluated_depsgraph_get()
    mesh = cloth.evaluated_get(dg).data
    n = len(mesh.vertices)
    co = np.empty(3 * n)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(n, 3) @ np.array(cloth.matrix_world.to_3x3()).T + np.array(cloth.matrix_world.translation)
    rgba = np.empty(4 * n)
    mesh.attributes["madder_stain"].data.foreach_get("color", rgba)
    cov = rgba[3::4]
    top = (co[:, 2] > table_height - 0.002) & (np.linalg.norm(co[:, :2] - np.array(centre[:2]), axis=1) < 0.25)
    core = top & (cov > 0.9 * cov[top].max())
    clean = top & (cov < 1e-3)
    return co[core], co[clean]


def _project(bpy, scene, pts, shape):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    h, w = shape[:2]
    out = []
    for p in pts:
        v = world_to_camera_view(scene, scene.camera, Vector(p))
        if 0.0 <= v.x < 1.0 and 0.0 <= v.y < 1.0 and v.z > 0.0:
            out.append((int(v.y * h), int(v.x * w)))
    return np.array(out, dtype=int).reshape(-1, 2)


def _plain_materials(bpy, cloth):
    """Per slot, a Principled BSDF of the cloth's own colour and roughness: the material
    without the Madder nodes."""
    plain = []
    for slot in cloth.material_slots:
        group = next(n for n in slot.material.node_tree.nodes if n.type == "GROUP"
                     and n.node_tree.name.startswith("Madder Stain"))
        mat = bpy.data.materials.new(slot.material.name + " (no Madder)")
        if mat.node_tree is None:
            mat.use_nodes = True
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        for name in ("Base Color", "Roughness"):
            bsdf.inputs[name].default_value = group.inputs[name].default_value
        plain.append(mat)
    return plain


def _cut_weave(cloth):
    """Removes the links out of the Madder Weave nodes; returns them (from, to) to restore."""
    cut = []
    for slot in cloth.material_slots:
        nt = slot.material.node_tree
        for node in nt.nodes:
            if node.type == "GROUP" and node.node_tree and node.node_tree.name.startswith("Madder Weave"):
                for out in node.outputs:
                    for link in list(out.links):
                        cut.append((nt, out, link.to_socket))
                        nt.links.remove(link)
    return cut


def run(scene, cloth, wide_pose, close_pose, out, table_height, centre):
    """The measurements (module doc). `wide_pose`/`close_pose`: (matrix_world, lens) of the
    camera for the two shots; `out`: the wide picture's path (the close-up's beside it)."""
    import bpy

    lab, ciede2000 = _colour_science()
    cam = scene.camera
    work = os.path.splitext(out)[0] + "-measure"
    os.makedirs(work, exist_ok=True)
    scene.cycles.seed = 0

    def shot(pose, name, variant=None):
        cam.matrix_world, cam.data.lens = pose[0], pose[1]
        saved = [slot.material for slot in cloth.material_slots]
        cut = []
        if variant == "plain":
            for slot, mat in zip(cloth.material_slots, _plain_materials(bpy, cloth), strict=True):
                slot.material = mat
        elif variant == "no weave":
            cut = _cut_weave(cloth)
        scene.render.filepath = os.path.join(work, name + ".png")
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        dt = time.perf_counter() - t0
        for slot, mat in zip(cloth.material_slots, saved, strict=True):
            slot.material = mat
        for nt, a, b in cut:
            nt.links.new(a, b)
        return _load(bpy, scene.render.filepath), dt

    core, clean = _points(bpy, cloth, table_height, centre)
    wide, t_full = shot(wide_pose, "wide")
    _, t_plain = shot(wide_pose, "wide-no-madder-shader", "plain")
    wide_noweave, _ = shot(wide_pose, "wide-no-weave", "no weave")
    close, _ = shot(close_pose, "close")
    close_noweave, _ = shot(close_pose, "close-no-weave", "no weave")
    print(f"demo measure: the wide frame renders in {t_full:.1f} s with the Madder shader, {t_plain:.1f} s with "
          f"its nodes muted (+{100 * (t_full / t_plain - 1):.0f} %)")

    cam.matrix_world, cam.data.lens = wide_pose
    wide_px = {k: _project(bpy, scene, pts, wide.shape) for k, pts in (("stain", core), ("clean", clean))}
    cam.matrix_world, cam.data.lens = close_pose
    close_px = {k: _project(bpy, scene, pts, close.shape) for k, pts in (("stain", core), ("clean", clean))}
    for kind in ("stain", "clean"):
        a, b = wide_px[kind], close_px[kind]
        if len(a) == 0 or len(b) == 0:
            print(f"demo measure: no {kind} points in view (wide {len(a)}, close {len(b)})")
            continue
        far = _decode(wide[a[:, 0], a[:, 1]]).mean(axis=0)
        near = _decode(close[b[:, 0], b[:, 1]]).mean(axis=0)
        de = ciede2000(lab(far), lab(near))
        ratio_w = wide[a[:, 0], a[:, 1]].mean(axis=1) / np.maximum(wide_noweave[a[:, 0], a[:, 1]].mean(axis=1), 1e-6)
        ratio_c = close[b[:, 0], b[:, 1]].mean(axis=1) / np.maximum(close_noweave[b[:, 0], b[:, 1]].mean(axis=1), 1e-6)
        print(f"demo measure: {kind}: {len(a)} points wide, {len(b)} close; mean colour wide vs close "
              f"dE00 {de:.2f} (L*a*b* {np.round(lab(far), 1)} vs {np.round(lab(near), 1)}); the weave's "
              f"variation wide {ratio_w.std() / ratio_w.mean():.4f}, close {ratio_c.std() / ratio_c.mean():.4f}")
