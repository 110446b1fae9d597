"""The elicitation study pipeline: its definition, stage graph, tables, and a tiny real run.

The run is reach-pillar with one simulated person (conflict-right: passes the pillar on the
wrong side), tiny networks and few rollouts: collect → base policy → thresholds → sessions
(naive, informed, feedback only, informed HG-DAgger) → M-filter → retrain → evaluate →
report; a re-run does nothing; deleting a session re-runs it and what depends on it only.
"""

from __future__ import annotations

import io
import math
import shutil

import numpy as np
import pytest
from rich.console import Console

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.elicitation.gather import SessionData, StudyData
from elicit_jax.pipeline.elicitation.plan import build_study_graph, session_seed
from elicit_jax.pipeline.elicitation.spec import load_study, parse_study
from elicit_jax.pipeline.elicitation.success import compare, success_cells
from elicit_jax.pipeline.elicitation.tables import (
    ablation_table,
    ablation_tests,
    length_table,
    person_table,
    table2,
)
from elicit_jax.pipeline.run import PipelineRunConfig, run_pipeline
from elicit_jax.pipeline.tables import ResultRow

TINY = """
[pipeline]
kind = "elicitation"
name = "tiny-study"
profile = "cpu"
seeds = [0]
conditions = ["naive", "filtered", "rejection", "informed"]
ablation = ["feedback"]
dagger_conditions = ["informed"]

[people]
size = 1
seed = 0
ranges = {imitation = [0, 0], uptake = [1, 1], explore = [0, 0], reach = [1, 1]}

[session]
demos = 2
practice = 1
prompt = 2
max_episodes = 5

[[task]]
name = "reach-pillar"
base_episodes = 8
holdout_episodes = 3
# the contrast set is another conflicting style (right of the pillar after a pause), never the
# person's own (the study refuses it)
incompatible_operator = "conflict-right-pause"
incompatible_episodes = 3
styles = ["conflict-right"]
dagger = true

[train]
hidden = [32, 32]
ensemble_size = 3
epochs = 40
checkpoint_every = 20
progress_every = 20
batch_size = 128

[evaluate]
rollouts = 4
"""


def _study(text: str, **kw):
    import tomllib

    return parse_study(tomllib.loads(text), text=text, **kw)


def test_shipped_definition_and_its_graph():
    spec = load_study("pipelines/elicitation.toml", "cpu", ("round-nut",))
    assert spec.kind == "elicitation" and spec.seeds == (0, 1, 2) and spec.profile == "cpu"
    (task,) = spec.tasks
    assert len(task.people) == 6 and task.dagger
    assert all(p.startswith("person:") for p in task.people)
    graph = build_study_graph(spec)
    kinds = [s.kind for s in graph]
    per_person = 8  # naive, rejection, informed, 3 ablation arms, naive and informed DAgger
    assert kinds.count("session") == 6 * per_person
    assert kinds.count("filter-session") == 6
    assert kinds.count("train") == 1 + 6 * (per_person + 1)  # + base, + filtered
    assert kinds.count("evaluate") == kinds.count("train")
    sessions = [s for s in graph if s.kind == "session"]
    for s in sessions:  # every condition of a person meets the same initial states
        assert s.config["seed"] == session_seed(spec, int(s.config["person"][1:]))
        assert set(s.inputs) == {"policy", "base", "thresholds"}
    modes = {s.config["condition"]: (s.config["mode"], s.config["show"]) for s in sessions}
    assert modes["naive"] == ("naive", [])
    assert modes["rejection"] == ("informed", [])  # the rule filters, nothing is shown
    assert modes["informed"] == ("informed", ["prompt", "indicator", "feedback"])
    assert modes["indicator"] == ("informed", ["indicator"])
    assert {c for c in modes if c.endswith("dagger")} == {"naive-dagger", "informed-dagger"}
    filt = graph["train/round-nut/mlp/filtered/p0"]
    assert graph[filt.inputs["demos1"]].kind == "filter-session"
    assert graph[filt.inputs["demos1"]].inputs["session"] == "session/round-nut/mlp/naive/p0"
    assert graph["train/round-nut/mlp/informed/p3"].inputs["demos1"] == (
        "session/round-nut/mlp/informed/p3"
    )
    paper = load_study("pipelines/elicitation.toml", "paper")
    assert [t.name for t in paper.tasks] == [
        "round-nut",
        "hammer-drawer",
        "square-nut",
        "reach-pillar",
    ]
    for task in paper.tasks:  # no person starts from the contrast set's operator
        assert all(p.split(",")[0] != f"person:{task.incompatible_operator}" for p in task.people)


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (('kind = "elicitation"', ""), "needs \\[pipeline\\] kind"),
        (('ablation = ["feedback"]', 'ablation = ["voice"]'), "ablation: distinct values"),
        (('styles = ["conflict-right"]', 'styles = ["base"]'), "cannot start from the base"),
        (('styles = ["conflict-right"]', 'styles = ["nope"]'), "no operator 'nope'"),
        (("demos = 2", "demos = 2\nmode = 'naive'"), "set by the study"),
        (('"conflict-right-pause"', '"conflict-right"'), "is also a person's starting style"),
        (("size = 1", "size = 1\ncolour = 2"), "unknown key"),
        (
            ("dagger = true", "dagger = true\npeople_ranges = {delay = [2, 1]}"),
            "reach-pillar: trait range delay: low 2.0 above high 1.0",
        ),
        (
            ("dagger = true", "dagger = true\npeople_ranges = {grip = [0, 1]}"),
            "reach-pillar: unknown trait range 'grip'",
        ),
    ],
)
def test_definition_errors_name_the_problem(edit, words):
    with pytest.raises(ElicitError, match=words):
        _study(TINY.replace(*edit))


