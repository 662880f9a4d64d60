"""Compressed motion (issue 15, Blender): Compress Motion writes the flag's evaluated cloth
as a .madm file whose decoded frames are within the encoder's stated error of the
evaluated positions; Decompress writes them to a PC2 that a Mesh Cache modifier plays at
the frames they came from; the bake takes the .madm file as a Motion File and gives the
same stain, bit for bit, as the PC2 through that modifier; cancelling or failing leaves
no file and an earlier file as it was."""

import math
import os
import sys

import bpy
import numpy as np
import pytest
from conftest import ADDON, make_active, plain_look

import madder

jobs = sys.modules[ADDON + ".codec_jobs"]
bake = sys.modules[ADDON + ".bake"]


def evaluated(scene, obj, frame):
    """Object-space positions the modifier stack shows at `frame`, (N, 3) float32."""
    scene.frame_set(frame)
    me = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    co = np.empty(3 * len(me.vertices), dtype=np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def evaluated_motion(scene, obj):
    """Every frame of the scene's range, (F, N, 3) float32."""
    return np.stack([evaluated(scene, obj, f) for f in range(scene.frame_start, scene.frame_end + 1)])


def decoded(path):
    r = madder.MotionCodec(str(path))
    return np.stack([r.read_frame(k) for k in range(r.n_frames)])


def cache_contents(obj):
    """Every field of every frame of `obj`'s baked cache, as one array."""
    r = madder.CacheReader(bpy.path.abspath(obj.madder.cache_file))
    return np.stack([np.stack([r.read(f, name) for name in r.fields]) for f in range(r.first_frame,
                                                                                      r.last_frame + 1)])


def files(folder):
    return sorted(os.listdir(folder))


def damaged(data, k):
    """The .madm file `data` with a byte of frame `k`'s payload flipped (the layout of
    rust/madder/src/angles/codec/format.rs: a 48-byte header, 12 bytes per face, then per
    frame its length, its checksum and its payload)."""
    n_faces = int.from_bytes(data[16:20], "little")
    at = 48 + 12 * n_faces
    for _ in range(k):
        at += 8 + int.from_bytes(data[at:at + 4], "little")
    out = bytearray(data)
    out[at + 8 + 3] ^= 0xFF
    return bytes(out)


@pytest.fixture
def flag(open_fixture, tmp_path):
    scene = open_fixture("flag.blend")
    flag = make_active(bpy.data.objects["Flag"])
    flag.madder.source_group = "stain_source"
    plain_look(flag.madder)  # the motion is what is tested, at the cloth's own resolution
    flag.madder.motion.path = str(tmp_path / "motion" / "flag.madm")
    return scene, flag


def test_compressed_flag_decodes_within_its_stated_error(flag, tmp_path):
    scene, obj = flag
    scene.frame_set(7)
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    assert scene.frame_current == 7  # the frame the user was on
    path = tmp_path / "motion" / "flag.madm"
    assert files(path.parent) == ["flag.madm"]
    motion = evaluated_motion(scene, obj)
    r = madder.MotionCodec(str(path))
    assert (r.n_frames, r.n_points) == motion.shape[:2]
    assert (r.start, r.rate) == (float(scene.frame_start), 1.0)
    np.testing.assert_array_equal(r.frame_times, scene.frame_start + np.arange(len(motion)))
    bpvf, max_error, rms_error = obj.madder.motion.figures
    assert bpvf == pytest.approx(8 * path.stat().st_size / motion.shape[0] / motion.shape[1])
    # the decoded frames against the evaluated ones, over the diagonal of the bounding box
    # of the whole sequence (the stats' measure), computed here independently
    frames = decoded(path)
    diagonal = np.linalg.norm(np.ptp(motion.reshape(-1, 3), axis=0))
    err = np.linalg.norm(frames.astype(np.float64) - motion, axis=2) / diagonal
    # the encoder measures in float64; the decoded frames are float32 (half an ulp of the
    # largest coordinate, over the diagonal, on top)
    slack = float(np.abs(motion).max() * 2.0**-24 * math.sqrt(3) / diagonal)
    assert err.max() <= max_error + slack
    assert np.sqrt(np.mean(err**2)) == pytest.approx(rms_error, rel=1e-3, abs=slack)
    assert 0 < rms_error <= max_error < 0.01  # 12 bits: under 1 % of the diagonal (measured: README)
    assert 0 < bpvf < 96  # smaller than PC2
    assert "bits/vertex/frame" in obj.madder.motion.report


def test_decompressed_pc2_plays_in_a_mesh_cache_where_it_was_compressed(flag, tmp_path):
    scene, obj = flag
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    madm = tmp_path / "motion" / "flag.madm"
    frames = decoded(madm)
    assert bpy.ops.madder.decompress_motion() == {"FINISHED"}
    pc2 = tmp_path / "motion" / "flag.pc2"  # the default: beside the .madm file
    assert files(pc2.parent) == ["flag.madm", "flag.pc2"]
    cache = madder.PointCache(str(pc2))
    assert cache.format == "pc2" or cache.format == "PC2"
    np.testing.assert_array_equal(np.stack([cache.read_frame(k) for k in range(cache.n_frames)]), frames)
    np.testing.assert_array_equal(cache.frame_times, scene.frame_start + np.arange(len(frames)))
    m = obj.modifiers[-1]  # added at the bottom of the stack: it overwrites the cloth
    assert (m.type, m.name) == ("MESH_CACHE", jobs.MODIFIER_NAME)
    assert os.path.normpath(bpy.path.abspath(m.filepath)) == str(pc2)
    assert (m.frame_start, m.frame_scale) == (float(scene.frame_start), 1.0)
    for frame in (scene.frame_start, scene.frame_start + 1, 20, scene.frame_end):
        np.testing.assert_allclose(evaluated(scene, obj, frame), frames[frame - scene.frame_start], atol=1e-6,
                                   err_msg=f"frame {frame}")
    # decompressing again replaces the file and reuses the modifier
    n_modifiers = len(obj.modifiers)
    assert bpy.ops.madder.decompress_motion() == {"FINISHED"}
    assert len(obj.modifiers) == n_modifiers and files(pc2.parent) == ["flag.madm", "flag.pc2"]
    # without the Mesh Cache option: the PC2 only, to a path of one's own
    other = tmp_path / "elsewhere" / "moved.pc2"
    obj.madder.motion.pc2_path, obj.madder.motion.add_mesh_cache = str(other), False
    assert bpy.ops.madder.decompress_motion() == {"FINISHED"}
    assert other.read_bytes() == pc2.read_bytes() and len(obj.modifiers) == n_modifiers


def test_bake_from_madm_is_the_bake_from_its_pc2_and_near_the_scene(flag, tmp_path):
    scene, obj = flag
    assert bpy.ops.madder.bake() == {"FINISHED"}
    from_scene = cache_contents(obj)
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    assert bpy.ops.madder.decompress_motion() == {"FINISHED"}
    obj.madder.motion_file = str(tmp_path / "motion" / "flag.madm")
    assert bpy.ops.madder.bake() == {"FINISHED"}
    from_madm = cache_contents(obj)
    obj.madder.motion_file = str(tmp_path / "motion" / "flag.pc2")  # read through the modifier's timing
    assert bpy.ops.madder.bake() == {"FINISHED"}
    from_pc2 = cache_contents(obj)
    # the same positions at the same samples: the same stain, bit for bit
    np.testing.assert_array_equal(from_madm, from_pc2)
    # and near the stain of the cloth itself: the decoded motion is within a fraction of a
    # percent of the diagonal, and the stain follows the motion's accelerations
    solute = slice(0, 1)  # field 0 of every frame: the solute density
    last = from_scene[-1, 0]
    diff = np.abs(from_madm[:, solute] - from_scene[:, solute]).max() / last.max()
    print(f"\nbake from the .madm vs the scene's cloth: max solute difference {100 * diff:.3g} % of the "
          "largest solute density at the last frame")
    assert diff < 0.05
    # the motion really drove it: a cloth that hangs still stains differently
    obj.modifiers.remove(obj.modifiers[jobs.MODIFIER_NAME])
    obj.modifiers.remove(next(m for m in obj.modifiers if m.type == "CLOTH"))
    obj.madder.motion_file = ""
    assert bpy.ops.madder.bake() == {"FINISHED"}
    still = np.abs(cache_contents(obj)[:, solute] - from_scene[:, solute]).max() / last.max()
    assert still > 10 * diff, (still, diff)


@pytest.mark.parametrize("start, rate", [(1.0, 1.0), (5.0, 1.0), (1.0, 2.0), (-3.0, 0.5)])
def test_madm_plays_its_samples_where_its_pc2_mesh_cache_does(flag, tmp_path, start, rate):
    """A .madm Motion File reads, at every scene frame (between samples, before the first
    and after the last), exactly what the bake reads from its decompressed PC2 through the
    Mesh Cache modifier Decompress sets up, and what that modifier shows."""
    scene, obj = flag
    motion = evaluated_motion(scene, obj)[:20]
    path = tmp_path / "motion" / "flag.madm"
    os.makedirs(path.parent)
    faces = np.array(_triangles(obj), dtype=np.uint32)
    enc = madder.MotionEncoder(str(path), faces, start=start, rate=rate, bits=12)
    for co in motion:
        enc.add_frame(co)
    enc.finish()
    obj.modifiers.remove(next(m for m in obj.modifiers if m.type == "CLOTH"))
    assert bpy.ops.madder.decompress_motion() == {"FINISHED"}
    obj.madder.motion_file = str(path)
    from_madm = bake.MotionFile(madder, obj)
    obj.madder.motion_file = str(path.with_suffix(".pc2"))
    from_pc2 = bake.MotionFile(madder, obj)
    assert (from_madm.offset, from_madm.scale) == (from_pc2.offset, from_pc2.scale)
    assert from_madm.sample(start + 3 * rate) == 3.0
    for frame in range(scene.frame_start - 2, scene.frame_end + 1):
        a = from_madm.local(frame)
        np.testing.assert_array_equal(a, from_pc2.local(frame), err_msg=f"frame {frame}")
        np.testing.assert_allclose(a, evaluated(scene, obj, frame), atol=1e-5, err_msg=f"frame {frame}")


def _triangles(obj):
    obj.data.calc_loop_triangles()
    return [list(t.vertices) for t in obj.data.loop_triangles]


def test_cancel_leaves_no_file_and_keeps_an_earlier_one(flag, tmp_path):
    scene, obj = flag
    path = tmp_path / "motion" / "flag.madm"
    scene.frame_set(3)
    job = jobs.CompressJob(scene, obj)
    for _ in range(10):
        assert job.step()
    job.cancel()  # what Esc does
    assert not path.parent.exists() or files(path.parent) == []
    assert scene.frame_current == 3
    os.makedirs(path.parent, exist_ok=True)
    path.write_bytes(b"an earlier compression")
    job = jobs.CompressJob(scene, obj)
    for _ in range(10):
        job.step()
    job.cancel()
    assert path.read_bytes() == b"an earlier compression" and files(path.parent) == ["flag.madm"]
    # decompression: nothing is written before the end
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    pc2 = path.with_suffix(".pc2")
    pc2.write_bytes(b"an earlier pc2")
    job = jobs.DecompressJob(scene, obj)
    assert job.step() and job.step()
    job.cancel()
    assert pc2.read_bytes() == b"an earlier pc2" and files(path.parent) == ["flag.madm", "flag.pc2"]
    assert jobs.MODIFIER_NAME not in obj.modifiers


def test_bad_input_is_named_and_writes_nothing(flag, tmp_path):
    scene, obj = flag
    path = tmp_path / "motion" / "flag.madm"
    os.makedirs(path.parent)
    path.write_bytes(b"an earlier compression")
    # the topology changes: the Build modifier removes faces from frame 11 on
    build = obj.modifiers.new("Build", "BUILD")
    build.frame_start, build.frame_duration, build.use_reverse = 10, 10, True
    changed = next(f for f in range(scene.frame_start, scene.frame_end + 1)
                   if len(evaluated(scene, obj, f)) != len(obj.data.vertices))
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.compress_motion()
    assert "'Flag'" in str(e.value) and f"at frame {changed} " in str(e.value), str(e.value)
    assert path.read_bytes() == b"an earlier compression" and files(path.parent) == ["flag.madm"]
    obj.modifiers.remove(build)
    # a vertex that is not a number (the cloth is removed: it would spread it)
    obj.modifiers.remove(next(m for m in obj.modifiers if m.type == "CLOTH"))
    obj.data.vertices[5].co = (float("nan"), 0.0, 0.0)
    with pytest.raises(RuntimeError, match=f"'Flag': vertex 5 has a non-finite position at frame "
                                           f"{scene.frame_start}"):
        bpy.ops.madder.compress_motion()
    assert path.read_bytes() == b"an earlier compression" and files(path.parent) == ["flag.madm"]
    # no faces
    mesh = bpy.data.meshes.new("Dots")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1)], [])
    dots = bpy.data.objects.new("Dots", mesh)
    scene.collection.objects.link(dots)
    make_active(dots).madder.motion.path = str(path)
    with pytest.raises(RuntimeError, match="'Dots' has no faces at frame"):
        bpy.ops.madder.compress_motion()
    assert path.read_bytes() == b"an earlier compression" and files(path.parent) == ["flag.madm"]
    # not a .madm path
    dots.madder.motion.path = str(tmp_path / "motion" / "flag.pc2")
    with pytest.raises(RuntimeError, match="must end in .madm"):
        bpy.ops.madder.compress_motion()


