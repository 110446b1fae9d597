"""One line naming the file and the problem (issue #27, 15): a Parquet file given as
thresholds, a .npz that is not a zip archive, watch errors, operator lists; no "best
validation loss" warning without a validation set; the in-sample accuracy the leave-one-out
check quotes is the one the report shows."""

import numpy as np
import pytest
from fixtures_data import invoke, tiny_run

from elicit_jax.artifact import make_header, write_parquet
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("errors"))


def _one_line(r, path, text):
    assert isinstance(r.exception, ElicitError), r.exception
    msg = str(r.exception)
    assert msg.startswith(f"{path}: ") and text in msg and "\n" not in msg, msg
    return msg


def test_a_parquet_file_given_as_thresholds(run, tmp_path):
    demos = run / "demos.parquet"
    r = invoke(
        "filter",
        "--scores",
        demos,
        "--demos",
        demos,
        "--thresholds",
        demos,
        "-o",
        tmp_path / "f.parquet",
    )
    _one_line(r, demos, "is a Parquet file, not a thresholds .json")
    # any binary file read as JSON
    blob = tmp_path / "blob.json"
    blob.write_bytes(bytes(range(256)))
    r = invoke("info", blob)
    _one_line(r, blob, "not a JSON file: it is binary, not text")


def test_a_file_of_random_bytes_named_npz(run, tmp_path):
    bad = tmp_path / "random.npz"
    bad.write_bytes(np.random.default_rng(0).bytes(4000))
    r = invoke("import", bad, "-o", tmp_path / "d.parquet")
    msg = _one_line(r, bad, "not a .npz archive: a .npz is a zip file")
    assert "pickle" not in msg
    # the same reader guards a checkpoint's parameter files
    import shutil

    shutil.copytree(run / "run", tmp_path / "run")
    (tmp_path / "run" / "seed0" / "params" / "best.npz").write_bytes(bad.read_bytes())
    r = invoke(
        "score",
        "--policy",
        tmp_path / "run",
        "--demos",
        run / "demos.parquet",
        "-o",
        tmp_path / "s.parquet",
    )
    msg = str(r.exception)
    assert "unreadable parameter file: not a .npz archive" in msg and "pickle" not in msg


def test_watch_errors_name_the_item(run, tmp_path):
    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.elicit.watch import WatchConfig, Watcher

    inbox = tmp_path / "inbox"
    inbox.mkdir()
    item = inbox / "op.npz"
    np.savez(
        item, obs=np.zeros((5, 3), np.float32), action=np.zeros((5, 2), np.float32), lengths=[5]
    )
    lines = []
    config = WatchConfig(
        inbox=str(inbox),
        policy=str(run / "run"),
        base_demos=str(run / "demos.parquet"),
        thresholds=Thresholds(0.4, 0.05, "given"),
        import_options=(("obs_keys", ("a", "b")),),
        settle=0.0,
    )
    Watcher(config, echo=lines.append).scan(now=1e9)
    assert lines == [f"error: {item}: --obs-keys does not apply to .npz files (one 'obs' array)"]
    # a reader's own error (text actions in a robomimic file) names the item, and the
    # watcher goes on
    import h5py

    bad = inbox / "text.hdf5"
    with h5py.File(bad, "w") as f:
        f.create_dataset("data/demo_0/actions", data=np.array([b"a", b"b"]))
    lines.clear()
    Watcher(config, echo=lines.append).scan(now=1e9)  # judges both items again
    assert sorted(lines) == [
        f"error: {item}: --obs-keys does not apply to .npz files (one 'obs' array)",
        f"error: {bad}: data/demo_0/actions holds |S1 values, not numbers (bytes or text "
        "where a robomimic file has floats)",
    ]


