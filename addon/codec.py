"""Compressed cloth motion: Madder's motion codec (`.madm`, `madder.MotionEncoder` and
`madder.MotionCodec`, seed ch. 3's angle representation) on the add-on's side, bpy-free
(tested without Blender in tests/python; `codec_jobs` evaluates the scene and drives it).

**Compression** takes the object-space positions of a cloth at consecutive scene frames
`first … last` and writes them as a `.madm` file whose sample `k` is scene frame
`first + k` (PC2 meaning: start `first`, rate 1). Every frame must show the mesh of the
first one (same vertex count, same triangles): the codec stores the connectivity once.
The encoder writes to a temporary file next to the target and renames it into place only
when the last frame is in, so a cancelled or failed compression leaves no file, and an
earlier file at that path intact.

**Timing.** A `.madm` file has no Mesh Cache modifier to say where its samples play (the
modifier reads PC2 and MDD only), so its header does: sample `k` is at scene frame
`start + k·rate`. A Mesh Cache modifier in Time Mode *Frame*, Play Mode *Scene* shows at
scene frame `f` the sample `f·scale − frame_start`; `modifier_timing(start, rate)` is the
Frame Start and Frame Scale that put sample `k` at `start + k·rate` (`frame_start =
start/rate`, `scale = 1/rate`), rounded to float32 as the modifier stores them. The bake
reads a `.madm` Motion File with exactly these values (`motion.MotionSamples`), and
**decompression** (a `.madm` to a PC2 with the same start and rate) points the Mesh Cache
modifier at the PC2 with them too. So a cloth baked from the `.madm` and one baked from
its PC2 through that modifier read the same positions at the same (fractional) samples
with the same arithmetic: the same stain, bit for bit."""

import os

import numpy as np

from .errors import MotionCodecError
from .placement import first_non_finite

EXT = ".madm"
PC2_EXT = ".pc2"
# Compress Motion warns above this largest error (over the bounding box diagonal): 1 %
# is visible on a cloth; the flag fixture at the default 12 bits is at 0.04 %, at 7 bits
# 0.8 %, at 6 bits 1.8 % (ARCHITECTURE.md)
ERROR_WARNING = 0.01


def is_compressed(path):
    """Whether `path` names a compressed motion file (by its extension, as Blender's own
    readers tell PC2 from MDD)."""
    return os.path.splitext(path)[1].lower() == EXT


def modifier_timing(start, rate, filename=None):
    """`(frame_start, frame_scale)` of a Mesh Cache modifier (Time Mode Frame, Play Mode
    Scene) that shows sample `k` of a file with PC2 `start` and `rate` at scene frame
    `start + k·rate`, as float32 values (what the modifier stores)."""
    if not (np.isfinite(start) and np.isfinite(rate) and rate > 0.0):
        raise MotionCodecError(f"{filename or 'the motion file'}: start {start} and rate {rate} place no "
                               "sample on the scene's frames (the rate must be a positive number)",
                               filename=filename)
    return float(np.float32(start / rate)), float(np.float32(1.0 / rate))


def pc2_path(path):
    """The PC2 file that decompressing the `.madm` file `path` writes by default: beside it,
    same name, extension `.pc2`."""
    return os.path.splitext(path)[0] + PC2_EXT


def summary(stats):
    """One line for the user from the encoder's `stats` (a dict with at least frames,
    vertices, bytes, bits_per_vertex_frame, max_error, rms_error)."""
    raw = 96.0  # PC2/MDD: three float32 per vertex and frame
    bpvf = stats["bits_per_vertex_frame"]
    ratio = raw / bpvf if bpvf > 0 else float("inf")
    return (f"{stats['frames']} frames × {stats['vertices']} vertices in {_size(stats['bytes'])}: "
            f"{bpvf:.2f} bits/vertex/frame ({ratio:.0f}× smaller than PC2), error max "
            f"{100 * stats['max_error']:.3g} % / RMS {100 * stats['rms_error']:.3g} % of the bounding box "
            "diagonal")


