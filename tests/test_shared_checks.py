"""What one command refuses, every command refuses (issue #45, item 10 and its "Also"): a demo
repeated inside one HDF5, a mask naming a demo the file lacks, demos files `select` and
`train` refuse (shuffled rows, step gaps, schema 99) given to `score`, parameter files copied
in from another run, operator names with a newline."""

import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fixtures_data import invoke, robomimic_demo, tiny_run, write_robomimic

from elicit_jax.artifact import read_header, write_parquet
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("shared"))


def _error(r, path, text):
    assert isinstance(r.exception, ElicitError), (r.exception, r.output)
    msg = str(r.exception)
    assert msg.startswith(f"{path}: ") and text in msg and "\n" not in msg, msg
    return msg


def _robomimic(tmp_path, masks=None, duplicate=False):
    rng = np.random.default_rng(1)
    demos = {f"demo_{i}": robomimic_demo(rng, 10) for i in range(4)}
    if duplicate:
        demos["demo_3"] = {k: np.array(v) for k, v in demos["demo_1"].items()}
    return write_robomimic(tmp_path / "src.hdf5", demos, masks=masks)


def test_a_demo_repeated_inside_one_hdf5_is_refused_unless_allowed(tmp_path):
    src = _robomimic(tmp_path, duplicate=True)
    out = tmp_path / "d.parquet"
    r = invoke("import", src, "-o", out)
    _error(r, src, "1 episode(s) repeat earlier ones step for step: episode 3 (demo_3) repeats "
           "episode 1 (demo_1); pass --allow-duplicates")  # fmt: skip
    assert not out.exists()
    r = invoke("import", src, "-o", out, "--allow-duplicates")
    assert r.exit_code == 0, r.output
    assert "kept: --allow-duplicates" in r.output
    # a file without repeats imports as before
    r = invoke("import", _robomimic(tmp_path), "-o", out, "--overwrite")
    assert r.exit_code == 0 and "repeat earlier" not in r.output, r.output


def test_a_mask_naming_a_missing_demo_is_refused(tmp_path):
    src = _robomimic(tmp_path, masks={"op_a": ["demo_0", "demo_1"], "op_b": ["demo_2", "demo_9"]})
    out = tmp_path / "d.parquet"
    r = invoke("import", src, "-o", out, "--operators-from-masks", "op_*")
    _error(r, src, "mask/op_b lists demo_9, which is not in the file (no data/demo_9)")
    assert not out.exists()


def test_operator_names_are_printable_one_line_text(tmp_path):
    src = _robomimic(tmp_path)
    out = tmp_path / "d.parquet"
    r = invoke("import", src, "-o", out, "--operator", "bad\nname")
    _error(r, "--operator", "operator name 'bad\\nname' holds a newline")
    assert not out.exists()
    r = invoke("import", src, "-o", out, "--operator", "tab\there")
    assert isinstance(r.exception, ElicitError) and not out.exists()
    r = invoke("import", src, "-o", out, "--operator", "Ana María (2nd try)")
    assert r.exit_code == 0, r.output


def _tampered(run, tmp_path, name, change):
    """A copy of the run's demos file whose table (and header) ``change`` alters."""
    src = run / "demos.parquet"
    header = read_header(src)
    table = pq.read_table(src).replace_schema_metadata(None)
    table, header = change(table, dict(header))
    out = tmp_path / name
    write_parquet(out, table, header)
    return out


def _shuffled(table, header):
    order = np.random.default_rng(0).permutation(table.num_rows)
    return table.take(pa.array(order)), header


def _step_gap(table, header):
    step = table.column("step").to_numpy().copy()
    step[3] += 1  # episode 0: steps 0, 1, 2, 4, ...
    i = table.column_names.index("step")
    return table.set_column(i, "step", pa.array(step, pa.int32())), header


def _schema_99(table, header):
    return table, {**header, "schema_version": 99}


@pytest.mark.parametrize(
    ("change", "text"),
    [
        (_shuffled, "is not contiguous"),
        (_step_gap, "episode 0: steps must run 0..19 in order, found step 4 at position 3"),
        (_schema_99, "schema version 99 is newer than this elicit-jax understands"),
    ],
)
def test_score_refuses_the_demos_files_select_and_train_refuse(run, tmp_path, change, text):
    bad = _tampered(run, tmp_path, "bad.parquet", change)
    r = invoke("demos", "select", bad, "--episodes", "0", "-o", tmp_path / "sel.parquet")
    expected = _error(r, bad, text)
    out = tmp_path / "s.parquet"
    r = invoke("score", "--policy", run / "run", "--demos", bad, "-o", out)
    assert _error(r, bad, text) == expected  # the same check, the same words
    assert not out.exists()


def test_parameters_copied_from_another_run_are_detected(run, tmp_path):
    other = tiny_run(tmp_path / "other", seeds=(0,), epochs=4, checkpoint_every=2)
    copy = tmp_path / "run"
    shutil.copytree(run / "run", copy)
    best = copy / "seed0" / "params" / "best.npz"
    shutil.copyfile(other / "run" / "seed0" / "params" / "best.npz", best)
    r = invoke("info", copy)
    assert r.exit_code == 0, r.output
    assert "check: ok" not in r.output and "check: 1 of 1 seeds have problems" in r.output
    assert "does not match the sha256" in " ".join(r.output.split())
    out = tmp_path / "s.parquet"
    r = invoke("score", "--policy", copy, "--demos", run / "demos.parquet", "-o", out)
    _error(r, best, "does not match the sha256 its checkpoint's artifact.json recorded")
    assert not out.exists()
    # the normalisation statistics too, and a parameter file the run never wrote
    shutil.copytree(run / "run", tmp_path / "run2")
    norm = tmp_path / "run2" / "seed0" / "normalization.npz"
    stats = dict(np.load(norm))
    with open(norm, "wb") as f:  # statistics of other data
        np.savez(f, **{**stats, "obs_mean": stats["obs_mean"] + 0.5})
    r = invoke("score", "--policy", tmp_path / "run2", "--demos", run / "demos.parquet", "-o", out)
    _error(r, norm, "does not match the sha256")
    shutil.copytree(run / "run", tmp_path / "run3")
    extra = tmp_path / "run3" / "seed0" / "params" / "epoch_0004.npz"
    shutil.copyfile(other / "run" / "seed0" / "params" / "epoch_0004.npz", extra)
    r = invoke("info", tmp_path / "run3")
    assert "records no hash for it" in " ".join(r.output.split())
    # the untouched run is still fine
    r = invoke("info", run / "run")
    assert "check: ok" in r.output
