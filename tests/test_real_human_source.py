"""benchmarks/real_human_source.py: the public source is checked before anything is rebuilt from it.

The source itself (robosuite 1.0.1's wheel) is not in the repository and is never downloaded,
so these tests cover what the script does with a path it is given: a missing path says where
to get the source, a wheel without the demo or a file with other bytes is refused by name,
and a recorded ``[time, qpos, qvel]`` state lands in the right places of the simulation.
"""

import importlib.util
import io
import json
import types
import zipfile
from pathlib import Path

import h5py
import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "real_human_source.py"


@pytest.fixture(scope="module")
def rh():
    spec = importlib.util.spec_from_file_location("real_human_source", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_missing_source_says_where_to_download_it(rh, tmp_path):
    with pytest.raises(SystemExit, match=r"pip download --no-deps robosuite==1\.0\.1"):
        rh.read_source(tmp_path / "robosuite-1.0.1-py3-none-any.whl")


def test_wheel_without_the_demo_is_refused(rh, tmp_path):
    wheel = tmp_path / "robosuite-1.5.1-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        z.writestr("robosuite/__init__.py", "")
    with pytest.raises(SystemExit, match=r"robosuite-1\.5\.1.*no robosuite/models/assets"):
        rh.read_source(wheel)


@pytest.mark.parametrize("in_wheel", [False, True])
def test_other_bytes_are_refused_by_hash(rh, tmp_path, in_wheel):
    path = tmp_path / ("w.whl" if in_wheel else "demo.hdf5")
    if in_wheel:
        with zipfile.ZipFile(path, "w") as z:
            z.writestr(rh.SOURCE_MEMBER, b"not the demo")
    else:
        path.write_bytes(b"not the demo")
    with pytest.raises(SystemExit, match=rf"{path.name}: demo SHA-256 [0-9a-f]{{12}}"):
        rh.read_source(path)


def _demo_file(n_demos: int) -> bytes:
    buf = io.BytesIO()
    with h5py.File(buf, "w") as f:
        data = f.create_group("data")
        data.attrs["env_info"] = json.dumps({"env_name": "NutAssembly", "robots": "Panda"})
        data.attrs["date"], data.attrs["repository_version"] = "9-4-2020", "1.0.0"
        for i in range(1, n_demos + 1):
            g = data.create_group(f"demo_{i}")
            g["states"] = np.arange(12.0).reshape(3, 4) + i
            g["actions"] = np.full((3, 7), 0.5)
    return buf.getvalue()


def test_load_demo_reads_the_one_demonstration(rh):
    demo = rh.load_demo(_demo_file(1))
    assert demo["name"] == "demo_1"
    np.testing.assert_array_equal(demo["states"][0], [1.0, 2.0, 3.0, 4.0])
    assert demo["actions"].shape == (3, 7)
    assert demo["env_info"]["env_name"] == "NutAssembly" and demo["date"] == "9-4-2020"


def test_load_demo_refuses_several(rh):
    with pytest.raises(SystemExit, match=r"expected one demonstration.*demo_1.*demo_2"):
        rh.load_demo(_demo_file(2))


def _sim(nq: int, nv: int):
    calls = []
    data = types.SimpleNamespace(qpos=np.zeros(nq), qvel=np.zeros(nv))
    sim = types.SimpleNamespace(
        model=types.SimpleNamespace(nq=nq, nv=nv), data=data, forward=lambda: calls.append(1)
    )
    return types.SimpleNamespace(sim=sim), calls


def test_set_state_splits_time_qpos_qvel(rh):
    env, calls = _sim(nq=3, nv=2)
    rh.set_state(env, np.array([0.05, 1.0, 2.0, 3.0, -1.0, -2.0]))
    np.testing.assert_array_equal(env.sim.data.qpos, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(env.sim.data.qvel, [-1.0, -2.0])
    assert calls == [1]


def test_set_state_refuses_another_models_state(rh):
    env, calls = _sim(nq=23, nv=21)
    with pytest.raises(SystemExit, match=r"state has 40 values, this model needs 1 \+ 23 \+ 21"):
        rh.set_state(env, np.zeros(40))
    assert calls == []
