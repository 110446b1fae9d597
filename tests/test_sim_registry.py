"""The task registry (sim/registry.py): one entry per task holds its class, its scripted
operators and its threshold preset, and every other list of tasks is read from it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from elicit_jax.compat.measures import PRESETS, TASK_PRESETS, ScoreConfig, preset_for_task
from elicit_jax.errors import ElicitError
from elicit_jax.sim.env import make_task, task_class, task_names
from elicit_jax.sim.operators import operator_names, style_names
from elicit_jax.sim.registry import TASKS, task_entry

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sorted(TASKS))
def test_every_task_has_its_class_operators_and_a_preset_or_says_why_not(name):
    entry = task_entry(name)
    assert task_class(name).name == name  # the entry's factory builds this very task
    names = style_names(name)
    assert names[0] == "base" and "same-style" in names and len(names) >= 3
    assert all(operator_names(name).values())  # every style has its description
    if entry.preset is None:
        assert entry.no_preset and not entry.preset_aliases and name not in PRESETS
    else:
        lam, eta = entry.preset
        assert 0 < lam < 1 and 0 < eta < 1 and not entry.no_preset
        assert PRESETS[name] == entry.preset and preset_for_task(name) == name
        assert all(preset_for_task(a.upper()) == name for a in entry.preset_aliases)


def test_the_paper_presets_and_their_aliases_are_as_before():
    assert dict(PRESETS) == {
        "square-nut": (0.4, 0.05),
        "round-nut": (0.35, 0.05),
        "hammer-drawer": (0.35, 0.06),
    }
    assert dict(TASK_PRESETS) == {
        "square-nut": "square-nut",
        "nutassemblysquare": "square-nut",
        "round-nut": "round-nut",
        "nutassemblyround": "round-nut",
        "hammer-drawer": "hammer-drawer",
        "hammerplaceenv": "hammer-drawer",
    }
    assert ScoreConfig.from_preset("square-nut").thresholds.pair == PRESETS["square-nut"]
    assert preset_for_task("NutAssemblyRound") == "round-nut" and preset_for_task(None) is None


def test_task_names_come_from_the_registry_alone():
    assert task_names() == sorted(TASKS)
    with pytest.raises(ElicitError, match=r"unknown task 'no-such' \(known: hammer-drawer, "):
        make_task("no-such")
    with pytest.raises(ElicitError, match="no scripted operators for task 'no-such'"):
        style_names("no-such")
    # no other module spells out a task list: no dict or tuple literal of 3+ task names
    found = []
    for path in (ROOT / "elicit_jax").rglob("*.py"):
        if path.name == "registry.py" and path.parent.name == "sim":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            items = (
                node.keys
                if isinstance(node, ast.Dict)
                else node.elts
                if isinstance(node, ast.Tuple | ast.List | ast.Set)
                else []
            )
            named = [k for k in items if isinstance(k, ast.Constant) and k.value in TASKS]
            if len(named) >= 3:
                found.append(path.relative_to(ROOT).as_posix())
    assert set(found) <= LISTS_LEFT, found


# Lists of task names outside the registry, each of something else (not a second registry).
LISTS_LEFT = {
    "elicit_jax/elicit/people/space.py",  # simulated people's per-task parameters
}
