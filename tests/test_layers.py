"""The package's layers (issue 12): formulations, integrators and the low layers import nothing
from the analyses, benchmarks or CLI; :mod:`fxflex.numerics` imports none of the layers above it;
the module graph has no cycle; no private SciPy module is imported. Read from the source with
``ast``, function-local imports included (imports under ``if TYPE_CHECKING:`` are not run)."""

import ast
import pathlib

import pytest

import fxflex

ROOT = pathlib.Path(fxflex.__file__).parent
LOW = ("solid", "beam", "time", "numerics", "mesh", "scene", "io")
UPPER = ("fxflex.analysis", "fxflex.bench", "fxflex.cli")
ABOVE_NUMERICS = ("fxflex.solid", "fxflex.beam", "fxflex.time", "fxflex.analysis", "fxflex.bench",
                  "fxflex.cli")


def _module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(path: pathlib.Path, module: str) -> set[str]:
    """Every module ``module`` imports, at any depth of its body (``from a import b`` counts as
    a.b when that is a module of fxflex, else as a)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text(), str(path)))
    return found


MODULES = {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}
IMPORTS = {name: _imports(path, name) for name, path in MODULES.items()}


def _fxflex_imports(name: str) -> set[str]:
    """The fxflex modules ``name`` imports (a ``from pkg import name`` of a non-module: pkg)."""
    return {m for m in IMPORTS[name] if m in MODULES and m != name}


def _within(name: str, prefixes) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def test_the_modules_are_found():
    assert "fxflex.numerics.dense" in MODULES and "fxflex.beam.ancf" in MODULES
    assert "fxflex.numerics.qep" in IMPORTS["fxflex.beam.frame"]


@pytest.mark.parametrize("layer", LOW)
def test_low_layers_import_no_analysis_bench_or_cli(layer):
    bad = {name: sorted(m for m in IMPORTS[name] if _within(m, UPPER))
           for name in MODULES if _within(name, [f"fxflex.{layer}"])}
    assert not {k: v for k, v in bad.items() if v}


def test_numerics_imports_no_layer_above_it():
    bad = {name: sorted(m for m in IMPORTS[name] if _within(m, ABOVE_NUMERICS))
           for name in MODULES if _within(name, ["fxflex.numerics"])}
    assert not {k: v for k, v in bad.items() if v}


def test_no_import_cycle():
    graph = {name: _fxflex_imports(name) for name in MODULES}
    # a package's __init__ imports its submodules and a submodule imports its package's
    # siblings through it: edges into a package's own __init__ from inside it are not cycles
    for name in graph:
        graph[name] = {m for m in graph[name] if not _within(name, [m])}
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def dfs(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                dfs(nxt)
        stack.pop()
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            dfs(name)
    assert not cycles


def test_no_private_scipy_import():
    bad = sorted((name, m) for name, found in IMPORTS.items() for m in found
                 if m.split(".")[0] == "scipy" and any(p.startswith("_") for p in m.split(".")))
    assert not bad


def _probes(path: pathlib.Path) -> list[str]:
    """getattr / hasattr calls on a formulation (a name or attribute called ``form``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in ("getattr", "hasattr") and node.args):
            target = node.args[0]
            name = target.id if isinstance(target, ast.Name) else (
                target.attr if isinstance(target, ast.Attribute) else None)
            if name == "form":
                found.append(f"{path.name}:{node.lineno}")
    return found


def test_no_caller_probes_a_formulation():
    """The contract (fxflex.formulation) declares every member: callers never discover one."""
    assert not [hit for path in MODULES.values() for hit in _probes(path)]


def test_no_module_name_repeats():
    """A newcomer finds a module by its name: one file per name across the package (packages'
    __init__ aside); ``fxflex bench NAME`` maps to bench/NAME.py or cli.BENCH_MODULES."""
    names = [path.stem for path in MODULES.values() if path.stem != "__init__"]
    assert sorted({n for n in names if names.count(n) > 1}) == []
