"""The layout's rules (ARCHITECTURE.md, issue 24), read from the source with Python's ast module.

1. Only the simulator's own modules, learning, the demo, the benchmarks and the tests import
   ``vrecho.sim``: the method takes what it hears as an argument, the simulator supplies it.
   Nor does the method import anything by name at run time (``importlib.import_module``,
   ``__import__``): the commands find the simulator as a plugin (an entry point).
2. No import cycles between the packages' modules; imports at the top of a module, except heavy
   libraries kept lazy where start-up time matters (torch, open3d, pxr, av, and the others of
   :data:`HEAVY` measured at half a second or more to import on the 2-core machine) and the
   project's own torch-bound modules (those that import torch when imported), each with a
   comment on its line.
3. No module of the packages over 700 lines; no private name imported from another module
   (packages, tests and benchmarks alike).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("vrecho", "localization", "usd_export", "demo")
SIM_ALLOWED = ("vrecho/sim/", "vrecho/learn/", "demo/", "benchmarks/", "tests/")
HEAVY = {
    "torch": 1.7, "open3d": 1.2, "pxr": 0.2, "av": 0.2,  # the four
    "pyroomacoustics": 1.4, "sklearn": 1.7, "matplotlib": 0.8, "meshcat": 0.6, "zarr": 0.5,
    "sounddevice": 0.06,  # quick, but it loads PortAudio, a system library only `vrecho watch` needs
    "ray": 1.0,  # an extra (pip install 'vrecho[ray]'): only with --ray
}
"""Libraries that may be imported inside a function, with their import time in seconds (``python3
-X importtime``, 2026-11-23, the 2-core machine; pxr and av are the issue's own choice; sounddevice
for the system library it loads)."""
MAX_LINES = 700


def _name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _files(*folders: str) -> list[Path]:
    return sorted(p for f in folders for p in (ROOT / f).rglob("*.py"))


MODULES = {_name(p): p for p in _files(*PACKAGES)}
TREES = {p: ast.parse(p.read_text(), str(p)) for p in _files(*PACKAGES, "tests", "benchmarks")}


def _imports(path: Path):
    """(statement, imported module names, at the module's top level) of every import in ``path``:
    ``from a import b`` names ``a.b`` where that is a module of the packages, else ``a``."""
    tree = TREES[path]
    top = {id(n) for n in tree.body}
    for n in tree.body:  # `if TYPE_CHECKING:` blocks are the module's top level too
        if isinstance(n, ast.If):
            top |= {id(m) for m in n.body}
    name = _name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield node, [a.name for a in node.names], id(node) in top
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
            yield node, sorted(set(targets)), id(node) in top


def test_the_method_never_imports_the_simulator():
    offenders = []
    for path in TREES:
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(SIM_ALLOWED):
            continue
        for node, targets, _ in _imports(path):
            if any(t == "vrecho.sim" or t.startswith("vrecho.sim.") for t in targets):
                offenders.append(f"{rel}:{node.lineno}")
        for node in ast.walk(TREES[path]):
            if isinstance(node, ast.Call):
                f = node.func
                called = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if called in ("import_module", "__import__"):
                    offenders.append(f"{rel}:{node.lineno} (imports by name)")
    assert not offenders, offenders


def _graph() -> dict[str, set[str]]:
    graph = {m: set() for m in MODULES}
    for m, path in MODULES.items():
        for _, targets, _ in _imports(path):
            graph[m] |= {t for t in targets if t in MODULES and t != m}
    return graph


def test_no_import_cycles():
    graph = _graph()
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == "open":
                cycles.append(stack[stack.index(n):] + [n])
            elif n not in state:
                visit(n)
        stack.pop()
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert not cycles, cycles


def _torch_bound() -> set[str]:
    """The packages' modules that import torch when they are imported."""
    return {m for m, path in MODULES.items()
            if any(top and any(t.split(".")[0] == "torch" for t in targets) for _, targets, top in _imports(path))}


def test_imports_at_the_top_except_heavy_ones_with_a_reason():
    torch_bound = _torch_bound()
    assert {"vrecho.models", "vrecho.classifier"} <= torch_bound  # the rule below rests on these
    offenders = []
    for m, path in MODULES.items():
        lines = path.read_text().splitlines()
        for node, targets, top in _imports(path):
            if top:
                continue
            heavy = all(t.split(".")[0] in HEAVY or t in torch_bound for t in targets)
            commented = "#" in lines[node.lineno - 1]
            if not (heavy and commented):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}"
                                 + ("" if heavy else " (not heavy)") + ("" if commented else " (no comment)"))
    assert not offenders, "\n".join(offenders)


