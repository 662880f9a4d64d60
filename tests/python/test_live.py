"""Live preview's bpy-free logic (`madder.addon.live`): what a frame change does, the
frames held under a byte limit, and the playback attributes of held fields against the
cache's own normalization (`CacheReader.read_stain`, Rust)."""

import numpy as np

import madder
from madder.addon import live


def test_decide_steps_forward_shows_back_and_resets_otherwise():
    first, last = 5, 12
    assert live.decide(5, first, last, None) == live.RESTART
    assert live.decide(5, first, last, 9) == live.RESTART  # back to the start: a new simulation
    assert live.decide(6, first, last, None) == live.RESET  # nothing simulated yet
    assert live.decide(9, first, last, 9) == live.STEP
    assert live.decide(12, first, last, 12) == live.STEP
    assert live.decide(7, first, last, 9) == live.SHOW  # scrubbing back
    assert live.decide(8, first, last, 9) == live.SHOW  # the same frame again
    assert live.decide(10, first, last, 9) == live.RESET  # a jump forward skips frames
    assert live.decide(13, first, last, 13) == live.RESET  # past the range
    assert live.decide(4, first, last, 9) == live.RESET  # before the start
    # a complete preview (every frame held) plays like a bake: looping keeps it
    for frame in (4, 5, 9, 12, 13):
        assert live.decide(frame, first, last, 13, complete=True) == live.SHOW


def test_store_drops_the_oldest_frames_past_its_limit():
    n = 100
    frame = 3 * 4 * n
    store = live.FrameStore(3 * frame + frame // 2)
    for f in range(1, 8):
        store.put(f, [np.full(n, f, np.float32)] * 3)
    assert store.frames() == [5, 6, 7] and store.nbytes == 3 * frame and store.dropped == 4
    assert store.newest_at_or_before(6)[0] == 6
    assert store.newest_at_or_before(2)[0] == 5  # before what is held: the oldest held
    assert store.newest_at_or_before(99)[0] == 7
    store.trim(1)  # the newest frame is always kept
    assert store.frames() == [7]
    src = np.ones(n, np.float32)
    store.put(8, [src, src, src])
    src[:] = 5.0  # held fields are copies
    assert (store.get(8)[0] == 1.0).all()
    store.clear()
    assert len(store) == 0 and store.newest_at_or_before(3) is None


def test_attributes_of_held_fields_match_the_caches_normalization(tmp_path):
    n = 301
    rng = np.random.default_rng(5)
    refs = (0.037, 0.21, 0.0)  # a zero reference makes its attribute zero
    for colors in (False, True):
        names = ["solute", "wetness", "deposit"] + (["color_r", "color_g", "color_b"] if colors else [])
        values = [rng.uniform(-0.01, 0.3, n).astype(np.float32) for _ in names]
        path = tmp_path / f"c{int(colors)}.madder"
        w = madder.CacheWriter(str(path), n, names, 1, 1)
        w.push_frame(values)
        w.finish()
        color = (0.3, 0.6, 0.9)
        want = [np.empty(4 * n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)]
        madder.CacheReader(str(path)).read_stain(1, refs, color, *want)
        got = live.stain_attributes(values[0], values[1], values[2], refs, values[3:6] if colors else color)
        for g, x in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, x)
