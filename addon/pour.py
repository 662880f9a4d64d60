"""The liquid a spill and the sources add, bpy-free (tested without Blender in
tests/python): what each vertex receives, and where a splash starts.

- A spill adds, at the first frame, the liquid the Spill Group's weights hold,
  `M = Σ amount · weight_i · A_i` (kg, `A_i` the vertex areas), either as a **pool**
  (the default; laid by the core, `Simulator.add_pool`, on the simulated cloth's
  vertices): `amount` deep where the weights are highest, until `M` is laid, or as the
  weights themselves, `weight × amount` (kg/m²) on every vertex (`spilled`). The same
  mass either way; a pool has a sharp edge, where a soft brush's weights would lay a film
  that thins to nothing and stains as a blurred disc (a liquid lands as a body of liquid,
  of its own depth: the weights say where it lands first, the amount how deep).
- A source pours `flow × dt × weight` over each frame it is active, `weight` falling
  linearly from 1 at contact to 0 at its reach `d ≥ reach` (and 0 out of reach, where
  the distance query returns infinity).
- A splash starts from the weighted centroid of the wet area (a spill) or the source's
  origin."""

import numpy as np


def falloff(distance, reach):
    """Pour weights (float32) of vertices at `distance` from a source of `reach`: 1 at
    contact, linearly down to 0 at the reach, 0 beyond (an infinite distance too)."""
    return np.clip(1.0 - distance / reach, 0.0, 1.0).astype(np.float32)


def pours_at(frame, use_frame_range, frame_start, frame_end):
    """Whether a source pours at `frame` (always, without a frame range)."""
    return not use_frame_range or frame_start <= frame <= frame_end


def spilled(weights, amount):
    """The liquid (kg/m², float32) a spill of `amount` puts on vertices of `weights`."""
    return (weights * amount).astype(np.float32)


def poured(flow, dt, weights):
    """The liquid (kg/m², float32) a source of `flow` (kg/m²/s) brings over `dt` seconds."""
    return (flow * dt * weights).astype(np.float32)


def centroid(weights, positions):
    """The `weights`-weighted centroid of `positions` (N, 3), as a tuple (the spill's
    splash centre)."""
    w = weights.astype(np.float64)
    return tuple((w @ positions.astype(np.float64)) / w.sum())
