"""The release staging (`.ci/stage_extension.py`): the manifest's `platforms` and `wheels`
generated from the wheels present, as the release workflow stages the four platforms'
wheels and `make addon` stages Linux x64's alone."""

import importlib.util
import pathlib
import tomllib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("stage_extension", ROOT / ".ci" / "stage_extension.py")
stage_extension = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(stage_extension)

# maturin's abi3 wheel names on the workflow's four runners
WHEELS = {
    "linux-x64": "madder-0.1.0-cp311-abi3-manylinux_2_28_x86_64.whl",
    "windows-x64": "madder-0.1.0-cp311-abi3-win_amd64.whl",
    "macos-arm64": "madder-0.1.0-cp311-abi3-macosx_11_0_arm64.whl",
    "macos-x64": "madder-0.1.0-cp311-abi3-macosx_10_12_x86_64.whl",
}


@pytest.mark.parametrize("platform", sorted(WHEELS))
def test_each_wheel_maps_to_blenders_platform_name(platform):
    assert stage_extension.platform_of(WHEELS[platform]) == platform


def test_a_compressed_tag_set_of_one_platform_is_that_platform():
    name = "madder-0.1.0-cp311-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl"
    assert stage_extension.platform_of(name) == "linux-x64"


@pytest.mark.parametrize("name, why", [
    ("madder-0.1.0-cp311-abi3-linux_x86_64.whl", "platform tag 'linux_x86_64'"),  # not manylinux: no Blender name
    ("madder-0.1.0-py3-none-any.whl", "platform tag 'any'"),
    ("madder-0.1.0.whl", "not a wheel file name"),
])
def test_a_wheel_blender_cannot_place_is_refused(name, why):
    with pytest.raises(ValueError, match=why):
        stage_extension.platform_of(name)


def test_the_committed_manifest_is_rewritten_for_the_four_wheels():
    manifest = (ROOT / "addon" / "blender_manifest.toml").read_text()
    text = stage_extension.rewrite(manifest, list(WHEELS.values()))
    data = tomllib.loads(text)
    assert data["platforms"] == sorted(WHEELS)
    assert data["wheels"] == [f"./wheels/{WHEELS[p]}" for p in sorted(WHEELS)]
    # everything else kept, line for line
    rest = [line for line in manifest.splitlines() if not line.startswith(("platforms", "wheels"))]
    assert [line for line in text.splitlines() if not line.startswith(("platforms", "wheels"))] == rest


def test_one_wheel_gives_one_platform():
    manifest = (ROOT / "addon" / "blender_manifest.toml").read_text()
    data = tomllib.loads(stage_extension.rewrite(manifest, [WHEELS["linux-x64"]]))
    assert data["platforms"] == ["linux-x64"]
    assert data["wheels"] == [f"./wheels/{WHEELS['linux-x64']}"]


def test_two_wheels_for_one_platform_or_none_at_all_are_refused():
    manifest = (ROOT / "addon" / "blender_manifest.toml").read_text()
    other = "madder-0.1.0-cp311-abi3-manylinux_2_17_x86_64.whl"
    with pytest.raises(ValueError, match="two wheels for linux-x64"):
        stage_extension.rewrite(manifest, [WHEELS["linux-x64"], other])
    with pytest.raises(ValueError, match="no wheel"):
        stage_extension.rewrite(manifest, [])


def test_a_manifest_without_the_lines_is_refused():
    with pytest.raises(ValueError, match="no top-level platforms or wheels"):
        stage_extension.rewrite('id = "madder"\n', [WHEELS["linux-x64"]])


def test_stage_copies_the_addon_with_its_wheels_and_the_generated_manifest(tmp_path):
    addon = tmp_path / "addon"
    (addon / "wheels").mkdir(parents=True)
    (addon / "__pycache__").mkdir()
    (addon / "__pycache__" / "x.pyc").write_bytes(b"")
    (addon / "__init__.py").write_text("")
    (addon / "blender_manifest.toml").write_text((ROOT / "addon" / "blender_manifest.toml").read_text())
    for w in WHEELS.values():
        (addon / "wheels" / w).write_bytes(b"")
    out = tmp_path / "stage"
    (out / "stale").mkdir(parents=True)  # an earlier staging is replaced whole
    stage_extension.stage(addon, out)
    assert sorted(p.name for p in out.iterdir()) == ["__init__.py", "blender_manifest.toml", "wheels"]
    assert sorted(p.name for p in (out / "wheels").iterdir()) == sorted(WHEELS.values())
    assert tomllib.loads((out / "blender_manifest.toml").read_text())["platforms"] == sorted(WHEELS)
    # the source manifest is left as committed
    assert tomllib.loads((addon / "blender_manifest.toml").read_text())["platforms"] == ["linux-x64"]
