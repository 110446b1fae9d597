"""A disk that fills while elicit-jax writes an HDF5 file: the user's file stays as it was,
the error is one line, no temporary is left behind.

A full disk is simulated for real: the CLI runs in a child process under
``RLIMIT_FSIZE`` (with ``SIGXFSZ`` ignored, so a write past the limit fails with ``EFBIG``,
as a write to a full disk fails with ``ENOSPC``). Other failures are injected in-process.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest
from fixtures_data import robomimic_demo, write_robomimic

from elicit_jax import output_rules
from elicit_jax.data import hdf5_write
from elicit_jax.data.demos import write_demos
from elicit_jax.data.robomimic import import_robomimic

RUNNER = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
limit, no_reserve = int(sys.argv[1]), sys.argv[2] == "1"
if no_reserve:  # let HDF5 itself meet the full disk
    from elicit_jax.data import hdf5_write
    hdf5_write.reserve_space = lambda path, nbytes: None
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
sys.argv = ["elicit-jax", *sys.argv[3:]]
from elicit_jax.cli import main
main()
"""


@pytest.fixture
def robomimic_file(tmp_path):
    """A robomimic file (demo_0..demo_7 with operator masks), its import and its bytes."""
    rng = np.random.default_rng(0)
    demos = {f"demo_{i}": robomimic_demo(rng, 30 + i) for i in range(8)}
    masks = {"op_a": [f"demo_{i}" for i in range(4)], "op_b": [f"demo_{i}" for i in range(4, 8)]}
    path = write_robomimic(tmp_path / "teleop.hdf5", demos, masks)
    parquet = tmp_path / "teleop.parquet"
    write_demos(parquet, import_robomimic(path, operators_from_masks="op_*"))
    return path, parquet, path.read_bytes()


def run_limited(tmp_path, limit: int, *args, no_reserve: bool = False):
    """``elicit-jax ARGS`` in a child process whose files cannot grow past ``limit`` bytes."""
    env = {**os.environ, "ELICIT_JAX_LOG": str(tmp_path / "cli.log")}
    cmd = [sys.executable, "-c", RUNNER, str(limit), "1" if no_reserve else "0", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)


def one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err and "Exception ignored" not in err
    return lines[0]


def temporaries(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def assert_intact(path, before, cli):
    assert path.read_bytes() == before
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: None)
        assert "K" not in f["mask"]
    code, out, err = cli("info", path)
    assert code == 0, err
    assert "robomimic dataset" in out


@pytest.mark.parametrize(
    "room, no_reserve",
    [
        pytest.param(lambda size: size // 2, False, id="no-room-for-the-copy"),
        pytest.param(lambda size: size + 2000, False, id="no-room-for-the-reserve"),
        pytest.param(lambda size: size + 2000, True, id="hdf5-meets-the-full-disk"),
    ],
)
def test_in_place_mask_on_a_full_disk_leaves_the_source_as_it_was(
    robomimic_file, tmp_path, cli, room, no_reserve
):
    path, demos, before = robomimic_file
    done = run_limited(
        tmp_path,
        room(len(before)),
        "export",
        demos,
        "-f",
        "robomimic",
        "--mask-key",
        "K",
        "--in-place",
        no_reserve=no_reserve,
    )
    assert done.returncode == 1, done.stderr
    line = one_line(done.stderr)
    assert line.startswith(f"error: {path}: cannot add mask/K in place (")
    assert "File too large" in line and line.endswith("the source file was not changed")
    assert temporaries(tmp_path) == []
    assert_intact(path, before, cli)


def test_in_place_mask_with_room_replaces_the_file_keeping_its_mode_and_links(
    robomimic_file, tmp_path, cli
):
    path, demos, before = robomimic_file
    os.chmod(path, 0o640)
    link = tmp_path / "link.hdf5"
    link.symlink_to(path.name)
    done = run_limited(
        tmp_path, 3 * len(before) + (4 << 20), "export", demos, "-f", "robomimic",
        "--mask-key", "K", "--source", link, "--in-place",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert link.is_symlink() and os.stat(path).st_mode & 0o777 == 0o640
    with h5py.File(path, "r") as f:
        assert [x.decode() for x in f["mask/K"][:]] == [f"demo_{i}" for i in range(8)]
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("where", ["reserve", "rename"])
def test_in_place_mask_injected_write_errors(robomimic_file, tmp_path, cli, monkeypatch, where):
    path, demos, before = robomimic_file

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    if where == "reserve":
        monkeypatch.setattr(hdf5_write, "reserve_space", full)
    else:
        monkeypatch.setattr(output_rules, "_commit", full)
    code, _, err = cli("export", demos, "-f", "robomimic", "--mask-key", "K", "--in-place")
    assert code == 1
    line = one_line(err)
    assert "No space left on device" in line and "the source file was not changed" in line
    assert temporaries(tmp_path) == []
    assert_intact(path, before, cli)


@pytest.mark.parametrize("limit", [20_000, 100_000])
def test_new_robomimic_file_on_a_full_disk_is_one_line_and_leaves_nothing(
    robomimic_file, tmp_path, limit
):
    _, demos, _ = robomimic_file
    out = tmp_path / "fresh.hdf5"
    done = run_limited(tmp_path, limit, "export", demos, "-f", "robomimic", "-o", out)
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    assert one_line(done.stderr) == f"error: {out}: cannot write (File too large; nothing written)"
    assert not out.exists() and temporaries(tmp_path) == []


def test_masked_copy_on_a_full_disk_is_one_line_and_leaves_nothing(robomimic_file, tmp_path):
    path, demos, before = robomimic_file
    out = tmp_path / "masked.hdf5"
    done = run_limited(
        tmp_path, len(before) + 2000, "export", demos, "-f", "robomimic", "--mask-key", "K",
        "-o", out, no_reserve=True,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    line = one_line(done.stderr)
    assert line.startswith(f"error: {out}: cannot write the masked copy (")
    assert line.endswith("nothing written")
    assert not out.exists() and temporaries(tmp_path) == []
    assert path.read_bytes() == before


KILLED = """
import os, signal, sys
from elicit_jax.data import hdf5_write
real = hdf5_write.edit_copy
def edit_then_die(source, copy, datasets, needs=0):
    real(source, copy, datasets, needs)  # the masked copy is complete: die before the rename
    os.kill(os.getpid(), signal.SIGKILL)
hdf5_write.edit_copy = edit_then_die
from elicit_jax.data import robomimic_export
robomimic_export.edit_copy = edit_then_die
sys.argv = ["elicit-jax", *sys.argv[1:]]
from elicit_jax.cli import main
main()
"""


def test_in_place_mask_killed_before_the_rename_leaves_the_source_and_is_cleaned(
    robomimic_file, tmp_path, cli
):
    path, demos, before = robomimic_file
    args = ["export", str(demos), "-f", "robomimic", "--mask-key", "K", "--in-place"]
    env = {**os.environ, "ELICIT_JAX_LOG": str(tmp_path / "cli.log")}
    done = subprocess.run(
        [sys.executable, "-c", KILLED, *args], capture_output=True, env=env, timeout=120
    )
    assert done.returncode == -9
    assert len(temporaries(tmp_path)) == 1  # the killed writer's copy, beside the source
    assert_intact(path, before, cli)
    code, _, err = cli(*args)  # the next export removes it and adds the mask
    assert code == 0, err
    assert temporaries(tmp_path) == []
    with h5py.File(path, "r") as f:
        assert len(f["mask/K"]) == 8


def test_any_artifact_on_a_full_disk_names_its_output(robomimic_file, tmp_path):
    """A Parquet or ``.npz`` writer meeting a full disk: one line naming the output."""
    _, demos, _ = robomimic_file
    for out, args in (
        (tmp_path / "sel.parquet", ("demos", "select", demos, "--episodes", "0-7")),
        (tmp_path / "d.npz", ("export", demos, "-f", "npz")),
    ):
        done = run_limited(tmp_path, 4_000, *args, "-o", out)
        assert done.returncode == 1, done.stderr
        line = one_line(done.stderr)
        assert line.startswith(f"error: {out}: cannot write (") and "nothing written" in line
        assert not out.exists() and temporaries(tmp_path) == []
