"""The model registry (policy/kinds.py), the profile table and the checkpoint read once.

Registers nothing new: checks that every kind's entry is complete and works on tiny shapes,
that an unknown kind is a one-line error wherever a kind is named, that nothing outside the
registry compares kind names, and that a checkpoint is read once into a LoadedPolicy."""

from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import Policy, init_policy
from elicit_jax.policy.checkpoint import SPEC_KEYS
from elicit_jax.policy.config import PIPELINE_PROFILES, PROFILES, TrainConfig
from elicit_jax.policy.kinds import (
    MODEL_KINDS,
    MODELS,
    ModelKind,
    foreign_fields,
    init_members,
    make_module,
    model_kind,
)
from elicit_jax.policy.loaded import load_policy
from tests.fixtures_data import tiny_run

ROOT = Path(__file__).resolve().parents[1]
CONFIG_FIELDS = {f.name for f in dataclasses.fields(TrainConfig)}
POLICY_FIELDS = {f.name for f in dataclasses.fields(Policy)}


@pytest.mark.parametrize("name", MODELS)
def test_every_kind_entry_is_complete_and_works_on_tiny_shapes(name):
    kind = model_kind(name)
    assert kind.name == name and kind.summary
    assert kind.members >= 1 and kind.lr > 0 and min(kind.hidden) >= 1
    assert set(kind.cpu) <= CONFIG_FIELDS and "model" not in kind.cpu
    assert set(kind.own_fields) <= CONFIG_FIELDS & POLICY_FIELDS & set(SPEC_KEYS)
    assert (kind.predict is None) == kind.recurrent  # feed-forward kinds act one state at a time
    assert not (kind.mc_dropout and kind.recurrent)
    for f in dataclasses.fields(ModelKind):
        if f.name not in ("predict", "spread"):
            assert getattr(kind, f.name) is not None, f.name
    # the config's defaults and the cpu profile come from the entry
    cfg = TrainConfig(model=name)
    assert (cfg.ensemble_size, cfg.hidden, cfg.lr) == (kind.members, kind.hidden, kind.lr)
    cpu = TrainConfig.from_profile("cpu", model=name)
    assert all(getattr(cpu, k) == v for k, v in kind.cpu.items())
    assert set(cfg.to_dict()) == CONFIG_FIELDS - foreign_fields(name)
    # module, init, loss, prediction and spread on 4 rows of 3-dim obs, 2-dim actions
    module = make_module(name, (4,), 2, 0.0, 2)
    params = init_members(module, name, jax.random.key(0), 3, 2)
    assert jax.tree.leaves(params)[0].shape[0] == 2
    one = jax.tree.map(lambda x: x[0], params)
    obs = jnp.ones((4, 1, 3)) * 0.5
    per = kind.loss(module, one, obs, jnp.zeros((4, 1, 2)), jax.random.key(1), False, jnp.mean)
    assert per.shape == (4, 1) and bool(jnp.isfinite(per).all())
    policy = init_policy(
        jax.random.key(0), kind=name, obs_dim=3, action_dim=2, n_members=2, hidden=(4,)
    )
    assert policy.entry is kind
    members = policy.members(jnp.ones((5, 3)))
    assert members.shape == (2, 5, 2) and float(jnp.abs(members).max()) <= 1.0
    spread = policy.spread(jnp.ones((5, 3)))
    assert (spread is None) == (kind.spread is None)
    carry, action = policy.act(policy.init_carry(5), jnp.ones((5, 3)))
    assert action.shape == (5, 2) and (len(carry) == 0) == (not kind.recurrent)
    assert isinstance(kind.describe({"n_components": 2, "reset_every": 10}), str)


def test_the_kinds_differ_where_the_paper_says():
    mlp, mdn, lstm = (model_kind(k) for k in ("mlp", "mdn", "lstm"))
    assert (mlp.members, mlp.hidden, mlp.lr) == (5, (1024, 1024), 1e-3)
    assert (mdn.members, mdn.lr) == (1, 1e-4) and (lstm.hidden, lstm.lr) == ((512, 512), 1e-3)
    assert [k.name for k in MODEL_KINDS.values() if k.recurrent] == ["lstm"]
    assert [k.name for k in MODEL_KINDS.values() if k.own_spread] == ["mdn"]
    assert [k.name for k in MODEL_KINDS.values() if k.mc_dropout] == ["mlp"]
    assert foreign_fields("mlp") == {"mdn_min_std"} and foreign_fields("mdn") == frozenset()


def test_an_unknown_kind_is_the_same_one_line_error_everywhere(tmp_path):
    want = "unknown model 'transformer'; choose one of mlp, mdn, lstm"
    for call in (
        lambda: model_kind("transformer"),
        lambda: TrainConfig(model="transformer"),
        lambda: TrainConfig.from_profile("cpu", model="transformer"),
        lambda: make_module("transformer", (4,), 2, 0.0, 2),
    ):
        with pytest.raises(ElicitError) as e:
            call()
        assert str(e.value) == want
    # a checkpoint whose spec names an unknown kind: one line naming the checkpoint
    seed_dir = tiny_run(tmp_path) / "run" / "seed0"
    header = json.loads((seed_dir / "artifact.json").read_text())
    header["model"]["kind"] = "transformer"
    (seed_dir / "artifact.json").write_text(json.dumps(header))
    with pytest.raises(ElicitError) as e:
        load_policy(seed_dir)
    assert str(e.value).startswith(str(seed_dir)) and want in str(e.value)
    assert "\n" not in str(e.value)


def _kind_name_comparisons(path: Path) -> list[int]:
    """Lines comparing something with a kind's name (``== "mdn"``, ``!= "lstm"``, ...)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Compare) and any(
            isinstance(op, ast.Eq | ast.NotEq) for op in node.ops
        ):
            names = [node.left, *node.comparators]
            if any(isinstance(n, ast.Constant) and n.value in MODELS for n in names):
                out.append(node.lineno)
    return out


# Files outside the registry's owner that still compare names; switch each to an entry field.
NAME_CHECKS_LEFT = {
    "elicit_jax/curation/cupid.py": "needs an MLP ensemble (its influence scores)",
}


def test_no_module_chooses_by_kind_name():
    found = {}
    for path in (ROOT / "elicit_jax").rglob("*.py"):
        rel = path.relative_to(ROOT).as_posix()
        if rel != "elicit_jax/policy/kinds.py" and (lines := _kind_name_comparisons(path)):
            found[rel] = lines
    assert set(found) <= set(NAME_CHECKS_LEFT), found


def test_one_profile_table():
    from elicit_jax.pipeline import spec

    assert tuple(PROFILES) == ("paper", "cpu", "original-code")
    assert PIPELINE_PROFILES == ("paper", "cpu") and spec.PROFILES is PIPELINE_PROFILES
    assert all(p.name == name for name, p in PROFILES.items())
    original = TrainConfig.from_profile("original-code")
    assert (original.loss, original.grad_clip, original.dropout_last) == ("sum", 10.0, True)


def test_a_checkpoint_is_read_once_into_a_loaded_policy(tmp_path):
    run = tiny_run(tmp_path, seeds=(3,)) / "run"
    loaded = load_policy(run)
    assert loaded.seed == 3 and loaded.kind is model_kind("mlp")
    assert loaded.seed_dir == run / "seed3" and loaded.source == str(run)
    # the retraining config: the base run's own, restricted to the loaded seed
    header = json.loads((run / "artifact.json").read_text())
    assert loaded.train_config() == dataclasses.replace(
        TrainConfig.from_dict(header["config"]), seeds=(3,)
    )
    same = load_policy(run / "seed3").policy
    for a, b in zip(jax.tree.leaves(loaded.policy), jax.tree.leaves(same), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    bare = dataclasses.replace(loaded, config={})
    with pytest.raises(ElicitError, match="records no training config"):
        bare.train_config()