def test_unknown_session_option_is_reported_before_anything_runs():
    from elicit_jax.pipeline.study_kinds import STAGE_KINDS

    spec = _study(TINY.replace("demos = 2", "demos = 2\nspeed = 3"))
    with pytest.raises(ElicitError, match=r"\[session\] unknown session config key.*speed"):
        build_study_graph(spec, STAGE_KINDS.resolve)


def _result(method, person, seed, success):
    return ResultRow("t", "mlp", method, person, seed, success, 50.0, 50, "best")


def _session(cond, person, lengths, fractions, accepted):
    rows = tuple(
        {
            "episode_kind": "demonstration",
            "verdict": "accepted" if a else "rejected",
            "rule_verdict": "accept" if a else "reject",
            "length": n,
            "operator_steps": n,
            "fraction_incompatible": f,
            "intervention_rate": None,
            "interventions": 0,
        }
        for n, f, a in zip(lengths, fractions, accepted, strict=True)
    )
    record = {"choices": {}, "start_choices": {}, "changes": [], "traits": {}}
    return SessionData("t", "mlp", cond, person, f"person:mild,seed={person[1:]}", False, rows,
                       record)  # fmt: skip


def test_table2_and_ablation_by_hand():
    results = [_result("base", None, s, v) for s, v in ((0, 0.2), (1, 0.4))]
    # naive: p0 .1/.3, p1 .2/.2 ; informed: p0 .5/.3, p1 .4/.6
    per_person = {"naive": ((0.1, 0.3), (0.2, 0.2)), "informed": ((0.5, 0.3), (0.4, 0.6))}
    for cond, values in per_person.items():
        for p, (a, b) in zip(("p0", "p1"), values, strict=True):
            results += [_result(cond, p, 0, a), _result(cond, p, 1, b)]
    sessions = (
        _session("naive", "p0", [100, 120], [0.2, 0.4], [False, False]),
        _session("informed", "p0", [90, 80, 70], [0.3, 0.0, 0.0], [False, True, True]),
    )
    data = StudyData("s", "cpu", "", "", "", tuple(results), sessions, {"t": (80.0, 5.0, 10)}, {},
                     {}, (), {}, {})  # fmt: skip
    header, (row,) = table2(data)
    cols = dict(zip(header, row, strict=True))
    # base: seeds 20, 40 → 30, sample std (ddof 1) √200 = 14.1; naive per seed:
    # mean(10, 20)=15, mean(30, 20)=25 → 20, std √50 = 7.1
    assert cols["Base"] == "30.0 (14.1)" and cols["Naive"] == "20.0 (7.1)"
    # informed per seed: mean(50, 40)=45, mean(30, 60)=45 → 45 (0)
    assert cols["Informed"] == "45.0 (0.0)" and cols["Naive + M-filtered"] == "–"
    # per person, informed − naive: p0 .40 − .20 = .20, p1 .50 − .20 = .30 → mean .25, paired
    # over the 2 people: ± t(0.975, 1) × sd(.2, .3) / √2 = 12.706 × 0.0707 / 1.414 = 0.635
    diff = compare(success_cells(data), "t", "mlp", "informed", "naive")
    assert diff.mean == pytest.approx(0.25) and diff.n == 2
    assert diff.high - diff.mean == pytest.approx(12.7062 * 0.05, rel=1e-4)
    # p = 2 · P(T_1 > .25 / .05 = 5) = 1 − 2 atan(5) / π = 0.1257, the smallest of Table 2's 3
    # tests (informed − naive, naive − base, informed − base): Holm multiplies it by 3
    assert diff.p == pytest.approx(1 - 2 * math.atan(5) / math.pi)
    assert cols["Informed − Naive"] == "+25.0 [-38.5, +88.5] (Holm p 0.377)"
    one = compare(success_cells(data), "t", "mlp", "informed", "base")  # vs base: p0 +10, p1 +20
    assert one.mean == pytest.approx(0.15)
    # Welch: people .40, .50 → var/n .005/2; base seeds .2, .4 → .02/2; se √.0125;
    # df = .0125² / (.0025² / 1 + .01² / 1) = 1.4706, t(0.975, 1.4706) = 6.1881 (scipy)
    assert one.high - one.mean == pytest.approx(6.1881 * 0.0125**0.5, rel=1e-4)
    assert not one.excludes_zero
    # naive − base: people .20, .20 (no spread), base seeds .2, .4 → se = √(.02 / 2) = .1,
    # Welch df = .01² / (.01² / 1) = 1, t(0.975, 1) = 12.7062 → −10 ± 127.1 points
    assert cols["Naive − Base"].startswith("-10.0 [-137.1, +117.1] (Holm p ")
    assert list(header[6:10]) == [
        "Naive − Base", "Informed − Naive", "Naive + M-filtered − Naive", "Informed − Base"
    ]  # fmt: skip
    header, rows = ablation_table(data, "t", "mlp")
    naive, informed = (dict(zip(header, r, strict=True)) for r in rows)
    assert naive["rule accepts"] == "0%" and naive["incompatible"] == "30.0%"
    assert informed["rule accepts"] == "67%" and informed["demos per accepted"] == "1.5"
    # the ablation's family is its own column: one test here, so Holm leaves p as it is
    assert informed["vs Naive"] == "+25.0 [-38.5, +88.5] (Holm p 0.126)"
    assert ablation_tests(data, "t", "mlp") == 1
    assert informed["ends as base"] == "–"  # no D_base states to compare styles on
    lengths = {r[2]: r for r in length_table(data)[1]}
    # accepted 80, 70 → 75, sample std √50 = 7.1
    assert lengths["Informed"][4] == "75.0 (7.1)" and lengths["Informed"][5] == "-6.2%"
    assert lengths["D_base"][4] == "80.0 (5.0)"


