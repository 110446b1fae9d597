"""``elicit-jax watch``: robomimic files and LeRobot episodes landing in a folder."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from fixtures_data import run_cli, write_lerobot_v21, write_robomimic

from elicit_jax.data.demos import from_episodes, write_demos

POLICIES: dict = {}


def _episode(rng, t=40, style="base", dims=(23, 7)):
    """States at random; actions of the policy trained for ``dims`` ("base": exactly the
    policy's own, so every pair is compatible) or their opposite ("other")."""
    import jax.numpy as jnp

    obs = rng.normal(size=(t, dims[0])).astype(np.float32)
    _, act = POLICIES[dims].act((), jnp.asarray(obs))
    act = np.clip(np.asarray(act), -0.99, 0.99) * (1.0 if style == "base" else -1.0)
    return obs, act.astype(np.float32)


def _base_and_policy(d, dims):
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.policy.train import train_policy

    rng = np.random.default_rng(0)
    eps = [
        {"obs": rng.normal(size=(40, dims[0])), "action": rng.uniform(-1, 1, (40, dims[1]))}
        for _ in range(6)
    ]
    base = from_episodes(eps, operators="base")
    write_demos(d / "base.parquet", base)
    cfg = TrainConfig(ensemble_size=3, hidden=(32, 32), epochs=1, checkpoint_every=1, seeds=(0,))
    train_policy(base, cfg, d / "run", quiet=True)
    POLICIES[dims] = load_policy(d / "run").policy


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """A robomimic-shaped (23-D obs, 7-D action) and a LeRobot-shaped (6, 6) base + policy."""
    d = tmp_path_factory.mktemp("watch")
    for name, dims in (("rm", (23, 7)), ("lr", (6, 6))):
        (d / name).mkdir()
        _base_and_policy(d / name, dims)
    return d


def _robomimic_demo(obs, act):
    return {
        "actions": act.astype(np.float64),
        "rewards": np.r_[np.zeros(len(act) - 1), 1.0],
        "obs/robot0_eef_pos": obs[:, 0:3],
        "obs/robot0_eef_quat": obs[:, 3:7],
        "obs/robot0_gripper_qpos": obs[:, 7:9],
        "obs/object": obs[:, 9:23],
    }


def _lerobot(root, episodes):
    eps = []
    for i, (obs, act) in enumerate(episodes):
        flags = np.zeros(len(obs), bool)
        flags[-1] = True
        eps.append(
            {
                "episode_index": i,
                "state": obs,
                "action": act,
                "reward": flags.astype(np.float32),
                "success_flags": flags,
                "task_index": 0,
            }
        )
    write_lerobot_v21(root, eps, ["stack"])


def _watch_args(inbox, d):
    return [
        "watch",
        inbox,
        "--policy",
        d / "run",
        "--base-demos",
        d / "base.parquet",
        "--lambda",
        "0.1",
        "--eta",
        "10",
        "--once",
        "--settle",
        "0.2",
        "--poll",
        "0.1",
    ]


def _verdicts(out):
    lines = [x for x in out.splitlines() if " / " in x]
    return {x.split(":")[0]: x.split(": ", 1)[1].split(":")[0] for x in lines}, lines


def test_watch_a_robomimic_inbox(setup, tmp_path, monkeypatch, capsys):
    rng = np.random.default_rng(1)
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    good, bad = _episode(rng), _episode(rng, style="other")
    write_robomimic(
        inbox / "op1.hdf5",
        {"demo_0": _robomimic_demo(*good), "demo_1": _robomimic_demo(*bad)},
    )
    (inbox / "op3.hdf5.part").write_bytes(b"still copying")
    (inbox / "broken.hdf5").write_bytes(b"\x89HDF\r\n\x1a\n cut short")
    args = _watch_args(inbox, setup / "rm")
    code, out, err = run_cli(monkeypatch, capsys, *args)
    assert code == 0, err
    verdicts, lines = _verdicts(out)
    assert verdicts == {"op1.hdf5 / demo_0": "accepted", "op1.hdf5 / demo_1": "rejected"}
    assert "broken.hdf5" in out and out.count("error:") == 1 and "op3" not in out
    rejected = next(x for x in lines if "demo_1" in x)
    assert "worst steps" in rejected and "compare base demo" in rejected
    pages = inbox / "verdicts"
    for stem in ("op1.hdf5__demo_0", "op1.hdf5__demo_1"):
        page = (pages / f"{stem}.html").read_text()
        assert "data:image/png;base64," in page and (pages / f"{stem}.png").stat().st_size > 1000
    log = [json.loads(x) for x in (pages / "verdicts.jsonl").read_text().splitlines()]
    assert len(log) == 3 and sum("error" in r for r in log) == 1
    code, out, _ = run_cli(monkeypatch, capsys, *args)  # a restart judges nothing again
    assert code == 0 and "judged 0 demonstrations" in out


def test_files_whose_names_sanitise_alike_get_pages_of_their_own(setup, tmp_path, monkeypatch,
                                                                 capsys):  # fmt: skip
    """`a b.hdf5` and `a_b.hdf5` once shared one page: the log linked a rejection to a page
    showing the other file's acceptance (#45 item 12)."""
    rng = np.random.default_rng(2)
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    good, bad = _episode(rng), _episode(rng, style="other")
    write_robomimic(inbox / "a b.hdf5", {"demo_0": _robomimic_demo(*bad)})
    write_robomimic(inbox / "a_b.hdf5", {"demo_0": _robomimic_demo(*good)})
    code, out, err = run_cli(monkeypatch, capsys, *_watch_args(inbox, setup / "rm"))
    assert code == 0, err
    verdicts, _ = _verdicts(out)
    assert verdicts == {"a b.hdf5 / demo_0": "rejected", "a_b.hdf5 / demo_0": "accepted"}
    log = [json.loads(x) for x in (inbox / "verdicts" / "verdicts.jsonl").read_text().splitlines()]
    pages = {r["item"]: r["page"] for r in log}
    assert len(set(pages.values())) == 2 and pages["a_b.hdf5"] == "a_b.hdf5__demo_0.html"
    for item, page in pages.items():
        text = (inbox / "verdicts" / page).read_text()
        assert item in text and ("rejected" if item == "a b.hdf5" else "accepted") in text
    # one-to-one also where the separator hides in a name, or a long name is cut
    from elicit_jax.elicit.watch import page_stem

    stems = {page_stem(i, e) for i, e in [("a__b", "c"), ("a", "b__c"), ("x" * 90, "0"),
                                         ("x" * 91, "0"), ("a b", "0"), ("a_b", "0")]}  # fmt: skip
    assert len(stems) == 6


def test_watch_a_lerobot_folder_that_grows(setup, tmp_path, monkeypatch, capsys):
    def episodes(n):
        rng = np.random.default_rng(1)
        styles = ["base", "other", "base"]
        return [_episode(rng, style=styles[i], dims=(6, 6)) for i in range(n)]

    inbox = tmp_path / "inbox"
    inbox.mkdir()
    _lerobot(inbox / "op2", episodes(2))
    args = _watch_args(inbox, setup / "lr")
    code, out, err = run_cli(monkeypatch, capsys, *args)
    assert code == 0, err
    assert _verdicts(out)[0] == {"op2 / 0": "accepted", "op2 / 1": "rejected"}
    assert (inbox / "verdicts" / "op2__1.html").exists()
    shutil.rmtree(inbox / "op2")  # the recorder adds an episode: only the new one is judged
    _lerobot(inbox / "op2", episodes(3))
    code, out, _ = run_cli(monkeypatch, capsys, *args)
    assert code == 0 and "judged 1 demonstrations" in out
    assert _verdicts(out)[0] == {"op2 / 2": "accepted"}


def test_a_file_still_being_written_is_not_read(setup, tmp_path):
    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.elicit.watch import WatchConfig, Watcher

    inbox = tmp_path / "inbox"
    inbox.mkdir()
    full = tmp_path / "full.hdf5"
    rng = np.random.default_rng(2)
    write_robomimic(full, {"demo_0": _robomimic_demo(*_episode(rng))})
    data = full.read_bytes()
    messages = []
    w = Watcher(
        WatchConfig(
            inbox=str(inbox),
            policy=str(setup / "rm" / "run"),
            base_demos=str(setup / "rm" / "base.parquet"),
            thresholds=Thresholds(0.1, 10.0, "given"),
            settle=1.0,
        ),
        echo=messages.append,
    )
    target = inbox / "new.hdf5"
    target.write_bytes(data[: len(data) // 2])  # the recorder has written half of it
    assert w.scan(now=0.0) == 0 and w.scan(now=0.6) == 0
    target.write_bytes(data)  # ... now all of it: the clock starts again
    assert w.scan(now=0.9) == 0 and w.scan(now=1.5) == 0
    assert w.scan(now=2.0) == 1
    assert len(messages) == 1 and "accepted" in messages[0] and "error" not in messages[0]
