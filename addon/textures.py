"""Image-sequence output, bpy-free (tested without Blender in tests/python): where the
files go, how they are numbered, how Blender's image user must be set to show them, the
export loop from a fine cache, and the staging folder that keeps the previous sequence
until a new one is complete.

Layout, next to the cache `<folder>/<stem>.madder` (`<stem>`: the object's clean name),
every path derived from the cache's (so Save As and Relocate Cache carry them along):

    <folder>/<stem>.fine.madder            the refined cloth's fields (the Detail mesh),
                                           same field names as the cache; the source of
                                           the images (re-exported from it at any size)
    <folder>/<stem>_images/<stem>_stain.####.exr
                                           RGBA: the solute colour × coverage, coverage
                                           (the dye amount up to saturation, 1)
    <folder>/<stem>_images/<stem>_wet.####.exr
                                           R: wetness, G: deposit, B: the dye above
                                           saturation / madder.DYE_EXCESS_RANGE

With a fabric's Thread Count, the images carry the weave's fine scale (`weave_maps`,
`madder.WeaveDetail`: the homogenization's corrector and the threads' uptake), laid along
each face's weft at its physical size and prefiltered to what a texel can hold
(`prefilter_cells`); Vertex Colors never do. The detail multiplies the deposit by the
threads' uptake, so those images start from the values *before* their clamp to 1 and clip
each finished texel (`CLIP`): where the dye saturates the fibres every thread shows it,
and the weave shows where the stain is faint.

With Sharp Outline (`outline`, on by default) the stain's front, which the Detail mesh
resolves over a few of its cells, is drawn within a texel where the cloth beyond is dry
(core `texture::outline`: the coverage read as the cell average of a sharp front at half
its local plateau); the dye above saturation is cut with it, wetness and deposit are left.

`####` is the scene frame (4 digits, more when needed). The values are exactly the
playback attributes (Sharp Outline aside) (`CacheReader.read_stain`, core `io::attributes`), rasterized over
the refined cloth's UV triangles (`madder.rasterize`: barycentric at texel centres,
islands padded), with the dye amount split at 1 (coverage + range × excess), so the
shader reads the same numbers from either.

One more file, number `first − 1`, repeats the first frame: Blender's image user shows
file `frame_offset` (here `first − 1`) at every scene frame before `frame_start` (it
clamps to 0 images into the sequence, not to 1), where the attributes show the first
frame. Without it those frames would render the "missing image" magenta.

Each sequence (and the fine cache of a bake) is written into `<stem>_images.partial/`
and swapped in whole by `Staging.commit`: a bake or re-export that fails or is cancelled
leaves the previous sequence as it was."""

import os
import shutil

import numpy as np

from .errors import ExportError

SIZES = (512, 1024, 2048, 4096)
DEFAULT_SIZE = 1024
PADDING = 4  # texels each UV island grows by (bilinear filtering and mip-maps read inside)
# rings of the Detail mesh over which Sharp Outline reads a front as smeared (the
# simulation's span two to four; core `texture::outline::DEFAULT_RINGS`)
OUTLINE_RINGS = 3
KINDS = ("stain", "wet")
EXT = ".exr"
DIGITS = 4
STAIN_CHANNELS = ("R", "G", "B", "A")
# wetness, deposit, and the dye's excess over saturation (an EXR without B would read as
# garbage there, −5e8, 1e15, in a material of the user's reading the image's colour)
WET_CHANNELS = ("R", "G", "B")
# with the outline left to the shader, the wet image's alpha is the front's signed
# distance in metres (core `texture::outline`, "At the pixel"; `shading` reads it)
DISTANCE_CHANNEL = "A"


# -- names


def stem(cache_path):
    """The cache's file name without its extension (the object's clean name)."""
    return os.path.splitext(os.path.basename(cache_path))[0]


def fine_cache_path(cache_path):
    """The fine cache beside `cache_path`: `<stem>.fine<ext>`."""
    base, ext = os.path.splitext(cache_path)
    return f"{base}.fine{ext}"


