"""Lagrangian coherent structures of a baked stain (seed ch. 5), bpy-free (tested from
tests/python): which frames of the cache a request needs and why it cannot be served,
reading the flow (the liquid's velocity and the cloth's positions, stored by a bake with
Bake Flow on), FTLE and ridges through the core (`madder.ftle`, `madder.ridges`), and the
ridge graph as polylines bound to the cloth's triangles (so the curve object can follow
the cloth: `lcs_blender` binds them with a Geometry Nodes modifier).

Time: the cache records the seconds between its frames (`CacheReader.frame_time`, format
version 2); scene frame `f` is time `f · frame_time`. FTLE at frame `f` over a span of
`s` frames is `madder.ftle(…, t0 = f·dt, T = ±s·dt)`, with the cache's positions and
velocities of the frames the span covers (linear in time between frames, as the core
interpolates them) and `s × steps_per_frame` RK4 steps. Forward spans show repelling
structures, backward spans attracting ones (seed §5.2)."""

from dataclasses import dataclass

import numpy as np

from .bridge import POSITION_FIELDS, VELOCITY_FIELDS
from .errors import LcsError

FORWARD, BACKWARD = "FORWARD", "BACKWARD"
# keywords of `madder.ridges` the panel sets (the others keep the core's defaults)
RIDGE_KEYS = ("smoothing", "hessian_smoothing", "min_edges", "min_branch", "join", "remove_valleys")


def span_frames(frame, span, direction):
    """The frames `(first, last)` (first ≤ last) a span of `span` frames from `frame` covers."""
    return (frame, frame + span) if direction == FORWARD else (frame - span, frame)


def check(name, path, reader, frame, span, direction):
    """`(first, last)`: the cache frames FTLE at `frame` over `span` frames (`direction`
    FORWARD or BACKWARD) reads, or an `LcsError` naming the object `name`, the cache `path`
    and the frame: no velocity in the cache, no frame time, a zero span, a frame outside
    the bake or a span that runs past it, or a truncated file."""

    def fail(message):
        return LcsError(f"'{name}': {message}", object=name, frame=frame, filename=path)

    missing = [f for f in VELOCITY_FIELDS + POSITION_FIELDS if f not in reader.fields]
    if missing:
        older = " (or by an older Madder)" if reader.version < 2 else ""
        raise fail(f"the cache {path} has no velocity: it was baked without Bake Flow{older}; "
                   "rebake with velocity (tick Bake Flow in the Coherent Structures panel, then Bake)")
    if not reader.frame_time:
        raise fail(f"the cache {path} records no single frame time: it was baked with an animated Frame Time "
                   "(Coherent Structures needs frames of one length: bake it with the Scene Rate clock) or by an "
                   "older Madder (rebake it)")
    if span <= 0:
        raise fail("the time span is 0 frames: FTLE needs a span of at least one frame")
    if direction not in (FORWARD, BACKWARD):
        raise fail(f"direction must be {FORWARD} or {BACKWARD}, not {direction!r}")
    first, last = reader.first_frame, reader.last_frame
    if not first <= frame <= last:
        raise fail(f"frame {frame} is outside the bake (frames {first}–{last})")
    lo, hi = span_frames(frame, span, direction)
    if lo < first or hi > last:
        raise fail(f"a {direction.lower()} span of {span} frames from frame {frame} needs frames {lo}–{hi}, "
                   f"the bake has {first}–{last}: shorten the span or pick another frame")
    cut = reader.truncated_at
    if cut is not None and hi >= cut:
        raise fail(f"the cache {path} is truncated at frame {cut}: frames {lo}–{hi} are needed (bake again)")
    return lo, hi


def read_flow(reader, first, last, progress=None):
    """`(times (K,), positions (K, N, 3), velocity (K, N, 3))`, float64, of cache frames
    `first..=last`: seconds, metres and m/s. `progress(k)` after each frame read."""
    names = reader.fields
    pos_rows = [names.index(f) for f in POSITION_FIELDS]
    vel_rows = [names.index(f) for f in VELOCITY_FIELDS]
    frames = range(first, last + 1)
    n = reader.n_vertices
    positions = np.empty((len(frames), n, 3))
    velocity = np.empty((len(frames), n, 3))
    for k, f in enumerate(frames):
        block = reader.read_frame(f)
        positions[k] = block[pos_rows].T
        velocity[k] = block[vel_rows].T
        if progress is not None:
            progress(k + 1)
    times = np.array(frames, dtype=np.float64) * reader.frame_time
    return times, positions, velocity


