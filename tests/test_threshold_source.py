"""resolve_thresholds: one source of (λ, η), its verdict and its units, for every command."""

import dataclasses
import json

import pytest

from elicit_jax.compat.threshold_source import resolve_thresholds, task_thresholds
from elicit_jax.compat.thresholds import Thresholds, write_thresholds
from elicit_jax.compat.trust import Verdict
from elicit_jax.errors import ElicitError


def _file(tmp_path, report, scale=None):
    scores = tmp_path / "scores.txt"  # not a scores artifact: raw units unless patched below
    scores.write_text("hand-set")
    path = tmp_path / "t.json"
    given = Thresholds(0.25, 0.125, "given")
    write_thresholds(
        path, given, method="hand", inputs={"scores": scores}, config={}, report=report
    )
    if scale is not None:
        data = json.loads(path.read_text())
        data["action_scale"] = scale
        path.write_text(json.dumps(data))
    return path


def test_a_preset_and_a_given_pair_resolve_to_their_numbers():
    t = resolve_thresholds(None, None, None, "square-nut")
    assert (t.pair, t.source, t.file, t.verdict, t.verdict_line()) == (
        (0.4, 0.05),
        "preset square-nut",
        None,
        None,
        None,
    )
    t = resolve_thresholds(None, 0.3, 0.5)
    assert (t.lam, t.eta, t.source) == (0.3, 0.5, "given")
    assert resolve_thresholds(None, None, None) is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        t.lam = 1.0


@pytest.mark.parametrize(
    "args, message",
    [
        ((None, 0.3, None), "--lambda and --eta go together"),
        ((None, 0.3, 0.5, "square-nut"), "give only one of"),
        ((None, None, None, "no-such"), "unknown preset 'no-such'"),
        ((None, float("nan"), 0.5), "finite"),
        ((None, None, None, "round-nut", "std"), "--preset round-nut is in raw action units"),
    ],
)
def test_bad_flags_are_one_line_errors(args, message):
    with pytest.raises(ElicitError, match=message):
        resolve_thresholds(*args)


def test_a_file_carries_its_source_verdict_and_units(tmp_path):
    clean = Verdict().to_dict()
    path = _file(tmp_path, {"trust": clean})
    t = resolve_thresholds(path, None, None, action_scale="none")
    assert (t.pair, t.source, t.file) == ((0.25, 0.125), f"file {path}", path)
    assert t.verdict.clean and t.verdict_line() is None
    with pytest.raises(ElicitError, match="fitted on --action-scale none scores"):
        resolve_thresholds(path, None, None, action_scale="std")
    std = _file(tmp_path, {"trust": clean}, scale="std")
    assert resolve_thresholds(std, None, None, action_scale="std").pair == (0.25, 0.125)


def test_a_file_without_a_recorded_verdict_is_noted(tmp_path):
    path = _file(tmp_path, {})
    line = resolve_thresholds(path, None, None).verdict_line()
    assert line.startswith(f"note: {path}: judged when fitted: ")
    assert "no trust verdict recorded" in line
    bad = Verdict(problems=("one demonstration per set",)).to_dict()
    line = resolve_thresholds(_file(tmp_path, {"trust": bad}), None, None).verdict_line()
    assert line.startswith("warning: ") and "one demonstration per set" in line


def test_without_thresholds_score_takes_the_tasks_preset_or_borrows_square_nuts():
    t, [note] = task_thresholds("NutAssemblyRound")
    assert (t.pair, t.source) == ((0.35, 0.05), "preset round-nut (task NutAssemblyRound)")
    assert note == "thresholds: paper preset round-nut (λ=0.35, η=0.05) for task NutAssemblyRound"
    t, [note] = task_thresholds("my-task")
    assert t.pair == (0.4, 0.05) and t.source.startswith("borrowed: square-nut preset")
    assert note.startswith("warning: task 'my-task' has no paper preset")
    t, [note] = task_thresholds("hammer-drawer", action_scale="std")  # presets are raw units
    assert t.pair == (0.35, 0.06)
    assert t.source == (
        "raw-unit preset, not valid for --action-scale std scores: preset hammer-drawer "
        "(task hammer-drawer)"
    )
    assert note.startswith("warning: --action-scale std: the paper presets are in raw")
