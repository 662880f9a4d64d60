"""Frame numbers as the user types and reads them, bpy-free (tested without Blender in
tests/python): the command line's `--frames A-B` and the console's lists of frames."""

import argparse
import re

# A, or A-B; either frame may be negative (Blender's frames are): 3, -5, 1-250, -5-3, -5--1
_FRAMES = re.compile(r"\s*(-?\d+)(?:\s*-\s*(-?\d+))?\s*")


def parse_range(text):
    """`(first, last)` of the frame range `text` ("A-B" or "A"); an argparse type, so a
    bad or empty range is an `argparse.ArgumentTypeError` (a usage error)."""
    m = _FRAMES.fullmatch(text)
    if m is None:
        raise argparse.ArgumentTypeError(f"expected A-B or A (e.g. 1-250, -5-3 or 7), got '{text}'")
    a = int(m[1])
    b = a if m[2] is None else int(m[2])
    if b < a:
        raise argparse.ArgumentTypeError(f"empty frame range {text}")
    return a, b


def join_frames(argv):
    """`--frames -5-3` as `--frames=-5-3`: argparse takes a value that starts with '-' (and
    is not a plain negative number) for an option, so a negative range needs the '='."""
    out, args = [], iter(argv)
    for a in args:
        if a == "--frames":
            value = next(args, None)
            out.append(a if value is None else f"{a}={value}")
        else:
            out.append(a)
    return out


def ranges(frames):
    """'1–3, 7' for the sorted frames [1, 2, 3, 7]."""
    out, start = [], None
    for i, f in enumerate(frames):
        if start is None:
            start = f
        if i + 1 == len(frames) or frames[i + 1] != f + 1:
            out.append(str(f) if f == start else f"{start}–{f}")
            start = None
    return ", ".join(out)
