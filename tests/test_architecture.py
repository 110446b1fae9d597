"""The shape of the code as a checked contract (docs/architecture.md): layers only import
downwards, no module imports another module's ``_private`` names, no import cycles (lazy
imports and ``importlib.import_module("elicit_jax...")`` strings included), and nothing in the
repository points outside it. A planted violation of each rule is caught."""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "elicit_jax"

LAYERS = {
    # top-level package or module of elicit_jax -> its layer; a module may import its own
    # layer and lower ones, never a higher one. Keep in step with docs/architecture.md.
    "": 0,  # elicit_jax/__init__.py: the version only
    "errors": 0,
    "hashing": 1,
    "runtime": 1,
    "stats": 1,
    "sharding": 1,
    "artifact": 2,
    "render": 2,
    "provenance": 2,
    "output_rules": 2,
    "data": 3,
    "policy": 4,
    "sim": 5,
    "compat": 5,
    "curation": 6,
    "elicit": 7,
    "web": 8,
    "pipeline": 9,
    "cli": 10,
}

UPWARD_EXCEPTIONS: dict[tuple[str, str], str] = {
    # (importer, imported): why it is still there. Remove an entry when the import goes.
}

PRIVATE_EXCEPTIONS = {
    # (importer, imported module, name): why. Remove an entry when the import goes.
}

RICH = "rich"
CONSOLE = "Console("
PRINT_CALL = "print("
PRINT_VALUE = "print as a value"

PRINTING_ALLOWED: dict[str, tuple[frozenset[str], str]] = {
    # Modules outside cli/ that still do one of the printing things (``import rich``, build a
    # ``Console``): which ones, and why. Printing belongs in cli/ (issue #28 item 4); remove an
    # entry when its module stops. Passing a console down from cli/ as a parameter is fine;
    # building one here is not, and neither is ``print`` (called or passed as a default).
    "elicit_jax.compat.show": (frozenset({RICH}), "a rendering module (the fit report's "
        "tables, the scoring bar) on the console its caller passes"),
    "elicit_jax.policy.progress": (frozenset({RICH, CONSOLE}), "a rendering module (the "
        "training bar and end-of-run table), but train() builds its console itself (quiet= "
        "silences it); its callers in cli/, pipeline/, web/ and elicit/ should pass it in"),
    "elicit_jax.pipeline.runner": (frozenset({RICH}), "the stage graph's progress bars and "
        "summary table, on the console passed down"),
    "elicit_jax.pipeline.ray_runner": (frozenset({RICH, CONSOLE}), "the Ray driver's progress "
        "bars and messages on the console passed down; a worker renders its stage's output "
        "into a string (a Console on a buffer) that the driver prints"),
    "elicit_jax.pipeline.run": (frozenset({RICH}), "the plan and result tables, on the "
        "console passed down"),
    "elicit_jax.pipeline.stages_policy": (frozenset({RICH}), "nested progress bars on the "
        "console passed down"),
    "elicit_jax.pipeline.elicitation.stages": (frozenset({RICH}), "nested progress bars on "
        "the console passed down"),
}  # fmt: skip

_MODULE_STRING = re.compile(r"elicit_jax(\.\w+)*")


def _modules(root: Path) -> dict[str, Path]:
    mods = {}
    for p in (root / "elicit_jax").rglob("*.py"):
        name = ".".join(p.relative_to(root).with_suffix("").parts)
        mods[name.removesuffix(".__init__")] = p
    return mods


