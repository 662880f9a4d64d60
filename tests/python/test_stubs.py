"""The type stubs `madder/_core.pyi` against the native module they describe.

Every class, method, property, function and constant of `madder._core` is in the stub and
the other way round, and where pyo3 gives a signature (`__text_signature__`) the stub's
parameters have the same names, kinds (positional or keyword-only) and defaults (pyo3
writes `...` for a default that is not a literal; the stub may then give the value). So a
binding change without a stub change fails here."""

import ast
import inspect
import pathlib

import pytest

from madder import _core

STUB = pathlib.Path(_core.__file__).with_name("_core.pyi")
# what every pyo3 class or module has without the binding asking for it
IMPLICIT = {"__doc__", "__module__", "__dict__", "__weakref__", "__qualname__", "__name__", "__loader__",
            "__package__", "__spec__", "__file__", "__all__", "__builtins__", "__cached__"}


def stub_tree():
    return ast.parse(STUB.read_text(encoding="utf-8"), filename=str(STUB))


def private(name):
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def stub_module():
    """Top-level names of the stub: {name: ast node}, leaving out its private aliases."""
    names = {}
    for node in stub_tree().body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names[node.target.id] = node
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Name):
                    names[t.id] = node
    return {k: v for k, v in names.items() if not private(k)}


def stub_members(cls):
    """{name: ("property" | "method", node)} of a stub class (a setter is its property)."""
    members = {}
    for node in cls.body:
        if isinstance(node, ast.FunctionDef):
            decorators = {ast.unparse(d) for d in node.decorator_list}
            if "property" in decorators or any(d.endswith(".setter") for d in decorators):
                members.setdefault(node.name, ("property", node))
            else:
                members[node.name] = ("method", node)
    return members


def real_module():
    return {k: v for k, v in vars(_core).items() if k not in IMPLICIT and not private(k)}


def real_members(cls):
    """{name: ("property" | "method", object)} the binding defines on `cls`."""
    members = {}
    for k, v in vars(cls).items():
        if k in IMPLICIT or private(k):
            continue
        if inspect.isgetsetdescriptor(v) or isinstance(v, property):
            members[k] = ("property", v)
        elif callable(v) or isinstance(v, (staticmethod, classmethod)):
            members[k] = ("method", v)
    return members


def stub_parameters(fn, drop_first):
    """[(name, kind, default source or None)] of a stub function."""
    a = fn.args
    out = []
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    for arg, d in zip(positional, defaults, strict=True):
        out.append((arg.arg, "positional", None if d is None else ast.unparse(d)))
    if a.vararg:
        out.append((a.vararg.arg, "*args", None))
    for arg, d in zip(a.kwonlyargs, a.kw_defaults, strict=True):
        out.append((arg.arg, "keyword", None if d is None else ast.unparse(d)))
    if a.kwarg:
        out.append((a.kwarg.arg, "**kwargs", None))
    return out[1:] if drop_first else out


KINDS = {
    inspect.Parameter.POSITIONAL_ONLY: "positional",
    inspect.Parameter.POSITIONAL_OR_KEYWORD: "positional",
    inspect.Parameter.VAR_POSITIONAL: "*args",
    inspect.Parameter.KEYWORD_ONLY: "keyword",
    inspect.Parameter.VAR_KEYWORD: "**kwargs",
}


def real_parameters(obj):
    """[(name, kind, default repr or None)] from pyo3's text signature, or None if it has
    none. A default pyo3 could not spell is `...`."""
    if getattr(obj, "__text_signature__", None) is None:
        return None
    sig = inspect.signature(obj)
    out = []
    for p in sig.parameters.values():
        default = None if p.default is inspect.Parameter.empty else repr(p.default)
        out.append((p.name, KINDS[p.kind], default))
    return out


def same_parameters(where, stub, real):
    assert [(n, k) for n, k, _ in stub] == [(n, k) for n, k, _ in real], f"{where}: parameters differ"
    for (name, _, s), (_, _, r) in zip(stub, real, strict=True):
        assert (s is None) == (r is None), f"{where}: {name} has a default in one only"
        if r not in (None, "Ellipsis"):
            assert ast.literal_eval(s) == ast.literal_eval(r), f"{where}: default of {name}: {s} vs {r}"


def test_the_stub_ships_with_its_marker():
    assert STUB.is_file()
    assert STUB.with_name("py.typed").is_file()


def test_module_names_agree():
    assert set(stub_module()) == set(real_module())


def test_constants_agree():
    stub, real = stub_module(), real_module()
    constants = [k for k, v in real.items() if not callable(v)]
    assert {"__version__", "DEFAULT_DIFFUSION", "DEFAULT_SOLUTE_COLOR", "DEGENERATE_UV_REL"} <= set(constants)
    for name in constants:
        assert isinstance(stub[name], ast.AnnAssign), f"{name} is a constant in the binding"


@pytest.mark.parametrize("name", sorted(k for k, v in real_module().items() if inspect.isclass(v)))
def test_class_agrees(name):
    cls, stub = getattr(_core, name), stub_module()[name]
    assert isinstance(stub, ast.ClassDef), f"{name} is a class in the binding"
    if issubclass(cls, BaseException):
        return  # an exception adds nothing of its own
    members, real = stub_members(stub), real_members(cls)
    assert set(members) - {"__new__"} == set(real) - {"__new__"}, f"{name}: members differ"
    for member, (kind, node) in members.items():
        if member == "__new__":
            continue
        assert real[member][0] == kind, f"{name}.{member} is a {real[member][0]} in the binding"
        if kind == "method":
            params = real_parameters(real[member][1])
            if params is not None:
                same_parameters(f"{name}.{member}", stub_parameters(node, True), params[1:])
    # the constructor: pyo3 puts #[new]'s signature on the class
    assert ("__new__" in members) == (cls.__text_signature__ is not None), f"{name}: constructor"
    if "__new__" in members:
        same_parameters(f"{name}()", stub_parameters(members["__new__"][1], True), real_parameters(cls))


@pytest.mark.parametrize("name", sorted(k for k, v in real_module().items() if inspect.isbuiltin(v)))
def test_function_agrees(name):
    stub = stub_module()[name]
    assert isinstance(stub, ast.FunctionDef), f"{name} is a function in the binding"
    params = real_parameters(getattr(_core, name))
    assert params is not None, f"{name}: pyo3 gives functions a signature"
    same_parameters(name, stub_parameters(stub, False), params)

