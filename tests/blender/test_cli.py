"""The command line (`blender --command madder …` and `python -m madder …`) and the
stepwise bake job behind the modal operator (cancel keeps the previous bake)."""

import os
import shutil
import subprocess
import sys

import bpy
import pytest
from conftest import ADDON, FIXTURES, install_in_user_default, make_active, open_two_stained_objects

try:
    from conftest import plain_look
except ImportError:  # before Part 1's helper lands: the same settings

    def plain_look(s):
        s.detail_auto, s.detail = False, 0
        s.output_images = False
        s.grain_from, s.irregularity = "OBJECT", 0.0

import madder

cli = sys.modules[ADDON + ".cli"]
bake = sys.modules[ADDON + ".bake"]


def flag_file(tmp_path):
    path = tmp_path / "flag.blend"
    shutil.copyfile(os.path.join(FIXTURES, "flag.blend"), path)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    flag = bpy.data.objects["Flag"]
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    # the command line and the job, not the look: no image sequence (whose frames the
    # progress would count a second time), Detail 0, no grain
    plain_look(flag.madder)
    bpy.ops.wm.save_mainfile()
    return path


def test_command_bakes_the_named_object_and_saves(tmp_path, capsys):
    path = flag_file(tmp_path)
    assert cli.main(["bake", str(path), "--object", "Flag", "--frames", "1-20"]) == 0
    out = capsys.readouterr().out
    assert "'Flag' 20/20 frames" in out and "baked 'Flag'" in out and "saved" in out
    r = madder.CacheReader(str(tmp_path / "madder_cache" / "Flag.madder"))
    assert (r.first_frame, r.last_frame) == (1, 20)
    bpy.ops.wm.open_mainfile(filepath=str(path))  # the saved file knows its cache
    assert bpy.data.objects["Flag"].madder.cache_file == "//madder_cache/Flag.madder"


@pytest.mark.parametrize(
    "argv, code, words",
    [
        (["bake", "--object", "Nope"], 1, ["no object named 'Nope'"]),
        (["bake", "--frames", "9-3"], 2, ["empty frame range"]),
        (["bake", "--object", "Flag", "--all"], 2, ["not allowed"]),
        (["frobnicate"], 2, ["invalid choice"]),
    ],
)
def test_command_errors_exit_non_zero_with_the_reason(tmp_path, capsys, argv, code, words):
    flag_file(tmp_path)
    assert cli.main(argv) == code
    err = capsys.readouterr().err
    for w in words:
        assert w in err


def test_command_failure_names_object_and_frame_and_keeps_the_cache(tmp_path, capsys):
    flag_file(tmp_path)
    assert cli.main(["bake", "--no-save"]) == 0
    cache = tmp_path / "madder_cache" / "Flag.madder"
    before = cache.read_bytes()
    build = bpy.data.objects["Flag"].modifiers.new("Build", "BUILD")
    build.frame_start, build.frame_duration, build.use_reverse = 10, 10, True
    assert cli.main(["bake", "--no-save"]) == 1
    err = capsys.readouterr().err
    assert "'Flag'" in err and "frame 11" in err
    assert cache.read_bytes() == before


def test_cancelled_job_keeps_the_previous_bake_and_frame(tmp_path):
    flag_file(tmp_path)
    scene = bpy.context.scene
    flag = make_active(bpy.data.objects["Flag"])
    assert bpy.ops.madder.bake() == {"FINISHED"}
    cache = tmp_path / "madder_cache" / "Flag.madder"
    before = cache.read_bytes()
    scene.frame_set(7)
    flag.madder.diffusion_rate *= 3  # a different bake, cancelled half-way
    job = bake.BakeJob(scene, flag)
    for _ in range(20):
        assert job.step()
    assert job.done == 20 and job.total == 48
    job.cancel()
    assert cache.read_bytes() == before
    assert scene.frame_current == 7
    assert [f.name for f in (tmp_path / "madder_cache").iterdir()] == ["Flag.madder"]
    # the same job run to the end does replace it
    job = bake.BakeJob(scene, flag)
    while job.step():
        pass
    job.finish()
    assert cache.read_bytes() != before


def test_bake_all_bakes_every_enabled_object(tmp_path):
    open_two_stained_objects(tmp_path / "table.blend")
    for name in ("Tablecloth", "Table"):
        plain_look(bpy.data.objects[name].madder)
    assert bpy.ops.madder.bake(all_objects=True) == {"FINISHED"}
    assert sorted(os.listdir(tmp_path / "madder_cache")) == ["Table.madder", "Tablecloth.madder"]


def test_python_module_entry_end_to_end(tmp_path):
    """`python -m madder bake scene.blend` in a fresh process with the bpy module, the
    extension installed in that Blender's user_default repository."""
    path = flag_file(tmp_path)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)
    install_in_user_default(env)
    # madder itself is importable only from the extension's wheel: point -m at it
    site = next((tmp_path / "user" / "extensions" / ".local").glob("lib/python*/site-packages"))
    env["PYTHONPATH"] = str(site)
    run = subprocess.run(
        [sys.executable, "-m", "madder", "bake", str(path), "--frames", "1-12"],
        env=env, capture_output=True, text=True, cwd=str(tmp_path),
    )
    assert run.returncode == 0, run.stderr
    assert "using the Madder extension bl_ext.user_default.madder installed in" in run.stdout  # not the wheel's copy
    assert "baked 'Flag'" in run.stdout and "saved" in run.stdout
    assert madder.CacheReader(str(tmp_path / "madder_cache" / "Flag.madder")).last_frame == 12
    bad = subprocess.run(
        [sys.executable, "-m", "madder", "bake", str(path), "--object", "Ghost"],
        env=env, capture_output=True, text=True, cwd=str(tmp_path),
    )
    assert bad.returncode == 1 and "no object named 'Ghost'" in bad.stderr
