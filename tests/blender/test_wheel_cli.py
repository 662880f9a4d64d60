"""The farm page's (docs/farm.md) `python -m madder bake scene.blend --all`, run verbatim on a fresh machine: a
clean virtual environment that has the bpy module and then only `pip install` of the
Madder wheel. No extension installed, an empty Blender user folder, no PYTHONPATH."""

import glob
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys

import bpy
import harness
import numpy as np
from conftest import FIXTURES, ROOT

import madder

FARM_COMMAND = "python -m madder bake scene.blend --all"


def farm_section():
    """docs/farm.md's command-line section (the README links there)."""
    text = open(os.path.join(ROOT, "docs", "farm.md"), encoding="utf-8").read()
    return text.split("## The command line", 1)[1].split("\n## ", 1)[0]


def wheel_path():
    wheels = glob.glob(os.path.join(ROOT, "addon", "wheels", "madder-*.whl"))
    assert len(wheels) == 1, f"expected one built wheel in addon/wheels, found {wheels} (run `make wheel`)"
    return wheels[0]


def fresh_venv(where):
    """A venv without pip or packages; the test venv's bpy and numpy (installed from PyPI,
    the same as `pip install bpy==…` would) are reused through a .pth file, which keeps
    the test fast. The test venv holds no madder, so the wheel is the only source of it."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(where)], check=True)
    site = next(where.glob("lib/python3*/site-packages"))
    (site / "reuse_bpy.pth").write_text(f"{importlib.metadata.distribution('bpy').locate_file('')}\n")
    return where / "bin"


def test_the_farm_pages_python_module_command_runs_with_the_wheel_alone(tmp_path):
    section = farm_section()
    assert FARM_COMMAND in section.splitlines(), "docs/farm.md no longer shows the command tested here"
    newest = harness.bpy_versions()[0]
    assert re.search(rf"pip install bpy=={re.escape(newest)} addon/wheels/madder-\S+\.whl", section), (
        f"docs/farm.md must say what to install: the newest tested bpy, {newest}"
    )

    # the scene: the flag fixture with its spill enabled, saved under the farm page's name
    bpy.ops.wm.open_mainfile(filepath=os.path.join(FIXTURES, "flag.blend"))
    flag = bpy.data.objects["Flag"]
    flag.madder.enabled = True
    flag.madder.source_group = "stain_source"
    group = flag.vertex_groups["stain_source"].index
    source = np.array([any(g.group == group and g.weight > 0 for g in v.groups) for v in flag.data.vertices])
    scene = bpy.context.scene
    first, last = scene.frame_start, scene.frame_end
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    bpy.ops.wm.read_homefile(use_empty=True)

    bindir = fresh_venv(tmp_path / "venv")
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PATH"] = f"{bindir}{os.pathsep}{env['PATH']}"
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "blender-user")  # empty: nothing installed
    install = [sys.executable, "-m", "pip", "--python", str(bindir / "python"), "install", "--no-index", "--quiet",
               wheel_path()]
    subprocess.run(install, check=True, env=env)

    run = subprocess.run(["bash", "-c", FARM_COMMAND], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "using the add-on packaged in the madder" in run.stdout
    assert "baked 'Flag'" in run.stdout and "saved" in run.stdout

    r = madder.CacheReader(str(tmp_path / "madder_cache" / "Flag.madder"))
    assert (r.first_frame, r.last_frame) == (first, last)
    solute = dict(zip(r.fields, r.read_frame(first), strict=True))["solute"]
    # the spill is where the source group is (a pool on its highest weights)
    assert solute[source].max() > 0.0 and not solute[~source].any()
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "scene.blend"))  # the saved file knows its cache
    assert bpy.data.objects["Flag"].madder.cache_file == "//madder_cache/Flag.madder"
    shutil.rmtree(tmp_path / "venv")
