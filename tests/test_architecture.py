"""The import rule of DEVELOPERS.md, read from the package files with ``ast`` (no module is run).

* A stage package (perception, generation, layout, exporters) imports from the project only its
  own package and the data-model modules of scene_builder (DEVELOPERS.md's list): never another
  stage, never the application or the bench layer.
* The data-model modules of scene_builder import only each other (no stage, no application).
* Only scene_builder.pipeline, scene_builder.cli and scene_builder.bench.* import the stages.
* No import circle between the project's modules, in any package: imports anywhere in a file
  count (top level or inside functions), and so do a package's ``__init__`` and its modules.
* No module in any package (scene_builder with its bench layer, perception, generation, layout,
  exporters) is over 800 lines; no stage module is named like a benchmark or synthetic data (those
  live in scene_builder/bench/).
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("perception", "generation", "layout", "exporters")
PROJECT = ("scene_builder",) + STAGES
MAX_LINES = 800


def data_model_modules() -> set[str]:
    """The modules DEVELOPERS.md allows stages to import: the names in its rule 'Stage packages
    import only `scene_builder.x`, ... (the data model ...)'."""
    text = (ROOT / "DEVELOPERS.md").read_text()
    m = re.search(r"Stage packages import only (.*?)\(", text, re.S)
    assert m, "DEVELOPERS.md lost its rule 'Stage packages import only ...'"
    names = set(re.findall(r"`scene_builder\.(\w+)`", m.group(1)))
    assert {"model", "frames", "errors"} <= names, names
    return names


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@functools.cache
def project_modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PROJECT for p in sorted((ROOT / pkg).rglob("*.py"))}


@functools.cache  # each file is parsed once for all the checks below
def imported_modules(source: str, name: str, is_package: bool = False) -> frozenset[str]:
    """Every project module that the module ``name`` with text ``source`` imports, anywhere in the
    file (top level or inside functions): ``import a.b`` gives a.b; ``from a import b`` gives a.b
    when a.b is a module, else a; relative imports are resolved against the module's package."""
    modules = project_modules()
    package = name if is_package else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(source, name)):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - (node.level - 1)] + ([base] if base else []))
            for a in node.names:
                sub = f"{base}.{a.name}" if base else a.name
                found.add(sub if sub in modules else base)
    return frozenset(m for m in found if m.split(".")[0] in PROJECT)


def import_graph(extra: dict[str, str] | None = None) -> dict[str, set[str]]:
    """Each project module -> the other project modules it imports (anywhere in the file).
    ``extra``: text appended to some files (relative path -> source), as in :func:`violations`."""
    extra = extra or {}
    graph = {}
    for name, path in project_modules().items():
        source = path.read_text() + extra.get(path.relative_to(ROOT).as_posix(), "")
        graph[name] = imported_modules(source, name, path.name == "__init__.py") - {name}
    return graph


def import_cycles(extra: dict[str, str] | None = None) -> list[list[str]]:
    """The import circles: each set of modules that import one another, directly or through
    others (a strongly connected component of more than one module, Tarjan's algorithm written
    out here, iteratively, because the project has no graph library), as one circle through
    them in import order, starting at its first module by name."""
    graph = import_graph(extra)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root] & graph.keys())))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, targets = work[-1]
            for t in targets:
                if t not in index:
                    index[t] = low[t] = len(index)
                    stack.append(t)
                    on_stack.add(t)
                    work.append((t, iter(sorted(graph[t] & graph.keys()))))
                    break
                if t in on_stack:
                    low[node] = min(low[node], index[t])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = set()
                    while True:
                        m = stack.pop()
                        on_stack.discard(m)
                        component.add(m)
                        if m == node:
                            break
                    if len(component) > 1:
                        components.append(component)
    return sorted(_circle_through(graph, c) for c in components)


def _circle_through(graph: dict[str, set[str]], component: set[str]) -> list[str]:
    """A shortest import path from the component's first module back to itself, inside it."""
    start = min(component)
    paths = {start: [start]}
    frontier = [start]
    while frontier:
        nxt = []
        for m in frontier:
            for t in sorted(graph[m] & component):
                if t == start:
                    return paths[m] + [start]
                if t not in paths:
                    paths[t] = paths[m] + [t]
                    nxt.append(t)
        frontier = nxt
    raise AssertionError(f"no circle through {sorted(component)}")


