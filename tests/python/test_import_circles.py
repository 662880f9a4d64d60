"""`.ci/import_circles.py` (run by `make lint`) on small trees written here: it must find a
circle closed by an import inside a function, a circle through a Rust re-export or a
`super::` path, and must not count `mod` lines, `pub use` re-exports, `#[cfg(test)]`
items, comments or strings."""

import importlib.util
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / ".ci" / "import_circles.py"
spec = importlib.util.spec_from_file_location("import_circles", SCRIPT)
ic = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ic)


def write(root, files):
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_an_import_inside_a_function_closes_an_addon_circle(tmp_path):
    addon = write(tmp_path / "addon", {
        "a.py": "from . import b\n",
        "b.py": "def f():\n    from . import a\n    return a\n",
        "c.py": "from .a import thing\nimport os\n",
    })
    edges = ic.addon_edges(addon)
    assert edges["b"] == {"a": "b.py:2"}
    assert ic.circles(edges) == [["a", "b"]]


def test_an_addon_without_circles_passes(tmp_path):
    addon = write(tmp_path / "addon", {"a.py": "from . import b\n", "b.py": "from .c import x\n", "c.py": "x = 1\n"})
    assert ic.circles(ic.addon_edges(addon)) == []


CORE_OK = {
    "lib.rs": "pub mod data;\npub mod algo;\npub use algo::run;\n",
    "data/mod.rs": "mod types;\npub use types::Field;\n",
    "data/types.rs": "/// uses crate::algo::run in a comment\npub struct Field;\n"
                     "const S: &str = \"crate::algo::run\";\n"
                     "const R: &str = r#\"a \"quoted\" crate::algo::run\"#;\n"
                     "const C: char = '\"'; fn f<'a>(x: &'a str) -> &'a str { x }\n"
                     "#[cfg(test)]\nmod tests {\n    use crate::algo::run;\n}\n",
    "algo.rs": "use crate::data::Field;\npub fn run(_: Field) {}\n",
}


def test_re_exports_mod_lines_tests_comments_and_strings_are_not_dependencies(tmp_path):
    core = write(tmp_path / "src", CORE_OK)
    edges = ic.core_edges(core)
    # `crate::data::Field` resolves through the re-export to the module that defines it
    assert dict(edges) == {"algo": {"data::types": "algo.rs:1"}}
    assert ic.circles(edges) == []


def test_a_super_path_through_a_re_export_closes_a_core_circle(tmp_path):
    files = dict(CORE_OK)
    files["data/types.rs"] = "pub struct Field;\nfn f() { let _ = crate::run; }\n"
    core = write(tmp_path / "src", files)
    edges = ic.core_edges(core)
    assert edges["data::types"] == {"algo": "data/types.rs:2"}
    assert ic.circles(edges) == [["algo", "data::types"]]

    files = dict(CORE_OK)
    files["data/mod.rs"] = "mod types;\nmod more;\npub use types::Field;\n"
    files["data/types.rs"] = "use super::more::{Other as O, helper};\npub struct Field;\n"
    files["data/more.rs"] = "use super::Field;\npub struct Other;\npub fn helper() {}\n"
    edges = ic.core_edges(write(tmp_path / "src2", files))
    assert ic.circles(edges) == [["data::more", "data::types"]]


def test_the_script_exits_1_naming_the_circle_and_0_without(tmp_path):
    addon = write(tmp_path / "addon", {"a.py": "from . import b\n", "b.py": "from . import a\n"})
    core = write(tmp_path / "src", CORE_OK)
    run = subprocess.run([sys.executable, SCRIPT, "--addon", addon, "--core", core], capture_output=True, text=True)
    assert run.returncode == 1
    assert "add-on: import circle between a, b" in run.stdout
    assert "a -> b   (a.py:1)" in run.stdout
    (addon / "b.py").write_text("x = 1\n")
    run = subprocess.run([sys.executable, SCRIPT, "--addon", addon, "--core", core], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout
