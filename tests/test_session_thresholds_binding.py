"""``elicit``, ``serve`` and ``watch`` refuse a thresholds file fitted for another policy than
the one they score with, as ``score``, ``filter`` and ``map`` do; ``--force`` applies it with a
warning, and the policy's own thresholds pass without a word."""

from __future__ import annotations

import pytest
from fixtures_data import invoke

from elicit_jax.compat.thresholds import Thresholds, write_thresholds
from elicit_jax.errors import ElicitError
from elicit_jax.policy.loaded import load_policy


def _thresholds(path, inputs, policy):
    t = Thresholds(inputs.lam, inputs.eta, "fit", policy=policy)
    write_thresholds(path, t, method="given", inputs={}, config={}, report={})
    return path


@pytest.fixture(scope="module")
def files(square_nut_session_inputs, tmp_path_factory):
    d = tmp_path_factory.mktemp("session-binding")
    inputs = square_nut_session_inputs
    own = load_policy(inputs.policy).sha256
    return (
        inputs,
        d,
        _thresholds(d / "own.json", inputs, own),
        _thresholds(d / "other.json", inputs, "0" * 64),
    )


def _inputs(inputs):
    return ("--policy", inputs.policy, "--base-demos", inputs.base)


def _refused(r, *names):
    assert isinstance(r.exception, ElicitError), (r.output, r.exception)
    msg = str(r.exception)
    assert "\n" not in msg and "another policy" in msg and "--force" in msg, msg
    assert all(str(n) in msg for n in names), msg


def _never(*args, **kwargs):
    raise AssertionError("started although the thresholds belong to another policy")


def test_elicit_refuses_another_policys_thresholds(files, monkeypatch):
    import elicit_jax.cli.session_console as console

    monkeypatch.setattr(console, "elicit", _never)
    inputs, d, _, other = files
    r = invoke("elicit", *_inputs(inputs), "--thresholds", other,
               "--operator", "scripted:same-style", "-o", d / "s1")  # fmt: skip
    _refused(r, other, inputs.policy)
    assert not (d / "s1").exists()


def test_serve_refuses_another_policys_thresholds_before_it_listens(files, monkeypatch):
    import elicit_jax.web.serve as web_serve

    monkeypatch.setattr(web_serve, "serve", _never)
    inputs, d, _, other = files
    r = invoke("serve", *_inputs(inputs), "--thresholds", other, "--sessions", d / "srv")
    _refused(r, other)
    assert not (d / "srv").exists()


def test_watch_refuses_them_and_force_or_the_policys_own_file_runs(files):
    inputs, d, own, other = files
    inbox = d / "inbox"
    inbox.mkdir()
    args = ("watch", inbox, *_inputs(inputs), "--once", "-o", d / "pages")
    _refused(invoke(*args, "--thresholds", other), other)
    r = invoke(*args, "--thresholds", other, "--force")
    assert r.exit_code == 0, (r.output, r.exception)
    assert "another policy" in r.output and "applied anyway" in r.output
    r = invoke(*args, "--thresholds", own)
    assert r.exit_code == 0 and "another policy" not in r.output, (r.output, r.exception)
