"""The shape of the package, as issue 28 settled it: checks that fail when the code drifts back.

- no type dispatch by ``hasattr``/``getattr`` above the kernels (the kernel contract is typed);
- no function over 80 lines (docstring aside) unless its docstring says why it stays in one
  piece;
- ``ContactProblem`` under 400 lines;
- the layers import downwards only: no module imports one that imports it back.
"""

from __future__ import annotations

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "dolfinx_mortar"
MAX_FUNCTION_LINES = 80
LONG_FUNCTION_REASON = "in one piece"


def _modules():
    return sorted(PACKAGE.rglob("*.py"))


def _tree(path: pathlib.Path) -> ast.Module:
    return ast.parse(path.read_text(), filename=str(path))


@pytest.mark.parametrize("name", ["mortar.py", "stencils.py", "system.py", "friction.py"])
def test_no_attribute_dispatch_above_the_kernels(name):
    calls = [node.lineno for node in ast.walk(_tree(PACKAGE / name))
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
             and node.func.id in ("hasattr", "getattr")]
    assert calls == [], f"{name}: hasattr/getattr at lines {calls}"


def test_long_functions_say_why():
    long = []
    for path in _modules():
        for node in ast.walk(_tree(path)):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            lines = node.end_lineno - node.lineno + 1
            body = node.body[0]
            if (isinstance(body, ast.Expr) and isinstance(body.value, ast.Constant)
                    and isinstance(body.value.value, str)):
                lines -= body.end_lineno - body.lineno + 1  # the docstring is not code
            doc = ast.get_docstring(node) or ""
            if lines > MAX_FUNCTION_LINES and LONG_FUNCTION_REASON not in " ".join(doc.split()):
                long.append(f"{path.relative_to(PACKAGE)}:{node.name} ({lines} lines)")
    assert long == [], "over 80 lines without saying why it stays " + LONG_FUNCTION_REASON


def test_contact_problem_is_lean():
    from_problem = [node for node in ast.walk(_tree(PACKAGE / "problem.py"))
                    if isinstance(node, ast.ClassDef) and node.name == "ContactProblem"]
    assert len(from_problem) == 1
    node = from_problem[0]
    assert node.end_lineno - node.lineno + 1 < 400


def _imports(path: pathlib.Path) -> set[str]:
    """The package modules ``path`` imports (relative or absolute), as dotted names."""
    module = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    package = module.rsplit(".", 1)[0] if path.name != "__init__.py" else module
    found = set()
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] + [f"{target}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        found.update(name for name in names if name.startswith("dolfinx_mortar"))
    return found


def test_layers_have_no_circles():
    modules = {".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts): p
               for p in _modules()}
    graph = {}
    for name, path in modules.items():
        if path.name == "__init__.py":
            continue  # the package's lazy re-exports
        graph[name] = {target for target in _imports(path)
                       if target in modules and target != name
                       and modules[target].name != "__init__.py"}
    visiting, done, circles = set(), set(), []

    def visit(node, trail):
        visiting.add(node)
        for target in graph.get(node, ()):
            if target in visiting:
                circles.append(trail[trail.index(target):] + [target])
            elif target not in done:
                visit(target, trail + [target])
        visiting.discard(node)
        done.add(node)

    for name in graph:
        if name not in done:
            visit(name, [name])
    assert circles == []


def test_the_package_does_not_import_the_tests_oracle():
    """The numpy kernels live under tests/oracle as the compiled kernels' oracle only: the
    package runs one implementation and must not reach back into the tests for another."""
    found = []
    for path in _modules():
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] if not node.level else []
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            found += [f"{path.relative_to(PACKAGE)}:{node.lineno} {name}" for name in names
                      if name.split(".")[0] in ("tests", "oracle")
                      or name.endswith(("line2_numpy", "surface3_numpy"))]
    assert found == []
