"""Re-export Textures: an object's image sequence written again from the fine cache of
its last bake, at the current image size, without baking (a job the modal operator steps
a frame at a time, as a bake's). It sits above `bake` (the native module, the scene's
unit scale), `images` (the export) and `shading` (the nodes that read the new images)."""

import os

from . import bake, bridge, images, presets, shading, stored, textures
from .errors import ExportError


class ReexportJob:
    """Re-export Textures: `obj`'s image sequence rewritten from its fine cache at the
    current Size, a frame per `step()`, without a bake. Checks first (nothing written
    on error); `finish()` swaps the new sequence in, `cancel()` (or an error) keeps the
    previous one."""

    def __init__(self, scene, obj):
        self.madder = bake.core()
        self.obj = obj
        s = obj.madder
        where = dict(object=obj.name)
        if obj.type != "MESH" or not s.cache_file:
            raise ExportError(f"'{obj.name}' has no bake: bake it with Image Sequence on", **where)
        fine, folder, name = stored.image_paths(obj)
        if not os.path.isfile(fine):
            raise ExportError(f"'{obj.name}': its fine cache {fine} is missing: bake with Image Sequence on",
                              filename=fine, **where)
        if s.bake_topology and not stored.same_topology(obj.data, s.bake_topology):
            raise ExportError(f"'{obj.name}': the mesh's faces changed since the bake: bake again", **where)
        # Auto: the size the bake chose (it depends on the bake's Detail)
        auto = s.image_size == "AUTO"
        size = textures.check_size(s.image_baked_size or textures.DEFAULT_SIZE if auto else s.image_size)
        faces, face_polygon, n_polygons = bridge.topology_arrays(obj.data)
        uv = bridge.corner_uvs(obj.data)
        if uv is None:
            raise ExportError(f"'{obj.name}' has no UV map: the image sequence needs one", **where)
        self.uv_map = obj.data.uv_layers.active.name
        try:
            topology = self.madder.Topology(faces, len(obj.data.vertices), face_polygon, n_polygons)
        except self.madder.MadderError as e:
            raise ExportError(f"'{obj.name}': {e}", **where) from e
        refs = tuple(s.bake_references)
        if not any(refs):
            refs = presets.references(s)
        self.staging = textures.Staging(folder)
        weave = images.weave_detail(self.madder, obj, faces, face_polygon, uv, s.bake_detail, size,
                             bake.unit_scale(scene))
        self.export = images.SequenceExport(self.madder, obj, fine, topology, s.bake_detail, uv, refs, size,
                                     self.staging.path, name, weave=weave)
        self.size = size
        self.warnings = []
        self._begun = False

    @property
    def done(self):
        return self.export.done

    @property
    def total(self):
        return self.export.total

    @property
    def frame(self):
        return self.export.frame

    def step(self):
        try:
            if not self._begun:
                self.staging.begin()
                self._begun = True
            return self.export.step()
        except BaseException:
            self.cancel()
            raise

    def finish(self):
        try:
            self.warnings += self.export.warnings()
            self.export.close()
            folder = self.staging.commit()
        except BaseException:
            self.cancel()
            raise
        images.record(self.obj, self.export.first, self.export.last, self.size, self.uv_map, self.export.outline)
        shading.sync_object(self.obj)
        images.reload(self.obj)
        return folder

    def cancel(self):
        self.export.close()
        self.staging.discard()