def violations(extra: dict[str, str] | None = None) -> list[str]:
    """Each broken rule as one line 'module imports target (rule)'. ``extra``: text appended to
    some files (relative path -> source), to show that the check sees a break."""
    extra = extra or {}
    allowed_data = data_model_modules()
    data_modules = {f"scene_builder.{n}" for n in allowed_data | {"serialize"}} | {"scene_builder"}
    may_import_stages = ("scene_builder.pipeline", "scene_builder.cli", "scene_builder.bench")
    out = []
    for name, path in project_modules().items():
        top = name.split(".")[0]
        source = path.read_text() + extra.get(path.relative_to(ROOT).as_posix(), "")
        for target in sorted(imported_modules(source, name, path.name == "__init__.py")):
            target_top = target.split(".")[0]
            if top in STAGES:
                if target_top == top:
                    continue
                if target_top == "scene_builder":
                    if target not in data_modules - {"scene_builder.serialize"}:
                        out.append(f"{name} imports {target} (stages import only the data model: {sorted(allowed_data)})")
                else:
                    out.append(f"{name} imports {target} (a stage never imports another stage)")
            elif name in data_modules and target not in data_modules:
                out.append(f"{name} imports {target} (the data model imports only the data model)")
            elif target_top in STAGES and not any(name == m or name.startswith(m + ".") for m in may_import_stages):
                out.append(f"{name} imports {target} (only {', '.join(may_import_stages)} import the stages)")
    return out


def test_import_rule_holds():
    assert violations() == []


def test_import_rule_is_checked():
    """The checker sees a broken rule: a stage importing the bench layer inside a function, a
    stage importing another stage's internals or the application, the data model importing a
    stage, and the application's report importing a stage."""
    broken = {
        "layout/solver.py": "\ndef _f():\n    from scene_builder.bench.clutter import clutter\n",
        "exporters/mjcf.py": "\nfrom layout.verify import verify_scene\n",
        "scene_builder/frames.py": "\nimport perception.room\n",
        "scene_builder/report.py": "\nfrom generation import generate_assets\n",
        "perception/room.py": "\nfrom scene_builder import pipeline\n",
        "generation/physx/tokens.py": "\nfrom scene_builder import serialize\n",
    }
    found = violations(broken)
    for start in (
        "layout.solver imports scene_builder.bench.clutter",
        "exporters.mjcf imports layout.verify",
        "scene_builder.frames imports perception.room",
        "scene_builder.report imports generation",
        "perception.room imports scene_builder.pipeline",
        "generation.physx.tokens imports scene_builder.serialize",
    ):
        assert any(v.startswith(start + " ") for v in found), (start, found)
    assert len(found) == len(broken), found


def test_relative_imports_are_resolved():
    src = "from . import protocol\nfrom .. import assembly\nfrom ..physx.tokens import encode\nfrom ..materials import material\n"
    assert imported_modules(src, "generation.physx.vlm") == {"generation.physx.protocol", "generation.assembly", "generation.physx.tokens", "generation.materials"}
    assert imported_modules("from .solver import solve_layout\nimport numpy\n", "layout", is_package=True) == {"layout.solver"}


def test_no_import_circles():
    circles = import_cycles()
    assert circles == [], "break these import circles (a module both use, or one direction only): " + "; ".join(" -> ".join(c) for c in circles)


def test_import_circles_are_found():
    """The check sees a circle of two modules made by a function-level import, one of three
    modules across a package's ``__init__``, and reports nothing for a one-way import added."""
    assert import_cycles({"exporters/sdf_xml.py": "\ndef _f():\n    from exporters.sdf import write_sdf\n"}) == [
        ["exporters.sdf", "exporters.sdf_xml", "exporters.sdf"]
    ]
    # layout.pushes -> layout (the package, whose __init__ imports layout.solver) -> layout.solver -> layout.pushes
    assert import_cycles({"layout/pushes.py": "\nfrom layout import solve_layout\n"}) == [
        ["layout", "layout.solver", "layout.pushes", "layout"]
    ]
    assert import_cycles({"perception/single_view.py": "\nfrom perception import vanishing_points\n"}) == []


def test_no_module_over_800_lines_in_any_package():
    sizes = {p.relative_to(ROOT).as_posix(): len(p.read_text().splitlines()) for pkg in PROJECT for p in (ROOT / pkg).rglob("*.py")}
    assert {p.split("/")[0] for p in sizes} == set(PROJECT) and len(sizes) > 100
    assert {p: n for p, n in sizes.items() if n > MAX_LINES} == {}, f"split these modules (at most {MAX_LINES} lines each)"