def test_bad_madm_files_are_named_and_keep_earlier_files(flag, tmp_path):
    scene, obj = flag
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    assert bpy.ops.madder.bake() == {"FINISHED"}
    baked = open(bpy.path.abspath(obj.madder.cache_file), "rb").read()
    path = tmp_path / "motion" / "flag.madm"
    pc2 = path.with_suffix(".pc2")
    pc2.write_bytes(b"an earlier pc2")
    data = path.read_bytes()
    n = scene.frame_end - scene.frame_start + 1
    path.write_bytes(data[: len(data) - 50])  # the last frame is cut short
    with pytest.raises(RuntimeError, match="'Flag': .*flag.madm") as e:
        bpy.ops.madder.decompress_motion()
    assert f"frame {n - 1}" in str(e.value)  # names the last sample (0-based)
    assert pc2.read_bytes() == b"an earlier pc2" and files(path.parent) == ["flag.madm", "flag.pc2"]
    # baking from it fails before the first frame, naming the object, the file and the
    # sample; the previous bake stays
    obj.madder.motion_file = str(path)
    with pytest.raises(RuntimeError, match=f"'Flag': motion file: .*flag.madm: .*sample {n - 1}"):
        bpy.ops.madder.bake()
    assert open(bpy.path.abspath(obj.madder.cache_file), "rb").read() == baked
    # a damaged frame in the middle: found when the bake reaches it, named with the scene
    # frame it plays at and the sample
    path.write_bytes(damaged(data, 10))
    with pytest.raises(RuntimeError, match=f"'Flag' at frame {scene.frame_start + 10}: .*flag.madm: sample 10 "):
        bpy.ops.madder.bake()
    assert open(bpy.path.abspath(obj.madder.cache_file), "rb").read() == baked
    with pytest.raises(RuntimeError, match="'Flag': .*flag.madm: frame 10 is corrupt"):
        bpy.ops.madder.decompress_motion()
    assert pc2.read_bytes() == b"an earlier pc2" and files(path.parent) == ["flag.madm", "flag.pc2"]
    # not a codec file at all
    path.write_bytes(b"not a motion file at all, but long enough to hold a header" * 4)
    with pytest.raises(RuntimeError, match="flag.madm"):
        bpy.ops.madder.bake()
    # a .madm of another mesh: the vertex counts differ, named with the object
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=3, y_subdivisions=3)
    grid = make_active(bpy.context.object)
    grid.madder.motion.path = str(path)
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    make_active(obj)
    with pytest.raises(RuntimeError, match=f"'Flag' has {len(obj.data.vertices)} vertices but its motion file "
                                           f".*flag.madm has {len(grid.data.vertices)} points"):
        bpy.ops.madder.bake()
    # and Decompress with the Mesh Cache option refuses to point the flag's modifier at it
    with pytest.raises(RuntimeError, match=f"'Flag' has 1025 vertices but .*flag.madm holds "
                                           f"{len(grid.data.vertices)} points"):
        bpy.ops.madder.decompress_motion()
    assert pc2.read_bytes() == b"an earlier pc2"