def _size(n):
    for unit in ("bytes", "kB", "MB"):
        if n < 1000 or unit == "MB":
            return f"{n} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"


class Compression:
    """The motion of the cloth `name` over scene frames `first … last`, going into the
    `.madm` file `path` one frame at a time (`add`), with `bits` quantization bits.
    Nothing appears at `path` before `finish()`; `abort()` (or any error) removes the
    partial file and leaves whatever was at `path` as it was."""

    def __init__(self, madder, name, path, first, last, bits):
        if not is_compressed(path):
            raise MotionCodecError(f"'{name}': the compressed motion file {path} must end in {EXT}",
                                   object=name, filename=path)
        if last < first:
            raise MotionCodecError(f"'{name}': the frame range {first}-{last} is empty", object=name)
        self.madder, self.name, self.path = madder, name, path
        self.first, self.last, self.bits = first, last, bits
        self.encoder = None
        self.faces = None
        self.frame = None  # the last frame added
        self.aborted = False  # by abort() or an error: no frame is taken after

    @property
    def total(self):
        return self.last - self.first + 1

    @property
    def done(self):
        return 0 if self.frame is None else self.frame - self.first + 1

    def next_frame(self):
        """The scene frame `add` expects next."""
        return self.first if self.frame is None else self.frame + 1

    def add(self, frame, positions, faces):
        """Adds scene `frame`'s object-space `positions` (N, 3) of the mesh with triangles
        `faces` (F, 3); returns whether frames are left to add."""
        try:
            if self.aborted:
                raise MotionCodecError(f"'{self.name}': the compression to {self.path} was cancelled",
                                       object=self.name, frame=frame)
            if frame != self.next_frame():
                raise MotionCodecError(f"'{self.name}': frame {frame} given where frame {self.next_frame()} was "
                                       "expected (the frames are compressed in order)", object=self.name, frame=frame)
            self._add(frame, np.asarray(positions), np.asarray(faces, dtype=np.uint32))
        except BaseException:
            self.abort()
            raise
        self.frame = frame
        return frame < self.last

    def _add(self, frame, positions, faces):
        name, first = self.name, self.first
        if self.encoder is None:
            if len(faces) == 0:
                raise MotionCodecError(f"'{name}' has no faces at frame {frame}: the motion codec stores a "
                                       "surface (its angles), not loose vertices or edges", object=name, frame=frame)
        elif len(positions) != self.n_vertices:
            raise MotionCodecError(
                f"'{name}' has {len(positions)} vertices at frame {frame} but {self.n_vertices} at frame "
                f"{first}: a compressed motion keeps one mesh (disable modifiers that add or remove geometry "
                "over time)", object=name, frame=frame)
        elif faces.shape != self.faces.shape or not np.array_equal(faces, self.faces):
            raise MotionCodecError(
                f"'{name}' changes its faces at frame {frame} ({len(faces)} triangles, {len(self.faces)} at "
                f"frame {first}, or the same number joined differently): a compressed motion keeps one mesh",
                object=name, frame=frame)
        bad = first_non_finite(positions)
        if bad is not None:
            raise MotionCodecError(f"'{name}': vertex {bad} has a non-finite position at frame {frame}",
                                   object=name, frame=frame, vertex=bad)
        madder = self.madder
        try:
            if self.encoder is None:
                folder = os.path.dirname(self.path)
                if folder:
                    os.makedirs(folder, exist_ok=True)
                self.encoder = madder.MotionEncoder(self.path, faces, start=float(first), rate=1.0,
                                                    bits=int(self.bits))
                self.faces, self.n_vertices = faces, len(positions)
            self.encoder.add_frame(positions)
        except madder.MadderError as e:
            raise MotionCodecError(f"'{name}' at frame {frame}: {e}", object=name, frame=frame,
                                   vertex=getattr(e, "vertex", None), filename=getattr(e, "filename", None)) from e
        except OSError as e:
            raise MotionCodecError(f"'{name}': cannot write {self.path}: {e.strerror or e}", object=name,
                                   filename=self.path) from e

    def finish(self):
        """Puts the file in place once every frame is in; returns the encoder's stats."""
        if self.frame != self.last or self.encoder is None:
            self.abort()
            raise MotionCodecError(f"'{self.name}': compression finished at frame {self.frame} before its last "
                                   f"frame {self.last}", object=self.name)
        encoder, self.encoder = self.encoder, None
        try:
            return encoder.finish()
        except self.madder.MadderError as e:
            encoder.abort()
            raise MotionCodecError(f"'{self.name}': {e}", object=self.name, filename=self.path) from e

    def abort(self):
        """Discards the partial file; `path` keeps what it held."""
        self.aborted = True
        if self.encoder is not None:
            encoder, self.encoder = self.encoder, None
            encoder.abort()


