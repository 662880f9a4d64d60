"""Image-sequence output, the bpy side: the object's sequence as Blender images, and the
export that writes a sequence from a fine cache a frame at a time (inside a bake, or as
Re-export Textures: `reexport`). Paths, numbering, staging and the export loop are bpy-free, in
`textures`; the shader nodes that read the images are in `shading`."""

import os

import bpy
import numpy as np

from . import fabrics, stored, textures
from .errors import ExportError

KINDS = textures.KINDS


def frame_problem(obj, frame):
    """The missing image of scene `frame` (clamped to the baked range, as shown), as a
    message naming it, or None."""
    if not stored.uses_images(obj):
        return None
    first, last = obj.madder.image_frames
    _, folder, name = stored.image_paths(obj)
    missing = textures.missing_file(folder, name, min(max(frame, first), last))
    if missing is None:
        return None
    return f"Image sequence incomplete: {missing} is missing: Re-export Textures or bake again"


def _image_name(obj, kind):
    return f"Madder {obj.name} {kind}"


def sequence_image(obj, kind):
    """The Blender image of `obj`'s `kind` ("stain" or "wet") sequence, made or updated:
    an image sequence on the first frame's file, non-colour (the values are data, the
    same as the attributes), alpha channel-packed (RGB and A are read as stored: the
    stain is premultiplied already)."""
    s = obj.madder
    _, folder, name = stored.image_paths(obj)
    path = textures.frame_file(folder, name, kind, s.image_frames[0])
    stored_as = stored.stored_path(path)
    img = bpy.data.images.get(_image_name(obj, kind))
    if img is None:
        if os.path.isfile(path):
            img = bpy.data.images.load(path, check_existing=False)
            img.name = _image_name(obj, kind)
        else:  # not there (yet): the image shows it is missing, as any image would
            img = bpy.data.images.new(_image_name(obj, kind), 1, 1, float_buffer=True)
    img.source = "SEQUENCE"
    if img.filepath != stored_as:
        img.filepath = stored_as
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"
    return img


def set_image_user(image_user, obj):
    """Scene frame f shows file f over the baked range, the first file before it and the
    last after it (`textures.image_user`), refreshed on every frame change."""
    first, last = obj.madder.image_frames
    for key, value in textures.image_user(first, last).items():
        setattr(image_user, key, value)
    image_user.use_cyclic = False
    image_user.use_auto_refresh = True


def reload(obj):
    """Makes Blender read `obj`'s sequences again (after a bake or re-export replaced them)."""
    for kind in KINDS:
        img = bpy.data.images.get(_image_name(obj, kind))
        if img is not None:
            img.reload()


def remove_images(obj):
    """Removes `obj`'s sequence images that nothing uses any more."""
    for kind in KINDS:
        img = bpy.data.images.get(_image_name(obj, kind))
        if img is not None and img.users == 0:
            bpy.data.images.remove(img)


def rest_positions(obj, unit):
    """`obj`'s mesh vertices in world space, metres (`unit`: metres per Blender unit)."""
    co = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    m = np.array(obj.matrix_world, dtype=np.float64)
    return (co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]) * unit


def weave_detail(madder, obj, faces, face_polygon, uv, level, size, unit):
    """`(details, warnings)`: per image kind the `madder.WeaveDetail` of `obj`'s fabrics
    with a Thread Count, over the cloth refined at Detail `level` (None when no face keeps
    a weave), and a warning per fabric whose threads are finer than a texel at `size` (those
    faces keep the smooth stain: `textures.drop_unresolved`). Each face's corrector is
    prefiltered to what its texels can hold (`textures.prefilter_cells`).
    Raises ExportError naming the material whose fabric is invalid."""
    spec = fabrics.face_weave(obj, face_polygon)
    if spec is None:
        return None, []
    slots, slot = spec
    threads = np.array([sl[2] if sl else 0.0 for sl in slots])[slot]
    angle = np.array([sl[3] if sl else 0.0 for sl in slots])[slot]
    maps = textures.weave_maps(rest_positions(obj, unit), faces, uv, threads, angle)
    resolved = textures.drop_unresolved(maps, size)
    # per woven slot, its corrector at each prefilter its faces need (a face's texel
    # footprint sets it: textures.prefilter_cells); faces index into that list
    correctors, face_index, warnings = [], np.full(len(slot), madder.NO_WEAVE, dtype=np.uint32), []
    for i, sl in enumerate(slots):
        mine = slot == i
        if sl is None or not mine.any():
            continue
        try:
            base = madder.fabric_corrector(**sl[1])
            width, _ = base.cells
            sigma = textures.prefilter_cells(resolved[mine], width / base.threads[0], size)
            for s in np.unique(sigma):
                correctors.append(madder.fabric_corrector(**sl[1], filter=float(s)))
                face_index[np.flatnonzero(mine)[sigma == s]] = len(correctors) - 1
        except madder.MadderError as e:
            raise ExportError(f"'{obj.name}': material '{sl[0]}': {e}", object=obj.name) from e
        why = textures.thread_problem(obj.name, sl[0], maps[mine], size)
        if why:
            warnings.append(why)
    if not np.any((face_index != madder.NO_WEAVE) & np.any(resolved != 0.0, axis=(1, 2))):
        return None, warnings  # no face keeps a weave: the plain images, bit for bit
    n = 4 ** level
    face_fabric = np.repeat(face_index, n)
    face_map = np.ascontiguousarray(np.repeat(resolved, n, axis=0))
    details = {kind: madder.WeaveDetail(correctors, face_fabric, face_map, list(textures.UPTAKE[kind]))
               for kind in KINDS}
    return details, warnings


