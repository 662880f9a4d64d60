"""Real Blender (the `bpy` module from PyPI) with the Madder extension installed from the
built zip into a fresh user repository, exactly as a user installs it."""

import os
import shutil
import sys
import tempfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FIXTURES = os.path.join(ROOT, "blend_fixtures")
sys.path.insert(0, FIXTURES)

# A fresh user resource folder per session: extensions (and the wheels they unpack into
# <user>/extensions/.local) are installed anew, never picked up from an earlier run.
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="madder-blender-user-")

import bpy  # noqa: E402

import harness  # noqa: E402

ZIP = os.environ.get("MADDER_ZIP") or os.path.join(ROOT, "dist", "madder-0.1.0.zip")

# Installed before the test modules are imported: `import madder` in a test resolves to the
# wheel the extension brought, which exists only once the extension is installed.
ADDON = harness.install_extension(ZIP)


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


def make_active(obj):
    bpy.context.view_layer.objects.active = obj
    return obj