def image_folder(cache_path):
    """The folder of the image sequences beside `cache_path`: `<stem>_images`."""
    return os.path.splitext(cache_path)[0] + "_images"


def file_name(name, kind, frame):
    """`<name>_<kind>.<frame>.exr`, the frame zero-padded to 4 digits (Blender finds the
    sequence's number as the last run of digits; it keeps the padding for other frames)."""
    if frame < 0:
        raise ValueError(f"image sequence frames are never negative (got {frame})")
    return f"{name}_{kind}.{frame:0{DIGITS}d}{EXT}"


def frame_file(folder, name, kind, frame):
    return os.path.join(folder, file_name(name, kind, frame))


def pattern(folder, name, kind):
    """The sequence as a user reads it: `…/<name>_<kind>.####.exr`."""
    return os.path.join(folder, f"{name}_{kind}.{'#' * DIGITS}{EXT}")


# -- checks


def check_size(size):
    """`size` as an int when it is one of `SIZES`; else ExportError."""
    try:
        value = int(size)
    except (TypeError, ValueError):
        value = None
    if value not in SIZES:
        raise ExportError(f"image size {size!r} is not one of {', '.join(map(str, SIZES))} px")
    return value


def frames_problem(first, last):
    """Why frames `first`…`last` cannot be numbered as an image sequence, or None:
    Blender reads no sign in a sequence's file numbers."""
    if first < 0:
        return (f"the frame range {first}–{last} starts before frame 0: image sequences are "
                "numbered by frame and Blender reads no negative numbers (start at frame 0 or later, "
                "or untick Image Sequence)")
    return None


def image_user(first, last):
    """Blender's image user settings that show file number f at scene frame f for
    `first` ≤ f ≤ `last`, the first file before and the last after. Blender shows file
    `clamp(f − frame_start + 1, 0, frame_duration) + frame_offset`."""
    return {"frame_start": first, "frame_offset": first - 1, "frame_duration": last - first + 1}


def shown_file_number(frame, frame_start, frame_offset, frame_duration):
    """The file number Blender's image user shows at scene `frame` (not cyclic): a model
    of Blender's `BKE_image_user_frame_get`, for tests of `image_user`."""
    return min(max(frame - frame_start + 1, 0), frame_duration) + frame_offset


def missing_file(folder, name, frame):
    """The first file of scene `frame`'s images that does not exist, or None."""
    for kind in KINDS:
        path = frame_file(folder, name, kind, frame)
        if not os.path.isfile(path):
            return path
    return None


# -- staging: a whole folder written aside, then swapped in


class Staging:
    """A folder `final` that is replaced only when its new contents are complete.

    `begin()` makes an empty `<final>.partial` (removing one left by an interrupted run);
    files go there (`path`); `commit()` moves the old `final` aside (`<final>.old`), the
    new one in, and deletes the old; `discard()` deletes the partial folder. A process
    killed between the two renames of `commit` leaves `<final>.old` and no `final`:
    the next `begin()` (or `recover`) puts it back."""

    def __init__(self, final):
        self.final = os.path.normpath(final)
        self.path = self.final + ".partial"
        self.old = self.final + ".old"

    def recover(self):
        if not os.path.isdir(self.final) and os.path.isdir(self.old):
            os.rename(self.old, self.final)

    def begin(self):
        try:
            self.recover()
            _remove(self.path)
            os.makedirs(self.path)
        except OSError as e:
            raise ExportError(f"cannot create the image folder {self.path}: {_reason(e)}",
                              filename=self.path) from e
        return self.path

    def commit(self):
        try:
            _remove(self.old)
            if os.path.lexists(self.final):
                os.rename(self.final, self.old)
            os.rename(self.path, self.final)
        except OSError as e:
            raise ExportError(f"cannot move the new images into {self.final}: {_reason(e)}",
                              filename=self.final) from e
        shutil.rmtree(self.old, ignore_errors=True)
        return self.final

    def discard(self):
        shutil.rmtree(self.path, ignore_errors=True)