class _Recorder:
    """The window manager, workspace and operator `self` a modal run touches, recording."""

    def __init__(self, job):
        self._running, self._timer, self._what = job, "timer", "compression"
        self.calls, self.reports = [], []

    def __getattr__(self, name):  # event_timer_remove, progress_update, status_text_set, …
        return lambda *args: self.calls.append((name, args))

    def report(self, kind, message):
        self.reports.append((set(kind), message))


def run_modal(job, events):
    """Feeds `events` (event types) to the operators' modal driver with `job` running, as
    Blender's event loop does (the UI is not there in background mode); returns the
    results and the recorder."""
    operators = sys.modules[ADDON + ".operators"]
    op = _Recorder(job)
    op._stop = lambda context, result: operators._StepwiseOperator._stop(op, context, result)
    op._done = lambda job, result: operators.MADDER_OT_compress_motion._done(op, job, result)
    context = type("Context", (), {"window_manager": op, "workspace": op})()
    out = []
    for kind in events:
        event = type("Event", (), {"type": kind})() if isinstance(kind, str) else kind
        out.append(operators._StepwiseOperator.modal(op, context, event))
        if out[-1] != {"RUNNING_MODAL"} and out[-1] != {"PASS_THROUGH"}:
            break
    return out, op


def test_modal_compression_steps_on_timer_and_esc_cancels(flag, tmp_path):
    scene, obj = flag
    path = tmp_path / "motion" / "flag.madm"
    os.makedirs(path.parent)
    path.write_bytes(b"an earlier compression")
    scene.frame_set(4)
    out, op = run_modal(jobs.CompressJob(scene, obj), ["TIMER"] * 5 + ["MOUSEMOVE", "TIMER", "ESC"])
    assert out == [{"RUNNING_MODAL"}] * 5 + [{"PASS_THROUGH"}, {"RUNNING_MODAL"}, {"CANCELLED"}]
    assert op._running.done == 6  # a frame per timer tick
    assert ("progress_update", (int(100 * 6 / 48),)) in op.calls and ("progress_end", ()) in op.calls
    assert op.reports == [({"WARNING"}, "Madder: compression of 'Flag' cancelled; nothing was written")]
    assert path.read_bytes() == b"an earlier compression" and files(path.parent) == ["flag.madm"]
    assert scene.frame_current == 4
    # run to the end: the file replaces the earlier one, and the figures are reported
    n = scene.frame_end - scene.frame_start + 1
    out, op = run_modal(jobs.CompressJob(scene, obj), ["TIMER"] * (n + 1))
    assert out == [{"RUNNING_MODAL"}] * (n - 1) + [{"FINISHED"}]
    assert madder.MotionCodec(str(path)).n_frames == n and files(path.parent) == ["flag.madm"]
    assert op.reports[0][0] == {"INFO"} and "bits/vertex/frame" in op.reports[0][1]
    assert scene.frame_current == 4


