"""Cloth motion from a PC2/MDD file (or a compressed `.madm` file, see `codec`), sampled
at scene frames, bpy-free (tested without Blender in tests/python; `bake.MotionFile` opens
the file and finds the modifier).

Blender's Mesh Cache modifier, in its Time Mode *Frame* and Play Mode *Scene*, shows at
scene frame `f` the file's sample `f · frame_scale − frame_start` (0-based), whatever
start, rate or times the file's header gives. Between samples it interpolates linearly;
before the first sample and after the last it holds that sample. `MotionSamples` reads
the file the same way, so the bake sees the cloth the modifier renders."""

import os
import re

import numpy as np

from .errors import BakeError

# the Mesh Cache modifier's settings that change the file's positions, with the test that
# they are not at their defaults (Flip Axis is a set of axes before 5.0, three booleans since)
_CHANGES = (
    ("Forward/Up Axis", lambda m: (m.forward_axis, m.up_axis) != ("POS_Y", "POS_Z")),
    ("Flip Axis", lambda m: any(m.flip_axis)),
    ("Influence", lambda m: m.factor != 1.0 or bool(m.vertex_group)),
    ("Deform Mode", lambda m: m.deform_mode != "OVERWRITE"),
    ("Interpolation", lambda m: m.interpolation != "LINEAR"),
)


def modifier_timing(name, m):
    """`(frame_start, frame_scale)` of the Mesh Cache modifier `m` (any object with its
    attributes) that reads the motion file of object `name`. Raises BakeError when the
    modifier reads the file in another time or play mode, or changes its positions."""
    if m.time_mode != "FRAME" or m.play_mode != "SCENE":
        raise BakeError(
            f"'{name}': its Mesh Cache modifier '{m.name}' reads the motion file with Time Mode "
            f"'{m.time_mode.title()}' and Play Mode '{m.play_mode.title()}'; Madder reads motion files "
            "as the modifier does in Time Mode Frame, Play Mode Scene: set those",
            object=name,
        )
    changed = [label for label, differs in _CHANGES if differs(m)]
    if changed:
        raise BakeError(
            f"'{name}': its Mesh Cache modifier '{m.name}' changes the file's positions "
            f"({', '.join(changed)}), which Madder's motion file reader does not do: leave those "
            "at their defaults, or clear Motion File to bake what the modifier stack shows",
            object=name,
        )
    return m.frame_start, m.frame_scale


def sample_message(error):
    """A point-cache error read while baking, with its file frame called the *sample*, so
    that the bake's message names one frame: the scene's."""
    return re.sub(r"\bframe (\d+)", r"sample \1", str(error))


class MotionSamples:
    """The positions of point cache `cache` (a `madder.PointCache`, or anything with
    `n_frames` and `read_frame(k)`) at scene frames, for object `name`, read as the Mesh
    Cache modifier with Frame Start `offset` and Frame Scale `scale` shows them."""

    def __init__(self, cache, name, path, offset=0.0, scale=1.0):
        self.cache, self.name, self.path = cache, name, path
        self.offset, self.scale = offset, scale
        self._last = {}  # the last two samples read, by index

    def _read(self, k):
        """Sample `k`, (N, 3) float32. The last two reads are kept: between samples every
        frame reads two, one of which the frame before read too, and a compressed file
        (`.madm`) decodes each sample anew otherwise."""
        co = self._last.get(k)
        if co is None:
            co = self.cache.read_frame(k)
            self._last = {j: v for j, v in self._last.items() if j in (k - 1, k + 1)}
            self._last[k] = co
        return co

    def sample(self, frame):
        """The (fractional) sample the Mesh Cache modifier shows at scene `frame`."""
        return frame * self.scale - self.offset

    def outside(self, first, last):
        """A warning when frames `first`–`last` read past the file's samples (or None)."""
        n = self.cache.n_frames
        out = [f for f in range(first, last + 1) if not (-1e-6 <= self.sample(f) <= n - 1 + 1e-6)]
        if not out:
            return None
        return (
            f"{len(out)} frames ({out[0]}…{out[-1]}) read past the {n} samples of its motion file "
            f"{os.path.basename(self.path)}: the cloth holds its first or last sample there, as the "
            "Mesh Cache modifier shows it"
        )

    def local(self, frame):
        """Object-space positions at scene `frame`, (N, 3) float64."""
        t, last = self.sample(frame), self.cache.n_frames - 1
        t = min(max(t, 0.0), float(last))  # the modifier holds the first or last sample
        k = int(min(np.floor(t + 1e-6), last))
        try:
            co = self._read(k).astype(np.float64)
            if k < last and t - k > 1e-6:
                co += (t - k) * (self._read(k + 1) - co)
        except Exception as e:
            message = f"'{self.name}' at frame {frame}: {sample_message(e)}"
            raise BakeError(message, object=self.name, frame=frame) from e
        return co
