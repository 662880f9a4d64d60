"""What playback can show from a cache, bpy-free (tested without Blender in tests/python):
the checks of an open `madder.CacheReader` against the mesh and the frame, as the
messages the panel and the console show. `handlers` adds what needs the mesh's faces (the
topology fingerprint) and writes the attributes.

A stale stain is never shown: a cache made for another vertex count, without the stain's
fields, truncated before the frame or corrupt there gives a message (naming the file)
instead of a frame to read."""

from .bridge import FIELDS


def mismatch(path, reader, n_vertices):
    """Why the cache `reader` (at `path`) cannot be this mesh's of `n_vertices` vertices,
    or None."""
    if reader.n_vertices != n_vertices:
        return (f"Stale cache: {path} holds {reader.n_vertices} vertices, the mesh has {n_vertices} "
                "(edited after the bake?): bake again")
    missing = [f for f in FIELDS if f not in reader.fields]
    if missing:
        return f"Cache {path} has no '{missing[0]}' field (baked by an older Madder?): bake again"
    return None


def frame_to_read(path, reader, frame, corrupt):
    """`(problem, cache frame)`: the frame of the cache that scene `frame` shows (clamped to
    the baked range: before it the first, after it the last), or the problem there: the
    file is truncated at or before it, or `corrupt` ({frame: message} of blocks that
    failed to read) holds it."""
    at = min(max(frame, reader.first_frame), reader.last_frame)
    cut = reader.truncated_at
    if cut is not None and at >= cut:
        return (f"Damaged cache: {path} is truncated at frame {cut} "
                f"(frames {reader.first_frame}–{cut - 1} play): bake again"), None
    bad = corrupt.get(at)
    if bad:
        return f"Damaged cache: {bad}: bake again", None
    return None, at


def truncation(reader):
    """A warning when the cache is truncated (some frames show no stain), else None."""
    cut = reader.truncated_at
    if cut is None:
        return None
    return f"Cache truncated at frame {cut}: frames {cut}–{reader.last_frame} show no stain (bake again)"
