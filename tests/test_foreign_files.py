"""The user's files in an output folder are never deleted: a training run, a report or a
pipeline run directory holding files their writer did not write is refused, naming them;
an output inside the run an input belongs to is refused (issue 45, items 2 and 3)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fixtures_data import invoke, tiny_run, tiny_train_config

from elicit_jax.artifact import file_sha256, write_json
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("foreign"))


def snapshot(folder: Path) -> dict[str, str]:
    return {
        p.relative_to(folder).as_posix(): file_sha256(p)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_train_overwrite_never_deletes_the_users_files_in_a_run(work, tmp_path):
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.train import train_policy

    demos = read_demos(work / "demos.parquet")
    run = tmp_path / "b"
    train_policy(demos, tiny_train_config(), run, quiet=True)
    (run / "NOTES.md").write_text("my notes")
    (run / "eval").mkdir()
    (run / "eval" / "rollouts.csv").write_text("1,2")
    (run / "seed0" / "mine.txt").write_text("mine")
    before = snapshot(run)
    for overwrite, config in ((True, tiny_train_config(seeds=(1,))), (False, tiny_train_config())):
        with pytest.raises(ElicitError) as e:
            train_policy(demos, config, run, quiet=True, overwrite=overwrite)
        text = str(e.value)
        assert "holds files a training run did not write" in text
        for name in ("NOTES.md", "eval/rollouts.csv", "seed0/mine.txt"):
            assert name in text
        assert snapshot(run) == before
    # once the user's files are moved out, the run is replaced as before
    for name in ("NOTES.md", "seed0/mine.txt"):
        (run / name).unlink()
    shutil.rmtree(run / "eval")
    train_policy(demos, tiny_train_config(seeds=(1,)), run, quiet=True, overwrite=True)
    assert (run / "seed1").is_dir() and not (run / "seed0").exists()


def test_an_output_inside_the_run_an_input_belongs_to_is_refused(work):
    header = work / "run" / "artifact.json"
    before = file_sha256(header)
    for policy in (work / "run" / "seed0", work / "run"):
        r = invoke(
            "score", "--policy", policy, "--demos", work / "demos.parquet",
            "-o", header, "--overwrite",
        )  # fmt: skip
        assert isinstance(r.exception, ElicitError), r.output
        assert "refusing to write here" in str(r.exception)
    assert file_sha256(header) == before
    r = invoke(
        "score", "--policy", work / "run" / "seed0", "--demos", work / "demos.parquet",
        "-o", work / "run" / "mine.parquet",
    )  # fmt: skip
    assert f"inside {work / 'run'}, the artifact the input" in str(r.exception)
    assert not (work / "run" / "mine.parquet").exists()


def test_pipeline_run_refuses_a_folder_it_did_not_make(tmp_path, cli):
    d = tmp_path / "d"
    (d / "report").mkdir(parents=True)
    (d / "report" / "report.md").write_text("my report")
    before = snapshot(d)
    code, _, err = cli("pipeline", "run", "quickstart", "--profile", "cpu", "--out", d)
    assert code == 1
    assert err.strip().splitlines()[-1] == (
        f"error: {d}: holds files not made by a pipeline run (report/report.md); elicit-jax "
        "writes only into a new folder or an earlier run's: choose another --out"
    )
    assert snapshot(d) == before
    # an earlier run's folder resumes, but its report folder must be a report
    write_json(d / "run.json", {"kind": "pipeline-run"})
    code, _, err = cli("pipeline", "run", "quickstart", "--profile", "cpu", "--out", d)
    assert code == 1 and "holding no report written by elicit-jax" in err
    assert (d / "report" / "report.md").read_text() == "my report"
    from elicit_jax.pipeline.run import check_run_dir

    shutil.rmtree(d / "report")
    check_run_dir(d)  # a run directory with no report yet: fine
    check_run_dir(tmp_path / "new")
    (tmp_path / "empty").mkdir()
    check_run_dir(tmp_path / "empty")


def test_a_report_holding_the_users_files_is_not_replaced(tmp_path, cli):
    folder = tmp_path / "quickstart"
    shutil.copytree(Path(__file__).parents[1] / "docs" / "results" / "quickstart-cpu", folder)
    code, _, err = cli("report", "--rebuild", folder)
    assert code == 0, err  # a report with only its own files is rebuilt in place
    (folder / "maps").mkdir(exist_ok=True)
    (folder / "maps" / "my-notes.txt").write_text("mine")
    before = snapshot(folder)
    code, _, err = cli("report", "--rebuild", folder)
    assert code == 1
    assert "holds files a report did not write (maps/my-notes.txt)" in err
    assert snapshot(folder) == before


def test_elicit_overwrite_never_deletes_the_users_files_in_a_session(tmp_path):
    from elicit_jax.elicit.store import SESSION_KIND, SessionStore

    store = SessionStore(tmp_path / "s")
    store.create({"kind": SESSION_KIND, "schema_version": 1})
    (store.episodes_dir / "e000000.parquet").write_bytes(b"episode")
    (store.root / "policies" / "batch1" / "seed0").mkdir(parents=True)
    (store.root / "policies" / "batch1" / "seed0" / "loss.parquet").write_bytes(b"loss")
    (store.root / "NOTES.md").write_text("my notes")
    (store.root / "policies" / "batch1" / "mine.txt").write_text("mine")
    before = snapshot(store.root)
    with pytest.raises(ElicitError) as e:
        store.wipe()  # what `elicit -o s --overwrite` does to start the session again
    assert "holds files an elicitation session did not write" in str(e.value)
    assert "NOTES.md" in str(e.value) and "policies/batch1/mine.txt" in str(e.value)
    assert snapshot(store.root) == before
    (store.root / "NOTES.md").unlink()
    (store.root / "policies" / "batch1" / "mine.txt").unlink()
    # a killed writer's temporary is elicit-jax's own
    (store.episodes_dir / ".e000001.parquet.p999999999-0123abcd.x1.tmp").mkdir()
    store.wipe()
    assert not store.root.exists()


def test_export_overwrite_replaces_only_a_lerobot_dataset_it_exported(tmp_path):
    import numpy as np
    from fixtures_data import lerobot_episode, robomimic_demo, write_lerobot_v30, write_robomimic

    from elicit_jax.data.demos import write_demos
    from elicit_jax.data.export import export_dataset
    from elicit_jax.data.export_config import ExportConfig
    from elicit_jax.data.robomimic import import_robomimic

    rng = np.random.default_rng(0)
    src = write_robomimic(
        tmp_path / "r.hdf5", {f"demo_{i}": robomimic_demo(rng, 5) for i in range(3)}
    )
    demos = tmp_path / "d.parquet"
    write_demos(demos, import_robomimic(src))

    def export(out):
        cfg = ExportConfig(str(demos), "lerobot", str(out), fps=20, overwrite=True)
        return export_dataset(cfg)

    export(tmp_path / "ours")
    export(tmp_path / "ours")  # an earlier export: replaced with --overwrite
    theirs = write_lerobot_v30(
        tmp_path / "theirs", [lerobot_episode(rng, i, 6) for i in range(2)], ["pick"]
    )
    before = snapshot(theirs)
    with pytest.raises(ElicitError, match="is an existing directory"):
        export(theirs)  # recorded by LeRobot, not exported by elicit-jax: never replaced
    assert snapshot(theirs) == before
