"""Fail on an import circle between the modules of the add-on or of the Rust core.

A module is a file: `addon/<name>.py` for the add-on, `rust/madder/src/<path>.rs` for the
core (`mod.rs` is its folder's module, `lib.rs` the crate root). Module A depends on B when
A's code names something B defines:

- Python: every `import`/`from ... import` inside the add-on, at top level or inside a
  function (an import deferred into a function still ties the two modules together; it only
  hides the circle from the interpreter);
- Rust: every `use` and every `crate::`/`super::`/`self::` path outside `#[cfg(test)]`
  items (unit tests may reach anywhere). A `mod` declaration or a `pub use` re-export is not
  a dependency; a path through a re-export depends on the module that defines the item.

The dependency graph must be acyclic: data types below, the algorithms that use them above.
Prints every strongly connected component with more than one module, and the edges inside
it with the line that makes each one, then exits 1; exits 0 when there is none.

    python .ci/import_circles.py [--graph] [--addon DIR] [--core DIR]

(`--graph` prints every edge too; `--addon`/`--core` check other trees, as the test does.)
"""

from __future__ import annotations

import ast
import re
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ADDON = ROOT / "addon"
CORE = ROOT / "rust" / "madder" / "src"

Edges = dict[str, dict[str, str]]  # module -> {dependency: where}


# ---------------------------------------------------------------------------------------
# The add-on


def addon_edges(addon: Path = ADDON) -> Edges:
    modules = {p.stem: p for p in addon.glob("*.py")}
    edges: Edges = defaultdict(dict)
    for name, path in sorted(modules.items()):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                if node.module is None:  # from . import x, y
                    targets = [a.name for a in node.names]
                else:  # from .x import y
                    targets = [node.module.split(".")[0]]
            elif isinstance(node, ast.ImportFrom) and node.level > 1:
                raise SystemExit(f"{path}:{node.lineno}: an import above the add-on")
            for target in targets:
                if target in modules and target != name:
                    edges[name].setdefault(target, f"{path.name}:{node.lineno}")
    return edges


# ---------------------------------------------------------------------------------------
# The core


RAW_STRING = re.compile(r'(?<!\w)r(#*)"')  # r"…", r#"…"#, not the end of an identifier
CHAR = re.compile(r"'(\\.[^']*|[^\\'])'")  # 'a', '\n', '\u{1F600}', not a lifetime 'a