def remove_outputs(cache_path):
    """Deletes the fine cache and the image folder beside `cache_path` (and leftovers of
    an interrupted run). Returns the paths removed."""
    removed = []
    fine, folder = fine_cache_path(cache_path), image_folder(cache_path)
    if os.path.isfile(fine):
        os.remove(fine)
        removed.append(fine)
    for path in (folder, folder + ".partial", folder + ".old"):
        if os.path.lexists(path):
            _remove(path)
            removed.append(path)
    return removed


def _remove(path):
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.remove(path)


def _reason(e):
    return e.strerror or str(e)


# -- the weave's detail (issue 13 part 4)

CLIP = {"stain": "premultiplied", "wet": "unit"}
"""How `madder.rasterize` clips each image kind when the values were read unclamped (with
the weave's detail, core `texture::clip`)."""

UPTAKE = {"stain": (True, True, True, True), "wet": (False, True, False)}
"""Per image kind and channel, whether the threads' uptake applies (the deposit: the stain's
colour and coverage, the wet image's deposit) or only the corrector (wetness; the dye's
excess over saturation, which lies over the threads evenly: core `io::attributes`)."""


def triangle_areas(p):
    """Areas of the triangles `p` (F, 3, 3)."""
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def uv_areas(t):
    """Areas of the UV triangles `t` (F, 3, 2)."""
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def weave_maps(positions, faces, uv, threads_per_m, angle):
    """Per triangle, the (F, 2, 2) map from UV to threads along the fabric's weft (row 0)
    and warp (row 1), the `face_map` of `madder.WeaveDetail`:
    `threads_per_m[f] · s_f · [[cos θ, sin θ], [−sin θ, cos θ]]`, with `s_f = √(world area /
    UV area)` the face's metres per UV unit (`positions` in metres) and `θ = angle[f]` the
    weft's angle from the u axis, counter-clockwise. A face with a degenerate UV or world
    triangle, or no threads, gets the zero map (no detail)."""
    p = np.asarray(positions, dtype=np.float64)[np.asarray(faces)]
    t = np.asarray(uv, dtype=np.float64)
    world, area_uv = triangle_areas(p), uv_areas(t)
    ok = (area_uv > 0) & (world > 0)
    s = np.zeros(len(p))
    s[ok] = np.sqrt(world[ok] / area_uv[ok])
    k = np.asarray(threads_per_m, dtype=np.float64) * s
    c, n = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([k * c, k * n], axis=1), np.stack([-k * n, k * c], axis=1)], axis=1)


def threads_per_texel(maps, size):
    """Threads per texel of each face at image `size`: the map's scale over `size`."""
    return np.sqrt(np.abs(np.linalg.det(maps))) / size


def thread_problem(obj_name, material, maps, size):
    """A warning when the weave of `material` on `obj_name` has more than one thread per
    texel at `size` px on some of its faces (`maps`: theirs), or None."""
    per = threads_per_texel(maps, size)
    over = per > 1.0
    if not over.any():
        return None
    return (f"'{obj_name}': the Thread Count of fabric '{material}' puts up to {per.max():.1f} threads in a "
            f"texel of the {size} px images on {over.mean():.0%} of its faces: the weave cannot be resolved "
            "there and is left out (raise Size, or lower Thread Count)")


def drop_unresolved(maps, size):
    """`maps` with the faces of more than one thread per texel at `size` zeroed: sampled
    that coarsely the weave would alias into a moiré, so those faces keep the smooth stain."""
    out = np.array(maps, dtype=np.float64)
    out[threads_per_texel(out, size) > 1.0] = 0.0
    return out


PREFILTER_TEXELS = 0.5
"""The weave's prefilter: a Gaussian of this standard deviation in texels (a texture's usual
antialiasing width: the thread's repeat at 2.5 texels keeps half its contrast, the cell
edges' harmonics that a texel grid would alias into a crosshatch are gone)."""

PREFILTER_STEPS = 2
"""Prefilter widths per octave: faces share a few correctors (core `Corrector::filtered`)."""


def prefilter_cells(maps, cells_per_thread, size):
    """Per face, the standard deviation in tile cells of the Gaussian that prefilters the
    weave's detail for its texels at `size` px (`maps`: the faces' `weave_maps`;
    `cells_per_thread`: the tile's cells per thread, 2 with gaps): `PREFILTER_TEXELS` times
    the texel's footprint in cells, rounded to `PREFILTER_STEPS` per octave in log scale;
    0 (no filter) below 1/16 of a cell, where point samples already resolve the cells, and
    on faces without detail (zero map)."""
    s = PREFILTER_TEXELS * threads_per_texel(maps, size) * cells_per_thread
    out = np.zeros(len(s))
    on = s >= 1.0 / 16.0
    out[on] = 2.0 ** (np.round(np.log2(s[on]) * PREFILTER_STEPS) / PREFILTER_STEPS)
    return out


# -- the export loop


class Exporter:
    """Writes the images of a fine cache's frames, one frame per `export(frame)`.

    - `madder`: the native module (`rasterize`, `write_exr`, `MadderError`);
    - `reader`: an open `madder.CacheReader` of the fine cache;
    - `faces` (T, 3) uint32 and `uv` (T, 3, 2) float32: the refined cloth's triangles and
      their corner UVs (`madder.Refinement.faces()`, `.face_uv(...)`);
    - `references`, `color`: as `CacheReader.read_stain` takes them (the bake's);
    - `size` (one of `SIZES`), `folder` (where the files go) and `name` (their prefix).

    `weave`: None, or per kind the `madder.WeaveDetail` that adds the weave's fine scale.
    `outline`: the rings over which a front is read as smeared (`madder.Outline`; core
    `texture::outline`), or 0 for the images as rasterized; `shader`: whether the front is
    left to the shader (`madder.lift_outline`, the wet image gains `DISTANCE_CHANNEL`;
    then `texel` is a texel's size in metres along u and v) instead of drawn within a
    texel (`madder.sharpen_outline`).

    `overlapping` holds the texels covered by more than one UV triangle (overlapping
    islands), as `madder.rasterize` counts them on the first frame exported."""

    def __init__(self, madder, reader, faces, uv, references, color, size, folder, name, padding=PADDING,
                 weave=None, outline=0, shader=False, texel=None):
        self.madder, self.reader = madder, reader
        self.faces = np.ascontiguousarray(faces, dtype=np.uint32)
        self.uv = np.ascontiguousarray(uv, dtype=np.float32)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.uv.shape != (len(self.faces), 3, 2):
            raise ValueError(f"faces {self.faces.shape} and uv {self.uv.shape} must be (T, 3) and (T, 3, 2)")
        self.references, self.color = tuple(references), tuple(color)
        self.size, self.padding = check_size(size), padding
        self.folder, self.name = folder, name
        self.weave = weave or {}
        # the Detail mesh's rings, built once for every frame (`madder.Outline`)
        self._outline = madder.Outline(self.faces, reader.n_vertices, int(outline)) if outline else None
        self.shader = bool(self._outline) and bool(shader)
        if self.shader:
            if texel is None or not all(np.isfinite(t) and t > 0 for t in texel):
                raise ValueError(f"the outline left to the shader needs the texel's size in metres, got {texel}")
            self.texel = (float(texel[0]), float(texel[1]))
        self._fields = None  # the frame's outline fields (N, 2), read with the values
        self._fields_raster = None  # (frame, their image)
        n = reader.n_vertices
        self._rgba = np.zeros(4 * n, dtype=np.float32)
        self._wet = np.zeros(n, dtype=np.float32)
        self._deposit = np.zeros(n, dtype=np.float32)
        self._excess = np.zeros(n, dtype=np.float32)
        self._wet_values = np.zeros((n, len(WET_CHANNELS)), dtype=np.float32)
        self.overlapping = None
        self._read = None  # the frame whose values the buffers hold

    @property
    def first(self):
        return self.reader.first_frame

    @property
    def last(self):
        return self.reader.last_frame

    def frames(self):
        return range(self.first, self.last + 1)

    def values(self, frame):
        """Frame `frame`'s per-vertex image values: (RGBA (N, 4), wet (N, 3): wetness,
        deposit and the dye's excess), the playback attributes with the dye amount above 1
        moved to the excess, a fraction of `madder.DYE_EXCESS_RANGE` (core `io::attributes`;
        without their clamp to 1 when the weave's detail is added: `export` clips the
        finished texels instead)."""
        # with the weave's detail the fractions are read unclamped and each finished texel
        # is clipped (`export`): a saturated stain stays saturated on every thread
        self.reader.read_stain(frame, self.references, self.color, self._rgba, self._wet, self._deposit,
                               clamp=not self.weave, excess=self._excess)
        self._wet_values[:, 0] = self._wet
        self._wet_values[:, 1] = self._deposit
        self._wet_values[:, 2] = self._excess
        if self._outline is not None:
            self._fields = self._outline.fields(self._rgba[3::4])
        self._read = frame
        return self._rgba.reshape(-1, 4), self._wet_values

    def _fields_image(self, frame):
        """The outline fields of `frame` rasterized, kept for the frame's other image (a
        rasterization was half the images' cost)."""
        if self._fields_raster is None or self._fields_raster[0] != frame:
            self._fields_raster = None  # (free the last frame's before the next is made)
            image, _ = self.madder.rasterize(self.faces, self.uv, self._fields, self.size, self.padding)
            self._fields_raster = (frame, image)
        return self._fields_raster[1]

    def export(self, frame, kinds=KINDS):
        """Writes scene `frame`'s images of `kinds` (both by default; one at a time keeps a
        modal operator's steps short at 4096 px), and, for the first frame, the file before
        it as well (see the module doc). Returns the paths written."""
        if self._read != frame:
            self.values(frame)
        written = []
        for kind in kinds:
            values, channels = ((self._rgba.reshape(-1, 4), STAIN_CHANNELS) if kind == "stain"
                                else (self._wet_values, WET_CHANNELS))
            extra = {}  # none: as without fabrics
            if self.weave:
                extra["clip"] = CLIP[kind]
                if kind in self.weave:
                    extra["weave"] = self.weave[kind]
            image, overlapping = self.madder.rasterize(self.faces, self.uv, values, self.size, self.padding,
                                                       **extra)
            if self.shader:  # the front left to the shader: the stain lifted, its distance
                fields = self._fields_image(frame)
                if kind == "stain":
                    self.madder.lift_outline(fields, self.texel, stain=image)
                else:
                    image = np.concatenate([image, np.empty(image.shape[:2] + (1,), np.float32)], axis=2)
                    self.madder.lift_outline(fields, self.texel, wet=image, distance=len(WET_CHANNELS))
                    channels = WET_CHANNELS + (DISTANCE_CHANNEL,)
            elif self._outline is not None:  # the front drawn within a texel
                fields = self._fields_image(frame)
                if kind == "stain":
                    self.madder.sharpen_outline(fields, stain=image)
                else:
                    self.madder.sharpen_outline(fields, wet=image, excess=WET_CHANNELS.index("B"))
            if self.overlapping is None:  # the same on every frame: the UV layout's
                self.overlapping = int(overlapping)
            path = frame_file(self.folder, self.name, kind, frame)
            self.madder.write_exr(path, image, channels)
            del image
            written.append(path)
            if frame == self.first and frame >= 1:
                lead = frame_file(self.folder, self.name, kind, frame - 1)
                try:
                    _link_or_copy(path, lead)
                except OSError as e:
                    raise ExportError(f"cannot write {lead}: {_reason(e)}", filename=lead, frame=frame) from e
                written.append(lead)
        return written


def _link_or_copy(src, dst):
    """`dst` as a second name of `src` (a hard link, or a copy where links are refused)."""
    if os.path.lexists(dst):
        os.remove(dst)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)