@pytest.mark.slow
def test_tiny_study_runs_reruns_nothing_and_resumes_a_deleted_session(tmp_path):
    from elicit_jax.elicit.store import SessionStore
    from elicit_jax.pipeline.study_kinds import STUDY_KINDS

    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    out = tmp_path / "run"

    def run():
        console = Console(file=io.StringIO(), width=200)
        cfg = PipelineRunConfig(pipeline=str(spec), out=str(out), progress=False)
        return run_pipeline(cfg, console=console), console.file.getvalue()

    first, text = run()
    assert first.result.ids("failed") == [] and first.result.skipped == []
    data = STUDY_KINDS["elicitation"].report_data(out)
    conds = {(r.method, r.operator) for r in data.results}
    assert conds == {
        ("base", None),
        *{
            (c, "p0")
            for c in ("naive", "filtered", "rejection", "informed", "feedback", "informed-dagger")
        },
    }
    assert all(r.n_rollouts == 4 for r in data.results)
    by = {s.condition: s for s in data.sessions}
    assert set(by) == {"naive", "rejection", "informed", "feedback", "informed-dagger"}
    naive, informed = by["naive"], by["informed"]
    # explore 0: no practice trials, so in naive mode and under rejection alone nothing changes
    assert naive.person_record["changes"] == [] == by["rejection"].person_record["changes"]
    assert {r["rule_verdict"] for r in by["rejection"].demonstrations} <= {"accept", "reject"}
    assert len(naive.accepted) == 2 and naive.spec == informed.spec
    # the informed person changed only on feedback (imitation 0, explore 0), and only after it
    changes = informed.person_record["changes"]
    assert changes and all(c["source"] == "feedback" for c in changes)
    assert informed.person_record["choices"]["route"] == "left"  # it now passes on the left
    rejected = [r["index"] for r in informed.rows if r["verdict"] == "rejected"]
    assert all(c["episode"] in rejected for c in changes)
    assert (
        SessionStore(out / "sessions/reach-pillar/mlp/informed/p0").header()["config"]["operator"]
        == informed.spec
    )
    dagger = by["informed-dagger"]
    assert any(r["intervention_rate"] for r in dagger.rows if r["episode_kind"] != "practice")
    # every session records how far the person's θ starts (and ends) from the base's; the
    # start is the person's, the same in every condition, and the per-person table shows it
    distances = {c: s.person_record["distance_from_base"] for c, s in by.items()}
    assert len({d["start"] for d in distances.values()}) == 1
    assert distances["informed"]["end"] < distances["informed"]["start"]
    header, rows = person_table(data, "reach-pillar", "mlp")
    start, end = distances["informed"]["start"], distances["informed"]["end"]
    assert dict(zip(header, rows[0], strict=True))["θ from base: start → informed end"] == (
        f"{start:.2f} → {end:.2f}"
    )
    md = first.report_md.read_text()
    for words in (
        "Base / Naive / Naive + M-filtered / Informed",
        "per person",
        "which part of the interface does the work",
        "do the people learn",
        "Demonstration lengths",
        "HG-DAgger",
        "What the M-filter kept",
        "CPU profile",
        "simulated",
    ):
        assert words in md, words
    html = first.report_html.read_text()
    assert "data:image/png;base64," in html and "<table>" in html
    assert "Informed − Naive" in text  # the console summary
    # a re-run does nothing
    second, _ = run()
    assert second.result.ran == []
    # a deleted session re-runs with its training and the report; the session's timing
    # columns differ, so the training re-runs, but it trains the same policy (same content
    # hash: wall-clock fields left out), so its evaluation is still up to date
    shutil.rmtree(out / "sessions/reach-pillar/mlp/feedback/p0")
    third, _ = run()
    assert sorted(third.result.ran) == [
        "report",
        "session/reach-pillar/mlp/feedback/p0",
        "train/reach-pillar/mlp/feedback/p0",
    ]
    assert np.isclose(
        STUDY_KINDS["elicitation"].report_data(out).sessions[0].rows[0]["length"],
        data.sessions[0].rows[0]["length"],
    )
    # `elicit-jax report RUN_DIR` rewrites a study's report
    from typer.testing import CliRunner

    from elicit_jax.cli import app

    res = CliRunner().invoke(app, ["report", str(out), "-o", str(tmp_path / "again")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "again/report.md").read_text() == first.report_md.read_text()
    # and `elicit-jax report --rebuild` remakes it from the report folder alone
    from elicit_jax.pipeline.run import rebuild_report

    shutil.copytree(tmp_path / "again", tmp_path / "kept")
    shutil.rmtree(out)
    rebuild_report(tmp_path / "kept", tmp_path / "rebuilt")
    for name in ("report.md", "report.html", "rollouts.parquet", "report-data.json"):
        assert (tmp_path / "rebuilt" / name).read_bytes() == (
            tmp_path / "again" / name
        ).read_bytes()