def strip_rust(text: str) -> str:
    """Comments, strings and char literals blanked (lines kept), `#[cfg(test)]` items cut."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif m := RAW_STRING.match(text, i):
            end = '"' + m.group(1)
            j = text.find(end, i + len(m.group(0)))
            j = n if j < 0 else j + len(end)
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j + 1
        elif m := CHAR.match(text, i):
            out.append("' '")
            i += len(m.group(0))
        else:
            out.append(c)
            i += 1
    code = "".join(out)
    return cut_test_items(code)


def cut_test_items(code: str) -> str:
    """Blank every item under `#[cfg(test)]` (to its closing brace or semicolon)."""
    while (m := re.search(r"#\[cfg\(test\)\]", code)) is not None:
        i = m.end()
        depth = 0
        while i < len(code):
            if code[i] == "{":
                depth += 1
            elif code[i] == "}":
                depth -= 1
                if depth == 0:
                    i += 1
                    break
            elif code[i] == ";" and depth == 0:
                i += 1
                break
            i += 1
        code = code[: m.start()] + "\n" * code.count("\n", m.start(), i) + code[i:]
    return code


def core_modules(core: Path) -> dict[tuple[str, ...], Path]:
    modules = {}
    for path in core.rglob("*.rs"):
        parts = path.relative_to(core).with_suffix("").parts
        if parts == ("lib",):
            parts = ()
        elif parts[-1] == "mod":
            parts = parts[:-1]
        modules[parts] = path
    return modules


def expand_use(tree: str) -> list[list[str]]:
    """`a::{b, c::{d, e as f}, self}` into [[a,b], [a,c,d], [a,c,e], [a]]."""
    tree = re.sub(r"\s+as\s+\w+", "", tree)  # `x as y` names x
    tree = re.sub(r"\s+", "", tree)

    def parse(s: str, i: int, prefix: list[str]) -> tuple[list[list[str]], int]:
        paths: list[list[str]] = []
        seg = ""
        segs = list(prefix)
        while i < len(s):
            c = s[i]
            if s.startswith("::", i):
                segs.append(seg)
                seg = ""
                i += 2
            elif c == "{":
                while True:
                    sub, i = parse(s, i + 1, segs)
                    paths.extend(sub)
                    if s[i] == "}":
                        i += 1
                        break
                segs, seg = list(prefix), ""
            elif c in ",}":
                if seg:
                    paths.append(segs + [seg])
                elif segs != prefix:
                    paths.append(segs)
                return paths, i
            else:
                seg += c
                i += 1
        if seg:
            paths.append(segs + [seg])
        return paths, i

    paths, _ = parse(tree, 0, [])
    return [[p for p in path if p] for path in paths]


def core_edges(core: Path = CORE) -> Edges:
    modules = core_modules(core)
    code = {m: strip_rust(p.read_text()) for m, p in modules.items()}
    # What each module re-exports: name -> absolute path of the item it names.
    reexports: dict[tuple[str, ...], dict[str, list[str]]] = defaultdict(dict)
    uses: dict[tuple[str, ...], list[tuple[list[str], int]]] = defaultdict(list)

    def absolute(module: tuple[str, ...], path: list[str]) -> list[str] | None:
        if not path:
            return None
        head = path[0]
        if head == "crate":
            return path[1:]
        if head == "self":
            return list(module) + path[1:]
        if head == "super":
            base = list(module)
            while path and path[0] == "super":
                base, path = base[:-1], path[1:]
            return base + path
        if tuple(module) + (head,) in modules:  # a child module, named from its parent
            return list(module) + path
        return None  # std, glam, faer, rayon, ...

    for module, text in code.items():
        for m in re.finditer(r"\b(pub(\([^)]*\))?\s+)?use\s+([^;]+);", text):
            line = text.count("\n", 0, m.start()) + 1
            public = m.group(1) is not None
            for path in expand_use(m.group(3)):
                full = absolute(module, path)
                if full is None:
                    continue
                if public:
                    reexports[module][path[-1]] = full
                else:
                    uses[module].append((full, line))
        without_uses = re.sub(r"\buse\s+[^;]+;", lambda u: "\n" * u.group(0).count("\n"), text)
        for m in re.finditer(r"\b(?:crate|super|self)(?:::\w+)+", without_uses):
            full = absolute(module, m.group(0).split("::"))
            if full is not None:
                uses[module].append((full, text.count("\n", 0, m.start()) + 1))

    def defining_module(full: list[str], seen: int = 0) -> tuple[str, ...] | None:
        """The module that defines what `full` names, following re-exports."""
        for k in range(len(full), -1, -1):
            prefix = tuple(full[:k])
            if prefix in modules:
                rest = full[k:]
                if rest and rest[0] in reexports.get(prefix, {}) and seen < 16:
                    return defining_module(reexports[prefix][rest[0]] + rest[1:], seen + 1)
                return prefix
        return None

    edges: Edges = defaultdict(dict)
    for module, refs in uses.items():
        for full, line in refs:
            target = defining_module(full)
            if target is None or target == module:
                continue
            # A module naming an item of one of its own submodules through its path is a
            # use, as any other; only `mod` lines and re-exports are not.
            name = "::".join(target) or "crate"
            source = "::".join(module) or "crate"
            rel = modules[module].relative_to(core)
            edges[source].setdefault(name, f"{rel}:{line}")
    return edges


# ---------------------------------------------------------------------------------------


def circles(edges: Edges) -> list[list[str]]:
    """Tarjan's strongly connected components with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    nodes = sorted(set(edges) | {t for ts in edges.values() for t in ts})

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, {})):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in nodes:
        if v not in index:
            visit(v)
    return found


def main(argv: list[str]) -> int:
    show_graph = "--graph" in argv
    addon = Path(argv[argv.index("--addon") + 1]) if "--addon" in argv else ADDON
    core = Path(argv[argv.index("--core") + 1]) if "--core" in argv else CORE
    failed = False
    for label, edges in (("add-on", addon_edges(addon)), ("core", core_edges(core))):
        if show_graph:
            for source in sorted(edges):
                for target, where in sorted(edges[source].items()):
                    print(f"{label}: {source} -> {target}   ({where})")
        found = circles(edges)
        for comp in found:
            failed = True
            print(f"{label}: import circle between {', '.join(comp)}:")
            members = set(comp)
            for source in comp:
                for target, where in sorted(edges.get(source, {}).items()):
                    if target in members:
                        print(f"    {source} -> {target}   ({where})")
        if not found:
            n = len(set(edges) | {t for ts in edges.values() for t in ts})
            print(f"{label}: no import circle ({n} modules)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
