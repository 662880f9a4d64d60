"""Live preview, bpy-free: what a frame change does to an object's live simulation, and
the frames held in memory (the adapter is `preview`).

The simulator's step to frame `f` takes the positions at `f + 1` (`schedule`: the
cloth's acceleration over `[f − 1, f]` is centred). A frame change shows only the new
frame's positions, so the live simulation finishes frame `f` when `f + 1` is shown: the
step is exactly the bake's, and what is shown at `f` is the newest finished frame, `f − 1`
(one frame late; the start frame and the range's last frame, which need no lookahead,
are on time). `decide` says what a frame change does; `FrameStore` holds each finished
frame's cache fields (for scrubbing back and for Bake from Preview) up to a byte limit,
dropping the oldest first."""

from collections import OrderedDict

import numpy as np

RESTART, STEP, SHOW, RESET = "restart", "step", "show", "reset"


def decide(frame, first, last, expected, complete=False):
    """What the frame change to `frame` does, with the range `first..last`, `expected` the
    frame the simulation takes next (None: nothing simulated yet) and `complete` whether
    every frame of the range is finished and still held:

    - `SHOW` for any frame once the preview is `complete`: it plays like a bake (looping
      playback keeps it, for Bake from Preview);
    - `RESTART` at the start frame: a new simulation from the first pose;
    - `STEP` at `expected` (playing forward one frame at a time, within the range);
    - `SHOW` between the start frame and `expected` (scrubbing back, or the same frame
      again): the frames simulated so far are kept and shown, nothing is stepped;
    - `RESET` anywhere else (before the start, past the range, or a jump forward that
      skips frames): the simulation is dropped; playing from the start frame begins again."""
    if complete and expected is not None:
        return SHOW
    if frame == first:
        return RESTART
    if expected is None or frame < first or frame > last:
        return RESET
    if frame == expected:
        return STEP
    if frame < expected:
        return SHOW
    return RESET


class FrameStore:
    """Finished frames' fields (`frame -> list of float32 arrays`), oldest dropped first
    once their bytes exceed `limit`. The newest frame is always kept."""

    def __init__(self, limit):
        self.limit = int(limit)
        self._frames = OrderedDict()
        self.nbytes = 0
        self.dropped = 0  # frames dropped by the limit since the last clear

    def clear(self):
        self._frames.clear()
        self.nbytes = 0
        self.dropped = 0

    def put(self, frame, fields):
        fields = [np.array(f, dtype=np.float32, copy=True) for f in fields]
        self._frames[frame] = fields
        self.nbytes += sum(f.nbytes for f in fields)
        self.trim()

    def trim(self, limit=None):
        if limit is not None:
            self.limit = int(limit)
        while self.nbytes > self.limit and len(self._frames) > 1:
            _, fields = self._frames.popitem(last=False)
            self.nbytes -= sum(f.nbytes for f in fields)
            self.dropped += 1

    def __len__(self):
        return len(self._frames)

    def frames(self):
        return list(self._frames)

    def get(self, frame):
        return self._frames.get(frame)

    def newest_at_or_before(self, frame):
        """(frame, fields) of the newest held frame ≤ `frame`, else of the oldest held
        (scrubbed back past what the limit kept: the last simulated state), else None."""
        best = None
        for f in self._frames:
            if f <= frame:
                best = f
        if best is None and self._frames:
            best = next(iter(self._frames))
        return None if best is None else (best, self._frames[best])


def stain_attributes(solute, liquid, deposit, references, color):
    """The playback attributes (RGB the colour premultiplied by the coverage, min(a, 1),
    A the dye amount a in [0, 1 + madder.DYE_EXCESS_RANGE]; wetness and deposit in [0, 1]) of one frame's
    densities: what `CacheReader.read_stain` computes from a cache (core `io::attributes`),
    here from fields held in memory. `color` is one RGB or per-vertex (3, N) colours. A
    reference ≤ 0 makes its attribute 0."""
    import madder

    def fraction(x, ref, upper=1.0):
        if ref <= 0.0:
            return np.zeros_like(x, dtype=np.float32)
        return np.clip(np.asarray(x, dtype=np.float32) / np.float32(ref), 0.0, upper).astype(np.float32)

    rs, rl, rd = (float(r) for r in references)
    c = fraction(solute, rs, 1.0 + madder.DYE_EXCESS_RANGE)
    rgba = np.empty((len(c), 4), dtype=np.float32)
    col = np.asarray(color, dtype=np.float32)
    s = np.minimum(c, 1.0)  # the colour premultiplied by the coverage (core `io::attributes`)
    for k in range(3):
        rgba[:, k] = s * (col[k] if col.ndim == 1 else col[k])
    rgba[:, 3] = c
    return rgba.ravel(), fraction(liquid, rl), fraction(deposit, rd)