def _named_modules(node: ast.AST) -> list[str]:
    """Modules a node names: imports, and module-path strings (``import_module`` targets,
    lookup tables; an f-string counts by its constant prefix)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value] if _MODULE_STRING.fullmatch(node.value) else []
    if isinstance(node, ast.JoinedStr) and node.values:
        head = node.values[0]
        if isinstance(head, ast.Constant) and isinstance(head.value, str):
            prefix = head.value.rstrip(".")
            return [prefix] if _MODULE_STRING.fullmatch(prefix) else []
    return []


def related(a: str, b: str) -> bool:
    """``a`` and ``b`` are a package and one of its own modules (either way round), matched
    whole module by module: ``x.stages`` is not a package of ``x.stages_policy``."""
    return a.startswith(b + ".") or b.startswith(a + ".")


def scan(root: Path = ROOT) -> tuple[dict[str, set[str]], list[tuple[str, str, str]]]:
    """(module -> the elicit_jax modules it imports or names, anywhere in the file; every
    ``from module import _private`` across modules as (importer, module, name))."""
    mods = _modules(root)
    graph: dict[str, set[str]] = {}
    private = []
    for name, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("elicit_jax"):
                for alias in node.names:
                    full = f"{node.module}.{alias.name}"
                    deps.add(full if full in mods else node.module)
                    is_private = alias.name.startswith("_") and not alias.name.startswith("__")
                    if is_private and node.module != name:
                        private.append((name, node.module, alias.name))
            deps.update(d for d in _named_modules(node) if d.startswith("elicit_jax"))
        graph[name] = {d for d in deps if d in mods and d != name and not related(name, d)}
    return graph, private


def printing_hits(source: str) -> list[str]:
    """What a module's source does that prints: ``rich`` imported in any form, anywhere
    (:data:`RICH`), a ``Console`` built (:data:`CONSOLE`), the builtin ``print`` called
    (:data:`PRINT_CALL`) or passed as a value, e.g. a ``log=print`` default
    (:data:`PRINT_VALUE`)."""
    tree = ast.parse(source)
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            hits += [RICH for a in node.names if a.name.split(".")[0] == "rich"]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "rich":
            hits.append(RICH)
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", None)
            if name == "Console":
                hits.append(CONSOLE)
        elif isinstance(node, ast.Name) and node.id == "print":
            hits.append(PRINT_CALL if id(node) in called else PRINT_VALUE)
    return sorted(set(hits))


def printers(root: Path = ROOT) -> dict[str, list[str]]:
    """Modules outside ``cli/`` that print: module -> what they do (:func:`printing_hits`)."""
    found: dict[str, list[str]] = {}
    for name, path in _modules(root).items():
        if name == "elicit_jax.cli" or name.startswith("elicit_jax.cli."):
            continue
        hits = printing_hits(path.read_text())
        if hits:
            found[name] = hits
    return found


def not_allowed(found: dict[str, list[str]]) -> dict[str, list[str]]:
    """The hits :data:`PRINTING_ALLOWED` does not allow."""
    out = {}
    for module, hits in found.items():
        allowed = PRINTING_ALLOWED.get(module, (frozenset(), ""))[0]
        extra = [h for h in hits if h not in allowed]
        if extra:
            out[module] = extra
    return out


@functools.cache
def _repo() -> tuple[dict[str, set[str]], list[tuple[str, str, str]]]:
    return scan(ROOT)


def layer_of(module: str) -> int:
    """The layer of an ``elicit_jax`` module (its top-level package's, :data:`LAYERS`)."""
    parts = module.split(".")
    return LAYERS[parts[1] if len(parts) > 1 else ""]


def upward_imports(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Every (importer, imported) where the imported module sits in a higher layer."""
    return sorted((a, b) for a, deps in graph.items() for b in deps if layer_of(b) > layer_of(a))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_every_package_has_a_layer_and_the_doc_lists_them():
    tops = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    tops |= {p.name for p in PACKAGE.iterdir() if p.is_dir() and any(p.rglob("*.py"))}
    assert tops - set(LAYERS) == set(), "give each new package a layer (here and in the doc)"
    doc = (ROOT / "docs" / "architecture.md").read_text()
    table = dict(re.findall(r"^\| (\d+) \| (.+?) \|", doc, re.M))
    documented = {
        name.strip(" `/").removesuffix(".py"): int(layer)
        for layer, names in table.items()
        for name in names.split(",")
    }
    assert documented == {k: v for k, v in LAYERS.items() if k}


def test_no_upward_imports():
    found = upward_imports(_repo()[0])
    assert [f for f in found if f not in UPWARD_EXCEPTIONS] == []
    assert [e for e in UPWARD_EXCEPTIONS if e not in found] == [], "stale exception"


def test_no_cross_module_private_imports():
    found = _repo()[1]
    assert [f for f in found if f not in PRIVATE_EXCEPTIONS] == []
    assert [e for e in PRIVATE_EXCEPTIONS if e not in found] == [], "stale exception"


def test_no_import_cycles():
    assert cycles(_repo()[0]) == []


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.fixture()
def planted(tmp_path: Path) -> Path:
    """A small elicit_jax tree with one violation of each rule."""
    files = {
        "__init__.py": "",
        "data/__init__.py": "",
        # upward: data (3) imports cli (10), lazily inside a function
        "data/demos.py": "def f():\n    from elicit_jax.cli.app import app\n    return app\n",
        "cli/__init__.py": "",
        "cli/app.py": "app = 1\n",
        "compat/__init__.py": "",
        # a private name from another module
        "compat/score.py": "from elicit_jax.compat.measures import _helper\n",
        "compat/measures.py": "def _helper():\n    return 1\n",
        "policy/__init__.py": "",
        # a cycle closed only by import_module strings
        "policy/a.py": "import importlib\n\ndef f():\n"
        "    return importlib.import_module('elicit_jax.policy.b')\n",
        "policy/b.py": "import importlib\n\ndef g(x):\n"
        "    return importlib.import_module(f'elicit_jax.policy.a.{x}')\n",
        # a cycle between two modules, one's name a prefix of the other's
        "pipeline/__init__.py": "",
        "pipeline/stages.py": "from elicit_jax.pipeline.stages_policy import train\n",
        "pipeline/stages_policy.py": "def train():\n"
        "    from elicit_jax.pipeline.stages import demos_file\n    return demos_file\n",
    }
    for rel, text in files.items():
        path = tmp_path / "elicit_jax" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


def test_planted_violations_are_caught(planted):
    graph, private = scan(planted)
    assert upward_imports(graph) == [("elicit_jax.data.demos", "elicit_jax.cli.app")]
    assert private == [("elicit_jax.compat.score", "elicit_jax.compat.measures", "_helper")]
    assert cycles(graph) == [
        ["elicit_jax.pipeline.stages", "elicit_jax.pipeline.stages_policy"],
        ["elicit_jax.policy.a", "elicit_jax.policy.b"],
    ]


def test_module_names_are_matched_whole():
    """``stages`` is not the package of ``stages_policy``: matching by a bare prefix dropped
    their edges (and a cycle between them); a package and its own modules are related."""
    assert not related("elicit_jax.pipeline.stages", "elicit_jax.pipeline.stages_policy")
    assert not related("elicit_jax.pipeline.stages_policy", "elicit_jax.pipeline.stages")
    assert related("elicit_jax.pipeline", "elicit_jax.pipeline.stages")
    assert related("elicit_jax.pipeline.elicitation.stages", "elicit_jax.pipeline.elicitation")


def test_printing_only_in_cli():
    found = printers()
    assert not_allowed(found) == {}
    stale = {m: sorted(kinds - set(found.get(m, ()))) for m, (kinds, _) in PRINTING_ALLOWED.items()}
    assert {m: k for m, k in stale.items() if k} == {}, "stale allow-list entry"


def test_planted_printing_is_caught(planted):
    extra = {
        # a lazy rich import in a lower layer, a bare print, and the same in cli/ (allowed)
        "data/show.py": "def f():\n    from rich.table import Table\n    return Table\n",
        "compat/say.py": "def g(x):\n    print(x)\n",
        "policy/bar.py": "import rich.progress\n",
        "cli/show.py": "from rich.console import Console\n\nprint(Console())\n",
        # print passed as a value (a default, an argument), and a Console built
        "data/log.py": "def run(log=print):\n    log('x')\n",
        "compat/echo.py": "def h(f):\n    return f\n\nh(print)\n",
        "policy/con.py": "import rich.console as rc\n\ndef c():\n    return rc.Console()\n",
    }
    for rel, text in extra.items():
        (planted / "elicit_jax" / rel).write_text(text)
    assert printers(planted) == {
        "elicit_jax.data.show": [RICH],
        "elicit_jax.compat.say": [PRINT_CALL],
        "elicit_jax.policy.bar": [RICH],
        "elicit_jax.data.log": [PRINT_VALUE],
        "elicit_jax.compat.echo": [PRINT_VALUE],
        "elicit_jax.policy.con": [CONSOLE, RICH],
    }


def test_an_allowed_rich_import_does_not_allow_building_a_console():
    """The allow-list is per hit: a rendering module may import rich, not build its console or
    default a callback to print."""
    renders = "from rich.table import Table\n\ndef show(t: Table, console):\n    console.print(t)\n"
    builds = (
        renders + "\ndef default():\n    from rich.console import Console\n    return Console()\n"
    )
    logs = renders + "\ndef run(log=print):\n    log('x')\n"
    module = "elicit_jax.compat.show"
    assert not_allowed({module: printing_hits(renders)}) == {}
    assert not_allowed({module: printing_hits(builds)}) == {module: [CONSOLE]}
    assert not_allowed({module: printing_hits(logs)}) == {module: [PRINT_VALUE]}


def test_nothing_points_outside_the_repository():
    outside = re.compile(r"/work/|shared/METHOD|\.\./shared|METHOD\.md|ARCHITECTURE\.md")
    files = [ROOT / "README.md", *PACKAGE.rglob("*.py"), *(ROOT / "docs").rglob("*.md")]
    files += [*(ROOT / "benchmarks").rglob("*.py"), *(ROOT / "benchmarks").rglob("*.md")]
    hits = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in files
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if outside.search(line)
    ]
    assert hits == []
