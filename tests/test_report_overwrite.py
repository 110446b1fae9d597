"""`elicit-jax report RUN_DIR` replaced an existing report without asking: the user's edited
report.md was gone, exit 0. It now needs --overwrite, like every other output."""

import json
from pathlib import Path

from fixtures_data import invoke

from elicit_jax.errors import ElicitError

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


def test_an_existing_report_is_replaced_only_with_overwrite(tmp_path):
    report = tmp_path / "run" / "report"
    report.mkdir(parents=True)
    (report / "artifact.json").write_text(json.dumps({"kind": "pipeline-report"}))
    (report / "report.md").write_text("my reading of the run")
    r = invoke("report", tmp_path / "run")
    assert isinstance(r.exception, ElicitError), r.output
    assert "already exists; pass --overwrite" in str(r.exception)
    assert (report / "report.md").read_text() == "my reading of the run"
    r = invoke("report", tmp_path / "run", "--overwrite")  # past the check: no run to report
    assert "--overwrite" not in str(r.exception)


def test_a_rebuild_onto_an_existing_report_needs_overwrite(tmp_path):
    folder = next(p for p in sorted(RESULTS.iterdir()) if (p / "report-data.json").is_file())
    out = tmp_path / "b"
    out.mkdir()
    (out / "artifact.json").write_text(json.dumps({"kind": "study-report"}))
    (out / "report.md").write_text("edited")
    r = invoke("report", "--rebuild", folder, "-o", out)
    assert "already exists; pass --overwrite" in str(r.exception)
    assert (out / "report.md").read_text() == "edited"