class SequenceExport:
    """Writes `obj`'s image sequence from the fine cache at `fine_path` into
    `folder`, one frame per `step()` (`textures.Exporter`).

    `topology` and `level`: the cloth's `madder.Topology` and the Detail level the fine
    cache was baked at (its refinement numbers the fine cache's vertices); `uv`: the
    cloth triangles' corner UVs (F, 3, 2); `references`: the bake's; `weave`: the
    `(details, warnings)` of `weave_detail`, or None. Errors are `ExportError`s naming the
    object, the frame and the file."""

    def __init__(self, madder, obj, fine_path, topology, level, uv, references, size, folder, name, weave=None):
        self.madder, self.obj = madder, obj
        s = obj.madder  # the outline's mode as the export began (`record` keeps it)
        self.outline = ("SHADER" if s.outline_in_shader else "TEXEL") if s.sharp_outline else ""
        texel = self._texel(size) if self.outline == "SHADER" else None
        try:
            self.reader = madder.CacheReader(fine_path)
            refinement = madder.Refinement(topology, level)
        except madder.MadderError as e:
            raise ExportError(f"'{obj.name}': {e}", object=obj.name, filename=fine_path) from e
        if refinement.n_vertices != self.reader.n_vertices:
            raise ExportError(
                f"'{obj.name}': the fine cache {fine_path} holds {self.reader.n_vertices} vertices, the cloth "
                f"refined at Detail {level} has {refinement.n_vertices}: bake again",
                object=obj.name, filename=fine_path)
        self.exporter = textures.Exporter(
            madder, self.reader, refinement.faces(), refinement.face_uv(uv), references,
            tuple(obj.madder.stain_color), size, folder, name, weave=weave[0] if weave else None,
            outline=textures.OUTLINE_RINGS if self.outline else 0, shader=texel is not None, texel=texel)
        self.weave_warnings = list(weave[1]) if weave else []
        self.first, self.last = self.exporter.first, self.exporter.last
        self.size = self.exporter.size
        # one image per step: a 4096² image takes about a second to write
        self._work = iter([(f, kind) for f in self.exporter.frames() for kind in KINDS])
        self.frame = None  # the last frame whose images are all written
        self.done = 0
        self.overlapping = None

    def _texel(self, size):
        """A texel's size in metres along u and v at `size` px: the cloth's rest metres per
        UV unit per axis (`weave_shader.metres_per_uv_axes`) over `size`."""
        from . import weave_shader

        layer = self.obj.data.uv_layers.active  # the map the images are baked for
        scales = weave_shader.metres_per_uv_axes(self.obj, layer.name if layer else "")
        if scales is None:
            raise ExportError(f"'{self.obj.name}': its UV map has no area, so the outline cannot be measured "
                              "in metres (turn Sharp Outline's In Shader off, or unwrap it)", object=self.obj.name)
        return (scales[0] / textures.check_size(size), scales[1] / textures.check_size(size))

    @property
    def total(self):
        return self.last - self.first + 1

    def step(self):
        """Writes the next image; returns False once the last is written."""
        frame, kind = next(self._work)
        where = dict(object=self.obj.name, frame=frame)
        try:
            self.exporter.export(frame, (kind,))
        except self.madder.MadderError as e:
            raise ExportError(f"'{self.obj.name}' at frame {frame}: {e}",
                              filename=getattr(e, "filename", None), **where) from e
        except ExportError as e:
            raise ExportError(f"'{self.obj.name}' at frame {frame}: {e}", filename=e.filename, **where) from e
        except OSError as e:
            raise ExportError(f"'{self.obj.name}' at frame {frame}: cannot write {e.filename}: {e.strerror or e}",
                              filename=e.filename, **where) from e
        self.overlapping = self.exporter.overlapping
        if kind == KINDS[-1]:
            self.frame = frame
            self.done += 1
        return not (frame == self.last and kind == KINDS[-1])

    def warnings(self):
        n = self.overlapping
        out = list(self.weave_warnings)
        if n:
            return out + [f"its UV islands overlap ({n} texels at {self.size} px): where they do, the image "
                    "sequence shows one island's stain on both (give each face its own UV space)"]
        return out

    def close(self):
        self.reader = self.exporter = None


def record(obj, first, last, size, uv_map, outline):
    """What the shader needs to read the sequence, and how Sharp Outline drew it
    (`outline`: "" as rasterized, "TEXEL" within a texel, "SHADER" lifted with the front's
    distance for the shader), recorded on the object."""
    s = obj.madder
    s.image_baked = True
    s.image_frames = (first, last)
    s.image_baked_size = size
    s.image_uv_map = uv_map
    s.image_baked_outline = bool(outline)
    s.image_baked_outline_shader = outline == "SHADER"


def forget(obj):
    s = obj.madder
    s.image_baked = False
    s.image_frames = (0, 0)
    s.image_baked_size = 0
    s.image_uv_map = ""
    s.image_baked_outline = False
    s.image_baked_outline_shader = False
