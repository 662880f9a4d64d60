"""Stages the extension for Blender's `extension build --split-platforms`: a copy of
`addon/` whose manifest lists, in `platforms` and `wheels`, exactly the wheels present in
`addon/wheels/` (here Linux x64's, built by `make wheel`; in the release workflow the four
platforms' wheels, built by maturin on their own runners).

    python .ci/stage_extension.py --addon addon --out target/extension

Blender then packs one zip per platform, each with its own wheel. A wheel whose platform
tag Blender has no name for, or a platform with two wheels, is an error: a zip must never
ship without its native module or with two of them."""

import argparse
import pathlib
import re
import shutil
import sys
import tomllib

# Blender's platform names (the manifest's `platforms`) by a wheel's platform tag
PLATFORMS = (
    (re.compile(r"^(many|musl)linux_\d+_\d+_x86_64$|^manylinux\d*_x86_64$"), "linux-x64"),
    (re.compile(r"^(many|musl)linux_\d+_\d+_aarch64$"), "linux-arm64"),
    (re.compile(r"^win_amd64$"), "windows-x64"),
    (re.compile(r"^win_arm64$"), "windows-arm64"),
    (re.compile(r"^macosx_\d+_\d+_arm64$"), "macos-arm64"),
    (re.compile(r"^macosx_\d+_\d+_x86_64$"), "macos-x64"),
)


def platform_of(wheel):
    """Blender's platform name for a wheel file name (PEP 427: the last tag is the
    platform's; a compressed tag set `a.b` names several, all of one Blender platform)."""
    stem = wheel[: -len(".whl")] if wheel.endswith(".whl") else wheel
    parts = stem.split("-")
    if len(parts) < 5:
        raise ValueError(f"{wheel}: not a wheel file name (name-version-python-abi-platform.whl)")
    names = set()
    for tag in parts[-1].split("."):
        name = next((n for pattern, n in PLATFORMS if pattern.match(tag)), None)
        if name is None:
            raise ValueError(f"{wheel}: platform tag {tag!r} is none Blender packs")
        names.add(name)
    if len(names) != 1:
        raise ValueError(f"{wheel}: its tags name several Blender platforms {sorted(names)}")
    return names.pop()


def manifest_lines(wheels):
    """The manifest's `platforms` and `wheels` lines for these wheel file names."""
    by_platform = {}
    for w in sorted(wheels):
        p = platform_of(w)
        if p in by_platform:
            raise ValueError(f"two wheels for {p}: {by_platform[p]} and {w}")
        by_platform[p] = w
    if not by_platform:
        raise ValueError("no wheel in addon/wheels (run `make wheel`)")
    platforms = ", ".join(f'"{p}"' for p in sorted(by_platform))
    listed = ", ".join(f'"./wheels/{by_platform[p]}"' for p in sorted(by_platform))
    return f"platforms = [{platforms}]", f"wheels = [{listed}]"


def rewrite(manifest, wheels):
    """`manifest` (the TOML text) with its `platforms` and `wheels` lines replaced."""
    platforms, listed = manifest_lines(wheels)
    out, seen = [], set()
    for line in manifest.splitlines():
        key = line.split("=", 1)[0].strip() if "=" in line and not line.lstrip().startswith("#") else None
        if key in ("platforms", "wheels") and key not in seen:
            seen.add(key)
            out.append(platforms if key == "platforms" else listed)
        else:
            out.append(line)
    missing = {"platforms", "wheels"} - seen
    if missing:
        raise ValueError(f"the manifest has no top-level {' or '.join(sorted(missing))} line to generate")
    text = "\n".join(out) + "\n"
    tomllib.loads(text)  # still valid TOML
    return text


def stage(addon, out):
    addon, out = pathlib.Path(addon), pathlib.Path(out)
    wheels = sorted(p.name for p in (addon / "wheels").glob("*.whl"))
    text = rewrite((addon / "blender_manifest.toml").read_text(), wheels)
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(addon, out, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".*"))
    (out / "blender_manifest.toml").write_text(text)
    return text


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--addon", default="addon", help="the extension's source folder")
    ap.add_argument("--out", required=True, help="the staging folder (replaced)")
    args = ap.parse_args(argv)
    try:
        text = stage(args.addon, args.out)
    except ValueError as e:
        sys.exit(f"stage_extension: {e}")
    for line in text.splitlines():
        if line.startswith(("platforms", "wheels")):
            print(f"stage_extension: {line}")


if __name__ == "__main__":
    main()