def test_operator_lists_are_plain_names(run, tmp_path):
    demos = run / "demos.parquet"
    r = invoke("demos", "select", demos, "--operator", "nobody", "-o", tmp_path / "x.parquet")
    msg = _one_line(r, demos, "has no operator 'nobody' (operators: base)")
    assert "np." not in msg
    # a contrast selection that matches nothing names the scores file and its operators
    import pyarrow as pa

    s = tmp_path / "s.parquet"
    table = pa.table(
        {
            "episode": pa.array(np.repeat([0, 1], 3).astype(np.int64)),
            "operator": pa.array(["base"] * 3 + ["op2"] * 3),
            "likelihood": pa.array(np.zeros(6, np.float32)),
            "novelty": pa.array(np.zeros(6, np.float32)),
        }
    )
    write_parquet(s, table, make_header("scores", 1))
    r = invoke(
        "fit-thresholds",
        "--scores",
        s,
        "--compatible",
        "operator:nobody",
        "--incompatible",
        "episodes:1",
        "-o",
        tmp_path / "t.json",
    )
    _one_line(
        r, s, "selection 'operator:nobody' matches no episode in the scores (operators: base, op2)"
    )


def test_no_validation_warning_without_a_validation_set():
    from fixtures_data import tiny_train_config

    from elicit_jax.policy.train import training_warnings

    config = tiny_train_config(epochs=5, val_fraction=0.0)
    action = np.random.default_rng(0).uniform(-1, 1, (50, 2))
    no_val = {0: (np.ones((5, 2)), np.full((5, 2), np.nan), 5, 1.0)}
    assert not any("validation" in w for w in training_warnings(config, action, no_val))
    with_val = {0: (np.ones((5, 2)), np.linspace(1, 0, 10).reshape(5, 2), 5, 1.0)}
    (w,) = [w for w in training_warnings(config, action, with_val) if "validation" in w]
    assert "best validation loss is at the last epoch (5)" in w


def _loo_gap_scores(path):
    """3 compatible and 6 incompatible demos (seed 65 of this generator) whose fit decides 8
    of 9 right in sample and 6 of 9 held out: the leave-one-out check fires."""
    import pyarrow as pa

    rng = np.random.default_rng(65)
    ell, nu, ep = [], [], []
    for e in range(9):
        x = rng.uniform(0, 0.1, 30)
        k = rng.integers(0, 6) if e < 3 else rng.integers(0, 8)
        x[:k] = rng.uniform(0.1, 0.5, k)
        ell.append(x)
        nu.append(rng.uniform(0, 0.01, 30))
        ep.append(np.full(30, e))
    ell, nu, ep = map(np.concatenate, (ell, nu, ep))
    ops = np.where(ep < 3, "good", "bad")
    table = pa.table(
        {
            "episode": pa.array(ep.astype(np.int64)),
            "operator": pa.array(ops.tolist()),
            "likelihood": pa.array(ell.astype(np.float32)),
            "novelty": pa.array(nu.astype(np.float32)),
        }
    )
    write_parquet(path, table, make_header("scores", 1))
    return path


def test_the_in_sample_accuracy_quoted_is_the_one_the_report_shows(tmp_path, capsys):
    from rich.console import Console

    from elicit_jax.compat.fit import FitJob, fit_scores_file
    from elicit_jax.compat.show import print_report

    s = _loo_gap_scores(tmp_path / "s.parquet")
    job = FitJob("operator:good", "operator:bad", force=True)
    h = fit_scores_file(s, tmp_path / "t.json", job, show=lambda h: print_report(h, Console()))
    rep = h["report"]
    right = sum(c["rejected"] != c["compatible"] for c in rep["contrast"])
    assert (right, len(rep["contrast"]), rep["n_loo"]) == (8, 9, 9)
    assert rep["in_sample_accuracy"] == pytest.approx(8 / 9)
    assert rep["loo_accuracy"] == pytest.approx(6 / 9)
    assert rep["balanced_accuracy"] != pytest.approx(8 / 9)  # so it cannot stand for it
    (msg,) = [p for p in rep["trust"]["problems"] if "leave-one-out" in p]
    assert (
        "leave-one-out accuracy 0.667 is well below the in-sample accuracy 0.889 of the same 9"
        in msg
    )
    out = " ".join(capsys.readouterr().out.split())
    assert "in-sample accuracy of those demos │ 0.889" in out
    assert "leave-one-out accuracy │ 0.667 (9 held out)" in out


