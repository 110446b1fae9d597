"""Plain .npz archives: boundaries by lengths or episode ids, optional arrays, errors, export."""

from __future__ import annotations

import re

import numpy as np
import pytest

from elicit_jax.data.demos import SOURCE_EPISODE
from elicit_jax.data.npz import export_npz, import_npz
from elicit_jax.errors import ElicitError


def _arrays(rng, lengths=(2, 3, 1)):
    n = sum(lengths)
    return {
        "obs": rng.normal(size=(n, 3)),
        "act": rng.uniform(-1, 1, size=(n, 2)),
        "lengths": np.array(lengths),
    }


def test_lengths_and_optional_arrays(tmp_path):
    rng = np.random.default_rng(0)
    arrays = _arrays(rng)
    arrays["operators"] = np.array(["a", "b", "a"])
    arrays["success"] = np.array([True, False, True])
    arrays["rewards"] = np.arange(6, dtype=np.float32)
    np.savez(tmp_path / "d.npz", **arrays)
    demos = import_npz(tmp_path / "d.npz", task="reach")
    # lengths 2, 3, 1 -> episodes over rows [0, 2), [2, 5), [5, 6)
    assert demos.episode.tolist() == [0, 0, 1, 1, 1, 2]
    assert demos.step.tolist() == [0, 1, 0, 1, 2, 0]
    assert demos.operator.tolist() == ["a", "a", "b", "b", "b", "a"]
    assert demos.success.tolist() == [True, True, False, False, False, True]
    assert demos.reward.tolist() == [0, 1, 2, 3, 4, 5]
    np.testing.assert_allclose(demos.obs, arrays["obs"], rtol=1e-6)
    assert demos.task == "reach" and demos.provenance["importer"] == "npz"


def test_episode_ids_and_action_key(tmp_path):
    rng = np.random.default_rng(1)
    a = _arrays(rng)
    ids = np.array([7, 7, 3, 3, 3, 9])
    np.savez(
        tmp_path / "d.npz",
        obs=a["obs"],
        action=a["act"],
        episode_ids=ids,
        operators=np.array(["x"] * 6),
    )
    demos = import_npz(tmp_path / "d.npz")
    assert demos.n_episodes == 3 and demos.episode.tolist() == [0, 0, 1, 1, 1, 2]
    assert demos.extra[SOURCE_EPISODE].tolist() == ["7", "7", "3", "3", "3", "9"]
    assert set(demos.operator) == {"x"} and demos.success.all()


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda a: a.pop("obs"), "has no 'obs' array"),
        (lambda a: a.pop("act"), "has no 'act' or 'action' array"),
        (lambda a: a.pop("lengths"), "needs 'lengths' or 'episode_ids'"),
        (
            lambda a: a.update(lengths=np.array([2, 4, 1])),
            "'lengths' sum to 7 but 'obs' has 6 rows",
        ),
        (
            lambda a: a.update(lengths=np.array([2, 0, 3, 1])),
            r"episode 1 is empty \(lengths\[1\] = 0\)",
        ),
        (lambda a: a.update(act=a["act"][:5]), "'obs' has 6 rows but 'act' has 5"),
        (lambda a: a.update(obs=a["obs"][:, 0]), "must be 2-D"),
        (
            lambda a: a["obs"].__setitem__((3, 2), np.nan),
            r"non-finite obs\[2\] value at episode 1 \(1\), step 1",
        ),
        (lambda a: a["act"].__setitem__((5, 0), 4.0), None),
        (
            lambda a: (a.pop("lengths"), a.update(episode_ids=np.array([0, 0, 1, 1, 0, 2]))),
            r"episode id 0 is not contiguous \(resumes at row 4\)",
        ),
        (
            lambda a: a.update(operators=np.array(["a", "b"])),
            "'operators' has 2 entries: expected 3 or 6",
        ),
    ],
)
def test_errors_name_the_file(tmp_path, edit, message):
    arrays = _arrays(np.random.default_rng(2))
    edit(arrays)
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    if message is None:  # out-of-bounds actions are accepted by the importer, checked on write
        assert import_npz(path).action.max() == 4.0
        return
    with pytest.raises(ElicitError) as err:
        import_npz(path)
    assert str(err.value).startswith(f"{path}: ")
    assert re.search(message, str(err.value)), str(err.value)


def test_not_an_archive(tmp_path):
    (tmp_path / "x.npz").write_text("no zip here")
    with pytest.raises(ElicitError, match=r"not a \.npz archive: a \.npz is a zip file"):
        import_npz(tmp_path / "x.npz")


def test_export_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    arrays = _arrays(rng, (4, 2))
    arrays["operators"] = np.array(["p", "q"])
    np.savez(tmp_path / "d.npz", **arrays)
    demos = import_npz(tmp_path / "d.npz")
    export_npz(demos.select_episodes([1]), tmp_path / "out.npz", header={"kind": "export"})
    with np.load(tmp_path / "out.npz") as z:
        assert z["lengths"].tolist() == [2] and z["operators"].tolist() == ["q"]
        assert z["source_episode"].tolist() == ["1"]
        assert "export" in str(z["elicit_jax_header"])
    back = import_npz(tmp_path / "out.npz")
    np.testing.assert_array_equal(back.obs, demos.obs[4:])
    assert back.extra[SOURCE_EPISODE].tolist() == ["1", "1"]