def test_no_module_is_over_700_lines():
    long = {m: n for m, p in MODULES.items() if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_no_private_name_is_imported_from_another_module():
    offenders = []
    for path in TREES:
        for node, _, _ in _imports(path):
            if isinstance(node, ast.ImportFrom) and node.module != "__future__":
                private = [a.name for a in node.names if a.name.startswith("_") and not a.name.endswith("__")]
                if private:
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {private}")
    assert not offenders, offenders


@pytest.mark.parametrize("rule", [test_the_method_never_imports_the_simulator, test_no_import_cycles])
def test_the_rules_catch_what_they_are_for(rule, monkeypatch):
    """Each rule fails on a module that breaks it (the checks are not vacuous)."""
    bad = ROOT / "vrecho" / "capture" / "media.py"
    source = "from ..sim import scenes\n" if rule is test_the_method_never_imports_the_simulator \
        else "from .pipeline import analyse\n"  # pipeline imports media: a cycle
    monkeypatch.setitem(TREES, bad, ast.parse(source + bad.read_text()))
    with pytest.raises(AssertionError):
        rule()


def _public_calls():
    """(module path, qualified name, node, class node or None) of every public function and
    method of the packages (``__call__`` included; properties and ``__init__`` apart)."""
    for path in MODULES.values():
        def walk(body, cls=None):
            for n in body:
                if isinstance(n, ast.ClassDef) and not n.name.startswith("_"):
                    yield from walk(n.body, n)
                elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                        and (not n.name.startswith("_") or n.name == "__call__"):
                    if not any(getattr(d, "id", getattr(d, "attr", "")) in ("property", "cached_property", "setter")
                               for d in n.decorator_list):
                        yield path, (f"{cls.name}." if cls else "") + n.name, n, cls
        yield from walk(TREES[path].body)


def _section(doc: str, *names: str) -> bool:
    lines = doc.splitlines()
    return any(a.strip() in names and set(b.strip()) == {"-"} for a, b in zip(lines, lines[1:]))


def test_public_calls_have_numpydoc_docstrings():
    """Rule 4: a public call documents its parameters (a constructor's in its class docstring) and
    what it returns, numpydoc style."""
    missing = []
    for path, name, node, cls in _public_calls():
        doc = ast.get_docstring(node) or ""
        params = [a.arg for a in node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                  if a.arg not in ("self", "cls")]
        returns = any(isinstance(n, ast.Return) and n.value is not None for n in ast.walk(node)) \
            or any(isinstance(n, (ast.Yield, ast.YieldFrom)) for n in ast.walk(node))
        where = f"{path.relative_to(ROOT)}:{node.lineno} {name}"
        if not doc:
            missing.append(f"{where}: no docstring")
        if params and not _section(doc, "Parameters"):
            missing.append(f"{where}: no Parameters")
        if returns and not _section(doc, "Returns", "Yields"):
            missing.append(f"{where}: no Returns")
    for path in MODULES.values():  # a class documents its constructor's parameters, or its fields
        for n in TREES[path].body:
            if isinstance(n, ast.ClassDef) and not n.name.startswith("_"):
                init = next((m for m in n.body if isinstance(m, ast.FunctionDef) and m.name == "__init__"), None)
                fields = [m for m in n.body if isinstance(m, ast.AnnAssign)]
                args = [] if init is None else [a for a in init.args.args[1:] + init.args.kwonlyargs]
                doc = ast.get_docstring(n) or ""
                if (args or fields) and not _section(doc, "Parameters", "Attributes"):
                    missing.append(f"{path.relative_to(ROOT)}:{n.lineno} class {n.name}: no Parameters or Attributes")
    assert not missing, f"{len(missing)} public calls without numpydoc sections:\n" + "\n".join(missing)


def test_the_public_calls_keep_their_names():
    """The calls ARCHITECTURE.md names stay where users find them."""
    import localization
    import usd_export
    import vrecho
    import vrecho.boundary
    import vrecho.headset

    assert vrecho.boundary.BoundaryMonitor is vrecho.headset.BoundaryMonitor
    for call in (vrecho.load_classifier, localization.place_sources, localization.locate, localization.separate,
                 usd_export.write_scene, usd_export.validate):
        assert callable(call)
    assert vrecho.Classifier.__name__ == "Classifier"  # torch loads on this first use only
