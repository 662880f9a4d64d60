"""The bake's walk over the frames, bpy-free (tested without Blender in tests/python).

The simulator's step to frame `f` takes the positions at `f + 1` too, so that the
cloth's acceleration over `[f − 1, f]` is centred (and right at the first frame). The
scene can only be evaluated forward, one frame at a time, and evaluating it is the
bake's main cost: `Lookahead` visits every frame exactly once, in order, and hands each
visit to the step that needs it, the next one included."""


class Lookahead:
    """Visits of frames (`visit(frame)`, any value: positions and pours) kept one frame
    ahead. `take(frame)` returns the visit of `frame` (from the lookahead when it was the
    one visited last, else visiting it); `peek(frame)` visits `frame` ahead of its step
    and returns the visit."""

    def __init__(self, visit):
        self._visit = visit
        self._ahead = None  # (frame, its visit)

    def take(self, frame):
        if self._ahead is not None and self._ahead[0] == frame:
            value = self._ahead[1]
            self._ahead = None
            return value
        return self._visit(frame)

    def peek(self, frame):
        self._ahead = (frame, self._visit(frame))
        return self._ahead[1]