def test_undo_is_held_while_a_modal_job_runs(flag, tmp_path):
    """Ctrl+Z (Cmd+Z) during a modal run would reload the data under the job: it is
    swallowed with a warning, the job goes on, and other keys still pass through."""
    scene, obj = flag
    path = tmp_path / "flag.madm"
    obj.madder.motion.path = str(path)
    undo = type("Event", (), {"type": "Z", "value": "PRESS", "ctrl": True, "oskey": False})()
    undo_mac = type("Event", (), {"type": "Z", "value": "PRESS", "ctrl": False, "oskey": True})()
    plain_z = type("Event", (), {"type": "Z", "value": "PRESS", "ctrl": False, "oskey": False})()
    out, op = run_modal(jobs.CompressJob(scene, obj), ["TIMER", undo, "TIMER", undo_mac, plain_z, "ESC"])
    assert out == [{"RUNNING_MODAL"}] * 4 + [{"PASS_THROUGH"}, {"CANCELLED"}]
    assert op._running.done == 2
    held = ({"WARNING"}, "Madder: undo waits until the job ends (Esc cancels it)")
    assert op.reports[:2] == [held, held]


class _Layout:
    """A panel layout that checks what it is asked to show: existing settings, registered
    operators; records the labels."""

    def __init__(self, shown):
        self.shown = shown

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, name
        self.shown.append(name)

    def operator(self, idname, **kw):
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name), idname
        self.shown.append(idname)

    def label(self, text="", **kw):
        self.shown.append(text)

    def column(self, **kw):
        return self


