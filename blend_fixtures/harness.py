"""Running the Madder extension inside the `bpy` module (Blender as a Python module).

There is no Blender binary on the build machines, so tests and the demo install the built
extension zip the way a user would: into a fresh *user* extension repository, with
Blender's own installer (`bpy.ops.extensions.package_install_files`), enabled on install.
Import `bpy` only after setting BLENDER_USER_RESOURCES (the Makefile does), so nothing
touches the user's own Blender configuration."""

import os
import sys
import tempfile

REPO = "madder_test"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def default_zip():
    """The extension zip `make addon` builds here (Linux x64's), unless MADDER_ZIP names one."""
    return os.environ.get("MADDER_ZIP") or os.path.join(ROOT, "dist", "madder-0.1.0-linux_x64.zip")


def bpy_versions():
    """The Blenders of the test matrix, newest first (tests/bpy-versions.txt)."""
    with open(os.path.join(ROOT, "tests", "bpy-versions.txt")) as f:
        return [v for v in (line.split("#")[0].strip() for line in f) if v]


def crashes_at_exit():
    """True for a bpy module that crashes (SIGSEGV) when the interpreter exits once any
    property with a Python `update` callback has been registered, even after
    unregistering it. Madder's presets use update callbacks. Seen with bpy 4.2.23 from
    PyPI (a bare `FloatProperty(update=f)` on a PropertyGroup reproduces it); 4.5.15 and
    later exit cleanly. A Blender binary is not affected. (A crash has no feature to test
    for: this is the one version check outside `addon/compat.py`.)"""
    import bpy

    return bpy.app.version < (4, 5, 0)


def exit(code=0):
    """Ends the process with `code`: normally, or, where bpy would crash at exit, at once
    (`os._exit`, after flushing the output), so the exit status is the real one."""
    if crashes_at_exit():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


def install_extension(zip_path, repo=REPO):
    """Installs and enables the extension zip into user repository `repo` (created in a
    temporary folder unless it exists, e.g. Blender's own ``user_default``); returns the
    add-on's module name (``bl_ext.<repo>.madder``). Idempotent within one process."""
    import bpy

    module = f"bl_ext.{repo}.madder"
    if module in bpy.context.preferences.addons:
        return module
    if not os.path.isfile(zip_path):
        raise FileNotFoundError(f"extension zip not found: {zip_path} (run `make addon`)")
    repos = bpy.context.preferences.extensions.repos
    if not any(r.module == repo for r in repos):
        repos.new(name=repo, module=repo, custom_directory=tempfile.mkdtemp(prefix="madder-ext-"), source="USER")
    result = bpy.ops.extensions.package_install_files(filepath=zip_path, repo=repo, enable_on_install=True)
    if result != {"FINISHED"} or module not in bpy.context.preferences.addons:
        raise RuntimeError(f"installing {zip_path} failed: {result}")
    return module


def frame_mesh(obj):
    """(F, 3) uint32 triangles and (N, 3) float64 positions of `obj` as evaluated at the
    current frame (its whole modifier stack), for tests and benchmarks that read a cloth's
    motion."""
    import bpy
    import numpy as np

    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        tri = np.empty(3 * len(mesh.loop_triangles), dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", tri)
        co = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    return tri.reshape(-1, 3).astype(np.uint32), co.reshape(-1, 3)
