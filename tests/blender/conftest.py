"""Real Blender (the `bpy` module from PyPI) with the Madder extension installed from the
built zip into a fresh user repository, exactly as a user installs it."""

import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
HARNESS = os.path.join(ROOT, "blend_fixtures")  # harness.py, shared with the demo
sys.path.insert(0, HARNESS)
# The .blend fixtures: the committed ones (saved by bpy 5.0), or, for a Blender that cannot
# read 5.0 files (4.2), the same fixtures rebuilt by that Blender (`make test-blender BPY=…`).
FIXTURES = os.environ.get("MADDER_FIXTURES") or HARNESS

# A fresh user resource folder per session: extensions (and the wheels they unpack into
# <user>/extensions/.local) are installed anew, never picked up from an earlier run.
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-blender-user-")

import bpy  # noqa: E402
import harness  # noqa: E402

ZIP = harness.default_zip()

# Installed before the test modules are imported: `import madder` in a test resolves to the
# wheel the extension brought, which exists only once the extension is installed.
ADDON = harness.install_extension(ZIP)


# The newest Blender of the matrix (the first line of tests/bpy-versions.txt), what a new
# user downloads
with open(os.path.join(ROOT, "tests", "bpy-versions.txt")) as f:
    NEWEST_BPY = next(v for v in (line.split("#")[0].strip() for line in f) if v)


def eevee_on_newest_only():
    """Skips an EEVEE render on every Blender but the newest: EEVEE compiles its shaders
    for minutes on the CPU-only machines CI runs on, so the EEVEE cases run on the newest
    Blender and the Cycles cases of the same checks on every Blender of the matrix."""
    here = ".".join(str(v) for v in bpy.app.version)
    if here != NEWEST_BPY:
        pytest.skip(f"EEVEE runs on the newest Blender of the matrix ({NEWEST_BPY}); this is {here}")


_status = [0]


def pytest_sessionfinish(session, exitstatus):
    _status[0] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """With a bpy that crashes at the interpreter's exit (4.2, see harness.crashes_at_exit),
    ends the process here, with pytest's own exit status, once the report is printed."""
    if harness.crashes_at_exit():
        harness.exit(_status[0])


@pytest.fixture(scope="session")
def addon():
    """The installed add-on's module name."""
    return ADDON


@pytest.fixture
def open_fixture(addon, tmp_path):
    """Opens a copy of a fixture .blend in a temporary folder (so caches land there)."""

    def _open(name):
        path = tmp_path / name
        shutil.copyfile(os.path.join(FIXTURES, name), path)
        bpy.ops.wm.open_mainfile(filepath=str(path))
        return bpy.context.scene

    return _open


def open_two_stained_objects(path):
    """Opens a copy (at `path`) of the tablecloth fixture with Madder Stain enabled on the
    cloth (its `stain_source` group) and on the table (three wet vertices)."""
    shutil.copyfile(os.path.join(FIXTURES, "tablecloth.blend"), path)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    for name in ("Tablecloth", "Table"):
        obj = bpy.data.objects[name]
        obj.madder.enabled = True
        obj.madder.source_group = obj.vertex_groups.new(name="wet").name if name == "Table" else "stain_source"
    bpy.data.objects["Table"].vertex_groups["wet"].add([0, 1, 2], 1.0, "REPLACE")


def install_in_user_default(env):
    """Installs the extension zip, in a fresh process, into Blender's own `user_default`
    repository of the user folder `env["BLENDER_USER_RESOURCES"]`."""
    code = (
        f"import sys; sys.path.insert(0, {HARNESS!r}); import harness; "
        f"harness.install_extension({ZIP!r}, repo='user_default'); harness.exit(0)"
    )
    subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, cwd=ROOT)


def make_active(obj):
    bpy.context.view_layer.objects.active = obj
    return obj


def shown(obj):
    """`obj`'s evaluated mesh: what the viewport and renders show, where playback's stain
    attributes arrive (through the "Madder Stain" modifier, from the carrier)."""
    return obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data


def lumped_areas(mesh, co=None):
    """Independent lumped vertex areas (a third of each incident triangle) of `mesh`'s
    triangles at positions `co` ((N, 3); default: the mesh's own vertex coordinates)."""
    mesh.calc_loop_triangles()
    t = np.empty(3 * len(mesh.loop_triangles), dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", t)
    t = t.reshape(-1, 3)
    if co is None:
        co = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
        co = co.reshape(-1, 3)
    area = 0.5 * np.linalg.norm(np.cross(co[t[:, 1]] - co[t[:, 0]], co[t[:, 2]] - co[t[:, 0]]), axis=1)
    out = np.zeros(len(co))
    for k in range(3):
        np.add.at(out, t[:, k], area / 3)
    return out


def plain_look(s):
    """The settings a test of something other than the look relies on: no Auto Detail (Detail 0), no image
    sequence, no fabric grain (the default fabric's grain is the look's), the spill as weight × Amount
    (the default pool is the look's)."""
    s.detail_auto, s.detail = False, 0
    s.spill_shape = "WEIGHTS"
    s.output_images = False
    s.grain_from, s.irregularity = "OBJECT", 0.0