def test_stage_packages_hold_no_benchmark_or_synthetic_modules():
    named = [p.relative_to(ROOT).as_posix() for pkg in STAGES for p in (ROOT / pkg).rglob("*.py") if re.search("bench|synthetic", p.stem)]
    assert named == [], f"benchmarks and synthetic data live in scene_builder/bench/, not in {named}"


# ------------------------------------------------------------------------------------------
# Errors that name the real cause (issue 26)
# ------------------------------------------------------------------------------------------

#: Where catching every exception is the point: the fuzzer counts any exception but a parser's
#: documented one as a crash; the ground-truth bench counts a build's crash (with its traceback)
#: and goes on to the next photo.
BROAD_CATCH_ALLOWED = {"scene_builder/bench/fuzz.py", "scene_builder/bench/groundtruth.py"}


def _names(node: ast.expr | None) -> set[str]:
    if node is None:
        return {"<bare>"}
    elts = node.elts if isinstance(node, ast.Tuple) else [node]
    return {e.id if isinstance(e, ast.Name) else e.attr if isinstance(e, ast.Attribute) else "?" for e in elts}


def broad_catches(extra: dict[str, str] | None = None) -> list[str]:
    """``except Exception`` / ``except BaseException`` / bare ``except`` in library code whose
    handler does not raise the exception again (a clean-up that re-raises is fine): each hides
    whatever went wrong, the project's own bugs included."""
    extra = extra or {}
    out = []
    for path in project_modules().values():
        rel = path.relative_to(ROOT).as_posix()
        if rel in BROAD_CATCH_ALLOWED:
            continue
        tree = ast.parse(path.read_text() + extra.get(rel, ""), rel)
        for node in ast.walk(tree):
            if isinstance(node, ast.ExceptHandler) and _names(node.type) & {"Exception", "BaseException", "<bare>"}:
                reraises = any(isinstance(n, ast.Raise) and n.exc is None for n in ast.walk(ast.Module(body=node.body, type_ignores=[])))
                if not reraises:
                    out.append(f"{rel}:{node.lineno}")
    return out


def test_library_code_catches_only_what_it_can_name():
    assert broad_catches() == []
    planted = {"layout/solver.py": "\ndef _f():\n    try:\n        pass\n    except (ValueError, Exception):\n        return None\n",
               "perception/inputs.py": "\ntry:\n    pass\nexcept BaseException:\n    raise\n"}
    found = broad_catches(planted)
    assert len(found) == 1 and found[0].startswith("layout/solver.py:"), found


def project_import_skips(extra: dict[str, str] | None = None) -> list[str]:
    """Tests that turn a failed import of the project's own code into a skip:
    ``pytest.importorskip("<project module>")``, or an import of it inside ``try`` whose
    ``except ImportError`` / ``ModuleNotFoundError`` does not raise. A broken import of the
    project is a failure, never a skip; optional third-party packages may still be skipped."""
    extra = extra or {}
    out = []
    for path in sorted((ROOT / "tests").glob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text() + extra.get(rel, ""), rel)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "importorskip"
                    and node.args and isinstance(node.args[0], ast.Constant) and str(node.args[0].value).split(".")[0] in PROJECT):
                out.append(f"{rel}:{node.lineno} importorskip({node.args[0].value!r})")
            if isinstance(node, ast.Try):
                imported = {a.name.split(".")[0] for n in node.body for a in getattr(n, "names", []) if isinstance(n, ast.Import)}
                imported |= {(n.module or "").split(".")[0] for n in node.body if isinstance(n, ast.ImportFrom)}
                for h in node.handlers:
                    if imported & set(PROJECT) and _names(h.type) & {"ImportError", "ModuleNotFoundError", "Exception", "<bare>"}:
                        if not any(isinstance(n, ast.Raise) for n in ast.walk(ast.Module(body=h.body, type_ignores=[]))):
                            out.append(f"{rel}:{h.lineno} except ImportError around an import of the project")
    return out


def test_a_failed_import_of_the_project_is_never_a_skip():
    assert project_import_skips() == []
    planted = {"tests/test_cli.py": "\ndef _f():\n    pytest.importorskip('perception.inputs')\n    pytest.importorskip('ray')\n"
                                    "    try:\n        from layout import verify\n    except ImportError:\n        pytest.skip('no')\n"}
    found = project_import_skips(planted)
    assert len(found) == 2 and any("importorskip('perception.inputs')" in f for f in found), found
    assert any("except ImportError around an import of the project" in f for f in found), found
