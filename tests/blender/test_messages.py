"""Messages and UI (issue 10, item 9): every setting has a tooltip, the vertex group and
the Madder Source object have different names, a bake without an active object says so,
and the command line takes negative frames."""

import os
import shutil
import sys

import bpy
import pytest
from conftest import ADDON, FIXTURES

import madder

cli = sys.modules[ADDON + ".cli"]
bake = sys.modules[ADDON + ".bake"]


def madder_rna_structs():
    """Every property group and operator the extension's modules define, with its RNA."""
    out = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith(ADDON + "."):
            continue
        for cls in vars(module).values():
            if isinstance(cls, type) and issubclass(cls, bpy.types.PropertyGroup):
                out[cls.__name__] = cls.bl_rna
            elif isinstance(cls, type) and issubclass(cls, bpy.types.Operator):
                category, name = cls.bl_idname.split(".")
                out[cls.__name__] = getattr(getattr(bpy.ops, category), name).get_rna_type()
    return sorted(out.items())


def test_every_setting_has_a_tooltip(addon):
    checked = 0
    for owner, rna in madder_rna_structs():
        for prop in rna.properties:
            if prop.identifier in ("rna_type", "name"):  # Blender's own, on every struct
                continue
            checked += 1
            assert prop.description.strip(), f"{owner}.{prop.identifier} has no description"
    names = [owner for owner, _ in madder_rna_structs()]
    for expected in ("MadderObjectSettings", "MadderSourceSettings", "MadderFabric", "MadderMotionSettings",
                     "MadderSplashSettings", "MADDER_OT_bake", "MADDER_OT_compress_motion",
                     "MADDER_OT_decompress_motion"):
        assert expected in names  # the walk really found the settings
    assert checked > 40


def test_spill_group_is_not_called_source(addon):
    props = dict(madder_rna_structs())["MadderObjectSettings"].properties
    assert props["source_group"].name == "Spill Group"
    names = [p.name for p in props]
    assert not [n for n in names if "Source" in n], names  # "Source" is the Madder Source object


def test_missing_spill_group_says_which_group(open_fixture):
    open_fixture("flag.blend")
    flag = bpy.data.objects["Flag"]
    bpy.context.view_layer.objects.active = flag
    flag.madder.source_group = "gone"
    with pytest.raises(RuntimeError, match="has no vertex group 'gone' \\(its Spill Group\\)"):
        bpy.ops.madder.bake()
    flag.madder.source_group = ""
    with pytest.raises(RuntimeError, match="choose a Spill Group"):
        bpy.ops.madder.bake()


def test_bake_without_an_active_object_says_so(open_fixture):
    open_fixture("flag.blend")
    bpy.context.view_layer.objects.active = None
    with pytest.raises(RuntimeError) as e:
        bpy.ops.madder.bake()
    msg = str(e.value)
    assert "no active object" in msg and "is nothing" not in msg, msg


@pytest.mark.parametrize(
    "text, frames",
    [("1-250", (1, 250)), ("-5-3", (-5, 3)), ("-5--1", (-5, -1)), ("3", (3, 3)), ("-5", (-5, -5)), ("0-0", (0, 0))],
)
def test_frame_ranges_may_be_negative(text, frames):
    assert cli._frame_range(text) == frames


@pytest.mark.parametrize("text", ["1-", "a-b", "1-2-3", "--5", "3-1"])
def test_bad_frame_ranges_are_refused(text):
    with pytest.raises(Exception, match=text if text != "3-1" else "empty frame range 3-1"):
        cli._frame_range(text)


@pytest.mark.parametrize("argv", [["--frames", "-2-3"], ["--frames=-2-3"]])
def test_command_bakes_negative_frames(tmp_path, capsys, argv, addon):
    path = tmp_path / "flag.blend"
    shutil.copyfile(os.path.join(FIXTURES, "flag.blend"), path)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    bpy.data.objects["Flag"].madder.source_group = "stain_source"
    bpy.ops.wm.save_mainfile()
    assert cli.main(["bake", str(path), "--object", "Flag", "--no-save", *argv]) == 0, capsys.readouterr().err
    captured = capsys.readouterr()
    # the default (not ticked) Image Sequence cannot number frames before 0: skipped, with a warning
    said = captured.out + captured.err
    assert "starts before frame 0" in said and "vertex colors only" in said
    r = madder.CacheReader(str(tmp_path / "madder_cache" / "Flag.madder"))
    assert (r.first_frame, r.last_frame) == (-2, 3)