@dataclass
class Structures:
    """What `compute` found: `sigma` (N,) FTLE (1/s); `ridges` the dict of `madder.ridges`
    (triangles, barycentric, points at `frame`, edges); `positions` (N, 3) of the cloth at
    `frame` (m); the `first`/`last` frames read."""

    sigma: np.ndarray
    ridges: dict
    positions: np.ndarray
    first: int
    last: int


def compute(madder, name, path, reader, faces, frame, span, direction, steps_per_frame, ridge_options,
            progress=None):
    """FTLE of the cache's flow at `frame` over `span` frames, and its ridges (at `frame`'s
    positions). `faces` (F, 3) uint32 of the cloth the cache was baked on; `ridge_options`
    keywords of `madder.ridges` (`RIDGE_KEYS`). `progress(done, total)` counts the frames
    read, then the FTLE and the ridges. Errors are `LcsError`s naming the object and frame."""
    first, last = check(name, path, reader, frame, span, direction)
    if steps_per_frame < 1:
        raise LcsError(f"'{name}': steps per frame must be ≥ 1 (got {steps_per_frame})", object=name, frame=frame)
    total = last - first + 3
    report = (lambda k: progress(k, total)) if progress is not None else None
    try:
        times, positions, velocity = read_flow(reader, first, last, report)
        dt = reader.frame_time
        t0 = frame * dt
        T = span * dt * (1.0 if direction == FORWARD else -1.0)
        sigma = madder.ftle(faces, positions, velocity, t0, T, steps=span * steps_per_frame, times=times)
        if progress is not None:
            progress(total - 1, total)
        at = positions[frame - first]
        ridges = madder.ridges(faces, at, sigma, **ridge_options)
        if progress is not None:
            progress(total, total)
    except madder.MadderError as e:
        raise LcsError(f"'{name}' at frame {frame}: {e}", object=name, frame=frame, filename=path) from e
    return Structures(sigma, ridges, at, first, last)


def polylines(n_points, edges):
    """The ridge graph (`n_points` points, `edges` (E, 2)) as polylines: a list of
    `(point indices, cyclic)`. A chain runs between points whose degree is not 2 (ends and
    junctions, which start several chains); what is left after them are closed loops. Each
    edge is in exactly one polyline."""
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    neighbours = [[] for _ in range(n_points)]
    for e, (a, b) in enumerate(edges):
        neighbours[a].append((int(b), e))
        neighbours[b].append((int(a), e))
    used = np.zeros(len(edges), dtype=bool)

    def walk(start, e, at):
        chain = [start, at]
        used[e] = True
        while len(neighbours[at]) == 2:
            free = [(n, f) for n, f in neighbours[at] if not used[f]]
            if not free:
                break
            at, f = free[0]
            used[f] = True
            chain.append(at)
        return chain

    out = []
    for p in range(n_points):
        if len(neighbours[p]) != 2:
            for q, e in neighbours[p]:
                if not used[e]:
                    out.append((walk(p, e, q), False))
    for e in range(len(edges)):
        if not used[e]:  # a loop through points of degree 2 only
            a, b = edges[e]
            chain = walk(int(a), e, int(b))
            if len(chain) > 2 and chain[-1] == chain[0]:
                chain.pop()
            out.append((chain, True))
    return out


def binding(faces, triangles, barycentric):
    """Each ridge point as the three vertices of its triangle `(P, 3)` int32 and their
    weights `(P, 3)` float32 (the barycentric coordinates): the point at any frame is
    `Σ_k w_k x[v_k]`, so it stays at the same place of the cloth as the cloth deforms."""
    faces = np.asarray(faces)
    tri = np.asarray(triangles, dtype=np.int64)
    return faces[tri].astype(np.int32), np.asarray(barycentric, dtype=np.float32).reshape(-1, 3)