def test_the_panel_shows_the_settings_and_the_figures(flag):
    scene, obj = flag
    panels = sys.modules[ADDON + ".panels"]
    panel = panels.MADDER_PT_stain_motion
    assert panel.bl_parent_id == "MADDER_PT_stain_cache"  # under Cache, with Motion File
    shown = []
    fake = type("Panel", (), {"layout": _Layout(shown)})()
    panel.draw(fake, bpy.context)
    assert shown == ["path", "bits", "madder.compress_motion", "pc2_path", "add_mesh_cache",
                     "madder.decompress_motion"]
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    shown.clear()
    panel.draw(fake, bpy.context)
    figures = " ".join(shown[3:-3])
    assert "bits/vertex/frame" in figures and "bounding box" in figures


def test_settings_and_figures_are_saved_in_the_blend(flag, tmp_path):
    scene, obj = flag
    m = obj.madder.motion
    m.bits, m.pc2_path, m.add_mesh_cache = 14, "//out/flag.pc2", False
    assert bpy.ops.madder.compress_motion() == {"FINISHED"}
    figures, report = tuple(m.figures), m.report
    bpy.ops.wm.save_mainfile(filepath=str(tmp_path / "saved.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "saved.blend"))
    m = bpy.data.objects["Flag"].madder.motion
    assert (m.path, m.bits, m.pc2_path, m.add_mesh_cache) == (str(tmp_path / "motion" / "flag.madm"), 14,
                                                             "//out/flag.pc2", False)
    assert tuple(m.figures) == pytest.approx(figures) and m.report == report
    assert madder.MotionCodec(m.path).bits[0] == 14