def test_info_on_an_empty_sessions_folder_says_what_it_looked_for(tmp_path):
    folder = tmp_path / "sessions"
    folder.mkdir()
    msg = _one_line(invoke("info", folder), folder, "no elicit-jax artifact")
    assert "operator session" in msg and "until an operator starts" in msg


def test_byte_actions_in_an_hdf5_name_the_file_and_dataset(tmp_path):
    """#45 Also: numpy's "could not convert string to float" named neither."""
    import h5py

    bad = tmp_path / "bytes.hdf5"
    with h5py.File(bad, "w") as f:
        f.create_dataset("data/demo_0/actions", data=np.array([b"a", b"b"]))
        f.create_dataset("data/demo_0/obs/robot0_eef_pos", data=np.zeros((2, 3)))
    r = invoke("import", bad, "-o", tmp_path / "d.parquet", "--obs-keys", "robot0_eef_pos")
    _one_line(r, bad, "data/demo_0/actions holds |S1 values, not numbers")
    with h5py.File(bad, "a") as f:
        del f["data/demo_0/actions"]
        f.create_dataset("data/demo_0/actions", data=np.zeros((2, 2)))
        del f["data/demo_0/obs/robot0_eef_pos"]
        f.create_dataset("data/demo_0/obs/robot0_eef_pos", data=np.array(["x", "y"], "S"))
    r = invoke("import", bad, "-o", tmp_path / "d.parquet", "--obs-keys", "robot0_eef_pos")
    _one_line(r, bad, "data/demo_0/obs/robot0_eef_pos holds |S1 values, not numbers")


def test_a_full_disk_in_demos_select_names_the_output(run, tmp_path):
    """A file size limit (as `ulimit -f`) stands in for a full disk: pyarrow's error names no
    file; the command's names the output, and nothing is left behind."""
    import os
    import subprocess
    import sys

    out = tmp_path / "out" / "sel.parquet"
    out.parent.mkdir()
    code = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (1000, 1000))\n"
        f"sys.argv = ['elicit-jax', 'demos', 'select', {str(run / 'demos.parquet')!r},"
        f" '--episodes', '0-5', '-o', {str(out)!r}]\n"
        "from elicit_jax.cli import main\n"
        "main()\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=dict(os.environ), timeout=300)  # fmt: skip
    assert p.returncode == 1, p.stderr
    line = p.stderr.strip().splitlines()[-1]
    assert line.startswith(f"error: {out}: cannot write (") and "nothing" in line
    assert "written" in line.split("nothing", 1)[1]
    assert list(out.parent.iterdir()) == []


def test_a_malformed_review_state_names_the_file(run, tmp_path):
    import json

    from elicit_jax.artifact import file_sha256

    demos = run / "demos.parquet"
    folder = tmp_path / "review"
    folder.mkdir()
    state = folder / "review.json"
    good = {"kind": "review", "demos": str(demos), "demos_sha256": file_sha256(demos)}
    for content, text in [
        ([1, 2], "malformed review state: not a JSON object"),
        ({**good, "flags": ["0"]}, "malformed review state: 'flags' is not an object"),
        ({**good, "flags": {"x": "why"}}, "flag 'x' names no episode of the demos"),
        ({**good, "flags": {"99": "why"}}, "flag '99' names no episode of the demos"),
        ({**good, "flags": {"0": 7}}, "the reason for episode 0 is not a one-line text"),
    ]:
        state.write_text(json.dumps(content))
        r = invoke("review", demos, "-o", folder)
        _one_line(r, state, text)