class Decompression:
    """The `.madm` file `source` decoded, a frame at a time (`step`), into the PC2 file
    `target` (same start and rate). Each decoded frame goes straight to a partial file
    beside `target` (`madder.Pc2Writer`), so memory holds one frame whatever the length;
    `finish()` puts the file in place atomically and `abort()` (or any error) removes the
    partial file: `target` keeps what it held until the whole file is on disk. `name` (an
    object's) prefixes the messages when given."""

    def __init__(self, madder, source, target, name=None):
        self.who = f"'{name}': " if name else ""
        self.madder, self.source, self.target, self.name = madder, source, target, name
        if not is_compressed(source):
            raise self._error(f"{source} is not a compressed motion file ({EXT})", filename=source)
        if os.path.splitext(target)[1].lower() != PC2_EXT:
            raise self._error(f"the decompressed motion file {target} must end in {PC2_EXT}", filename=target)
        try:
            self.codec = madder.MotionCodec(source)
        except madder.MadderError as e:
            raise self._error(str(e), filename=source) from e
        if self.codec.n_frames == 0:
            raise self._error(f"{source} holds no frames", filename=source)
        self.timing = modifier_timing(self.codec.start, self.codec.rate, source)
        self.writer = None
        self.done = 0

    @property
    def total(self):
        return self.codec.n_frames

    def _error(self, message, **fields):
        return MotionCodecError(self.who + message, object=self.name, **fields)

    def _write(self, action):
        """Runs `action` on the PC2 side, naming the target in its errors (and discarding
        the partial file)."""
        try:
            return action()
        except (self.madder.MadderError, OSError) as e:
            self.abort()
            text = str(e) if isinstance(e, self.madder.MadderError) else \
                f"cannot write {self.target}: {e.strerror or e}"
            raise self._error(text, filename=self.target) from e

    def step(self):
        """Decodes the next sample and appends it to the partial file; returns whether
        samples are left."""
        k = self.done
        try:
            frame = self.codec.read_frame(k)
        except self.madder.MadderError as e:
            self.abort()
            raise self._error(str(e), frame=k, filename=self.source) from e
        if self.writer is None:
            def start():
                folder = os.path.dirname(self.target)
                if folder:
                    os.makedirs(folder, exist_ok=True)
                return self.madder.Pc2Writer(self.target, self.codec.n_points,
                                             start=float(self.codec.start), rate=float(self.codec.rate))
            self.writer = self._write(start)
        self._write(lambda: self.writer.add_frame(frame))
        self.done += 1
        return self.done < self.total

    def finish(self):
        """Decodes what is left and puts the PC2 file in place; returns its path."""
        while self.done < self.total:
            self.step()
        self._write(self.writer.finish)
        self.writer = None
        return self.target

    def abort(self):
        """Removes the partial file; `target` keeps what it held."""
        writer, self.writer = self.writer, None
        if writer is not None:
            writer.abort()
