"""The type stubs (`_fogplanes.pyi`) say what the native module really takes: every function and
method of the stub exists in the module with the same parameters, in the same order, with the
same defaults, and every public function of the module has a stub. A keyword added to the Rust
signature and not to the stub (or the reverse) fails here."""

import ast
import inspect

import fogplanes._fogplanes as native
import pytest

from helpers import ROOT

STUB = ROOT / "crates" / "python" / "python" / "fogplanes" / "_fogplanes.pyi"


def _default(node: ast.expr | None) -> object:
    if node is None:
        return inspect.Parameter.empty
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.Tuple):
        return tuple(_default(e) for e in node.elts)
    return ast.unparse(node)


def _stub_parameters(f: ast.FunctionDef) -> list[tuple[str, str, object]]:
    """(name, kind, default) of each parameter, as inspect names kinds."""
    a = f.args
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    out = [(p.arg, "positional", _default(d)) for p, d in zip(positional, defaults)]
    if a.vararg:
        out.append((a.vararg.arg, "*", inspect.Parameter.empty))
    out += [(p.arg, "keyword", _default(d)) for p, d in zip(a.kwonlyargs, a.kw_defaults)]
    if a.kwarg:
        out.append((a.kwarg.arg, "**", inspect.Parameter.empty))
    return out


def _real_parameters(obj: object) -> list[tuple[str, str, object]]:
    kinds = {
        inspect.Parameter.POSITIONAL_ONLY: "positional",
        inspect.Parameter.POSITIONAL_OR_KEYWORD: "positional",
        inspect.Parameter.VAR_POSITIONAL: "*",
        inspect.Parameter.KEYWORD_ONLY: "keyword",
        inspect.Parameter.VAR_KEYWORD: "**",
    }
    return [(p.name, kinds[p.kind], p.default) for p in inspect.signature(obj).parameters.values()]


def _comparable(params: list[tuple[str, str, object]]) -> list[tuple[str, object]]:
    """What both sides must agree on: the names and defaults, keyword-only and positional alike
    (the native module cannot mark keyword-only parameters, the stub does); `**kwargs` by kind,
    since the stub may name it after what it forwards."""
    return [("**", None) if kind == "**" else (name, default) for name, kind, default in params]


def _stub_functions() -> dict[str, list[ast.FunctionDef]]:
    """Every function of the stub (overloads together) and every method, as Class.method."""
    tree = ast.parse(STUB.read_text())
    out: dict[str, list[ast.FunctionDef]] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            out.setdefault(node.name, []).append(node)
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not item.name.startswith("__"):
                    decorators = {ast.unparse(d) for d in item.decorator_list}
                    if "property" not in decorators:
                        out.setdefault(f"{node.name}.{item.name}", []).append(item)
    return out


STUBS = _stub_functions()


def _native(path: str) -> object:
    obj: object = native
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


@pytest.mark.parametrize("name", sorted(STUBS))
def test_every_stub_matches_the_native_signature(name: str) -> None:
    real = _native(name)
    real_params = _real_parameters(real)
    if "." in name and real_params and real_params[0][0] == "self":
        real_params = real_params[1:]
    for f in STUBS[name]:
        stub = _stub_parameters(f)
        if stub and stub[0][0] in ("self", "cls"):
            stub = stub[1:]
        if any(ast.unparse(d) == "overload" for d in f.decorator_list):
            # An overload narrows the signature (a literal return_stats, say): its parameters
            # are the real ones, some perhaps without their defaults.
            names = [p[0] for p in _comparable(stub)]
            assert names == [p[0] for p in _comparable(real_params)], f"{name}: {names}"
            continue
        assert _comparable(stub) == _comparable(real_params), f"{name}: stub {stub} vs native {real_params}"


def test_every_public_function_has_a_stub() -> None:
    public = {n for n in dir(native) if not n.startswith("_") and inspect.isbuiltin(getattr(native, n))}
    missing = public - set(STUBS)
    assert not missing, f"functions of the native module without a stub: {sorted(missing)}"
