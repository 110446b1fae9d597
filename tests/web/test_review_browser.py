"""The review page (`elicit-jax review`) in real headless Chromium: sort, replay, flag two
episodes with reasons, write the selection as a robomimic mask, and re-import without them;
and the server's Host check and token."""

from __future__ import annotations

import urllib.error
import urllib.request

import pytest
from chromium import page_with_errors
from cli_server import CliServer
from fixtures_data import cli_ok
from review_data import imported_demos


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """Six robomimic demos imported as square-nut data (see review_data.imported_demos)."""
    return imported_demos(tmp_path_factory.mktemp("review"))


def _status(url: str, host: str | None = None) -> int:
    req = urllib.request.Request(url, headers={"Host": host} if host else {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def test_review_flags_two_episodes_and_the_export_reimports_without_them(
    browser,
    imported,
):
    d = imported
    server = CliServer(
        "review", d / "demos.parquet", "--scores", d / "scores.parquet",
        "--quality", d / "quality.parquet", "-o", d / "rv",
    )  # fmt: skip
    try:
        url = server.start()
        base = url.split("?")[0]
        port = base.rstrip("/").rsplit(":", 1)[1]
        assert _status(base) == 403  # no token
        assert _status(url, host=f"evil.example:{port}") == 400  # DNS rebinding
        assert _status(url) == 200
        page, errors = page_with_errors(browser)
        page.set_default_timeout(60_000)
        page.goto(url)
        page.wait_for_selector("body[data-ready='true']", timeout=60_000)
        assert page.locator("#episodes tbody tr").count() == 6
        # sort by mean M, lowest first: episode 4 (half its steps incompatible)
        page.click("th[data-key='m_mean']")
        first = page.locator("#episodes tbody tr").first
        assert first.get_attribute("data-episode") == "4"
        assert "0.30" in first.inner_text() and "\t6\t" in first.inner_text()
        # sort by the quality flag, worst first: the jumpy episode 3 leads
        page.click("th[data-key='quality_flagged']")
        page.click("th[data-key='quality_flagged']")
        assert page.locator("#episodes tbody tr").first.get_attribute("data-episode") == "3"
        assert "outlier" in page.locator("#episodes tbody tr").first.inner_text()
        for episode, reason in ((3, "jumpy actions"), (1, "operator hesitated")):
            page.click(f"tr[data-episode='{episode}']")
            page.wait_for_selector(f"body[data-episode='{episode}']")
            assert page.locator("#step").inner_text().startswith("step 1 / 12")
            page.fill("#flag-reason", reason)
            page.click("#flag-btn")
            page.wait_for_selector(f"tr[data-episode='{episode}'][data-flagged='true']")
        # a flag needs a reason; unflagging takes one back
        page.click("tr[data-episode='0']")
        page.wait_for_selector("body[data-episode='0']")
        page.fill("#flag-reason", "")
        page.click("#flag-btn")
        page.wait_for_selector("#flag-error:not(:empty)")
        assert "reason" in page.locator("#flag-error").inner_text()
        page.fill("#flag-reason", "by mistake")
        page.click("#flag-btn")
        page.wait_for_selector("tr[data-episode='0'][data-flagged='true']")
        page.click("#unflag-btn")
        page.wait_for_selector("tr[data-episode='0'][data-flagged='false']")
        assert page.locator("#counts").get_attribute("data-flagged") == "2"
        page.select_option("#export-format", "robomimic")
        page.click("#export-btn")
        page.wait_for_selector("#export-result[data-done='true']", timeout=60_000)
        assert "kept 4, dropped 2" in page.locator("#export-result").inner_text()
        assert errors == []
    finally:
        server.stop()
    cli_ok(
        "import", d / "rv" / "reviewed.hdf5", "--filter-key", "reviewed", "-o", d / "back.parquet"
    )
    from elicit_jax.data.demos import read_demos

    back = read_demos(d / "back.parquet")
    names = sorted({str(n) for n in back.extra["source_episode"]})
    assert names == ["demo_0", "demo_2", "demo_4", "demo_5"]
    kept = read_demos(d / "rv" / "kept.parquet")
    assert kept.n_episodes == 4


def test_review_state_persists_and_validates(imported, tmp_path):
    from elicit_jax.curation.review import Review, ReviewConfig
    from elicit_jax.errors import ElicitError

    cfg = ReviewConfig(demos=str(imported / "demos.parquet"), out=str(tmp_path / "rv"))
    r = Review(cfg)
    with pytest.raises(ElicitError, match="reason"):
        r.flag(2, True, "   ")
    with pytest.raises(ElicitError, match="no episode 9"):
        r.flag(9, True, "x")
    r.flag(2, True, "camera\nglitch")
    again = Review(cfg)  # resumes from OUT/review.json
    assert again.flags == {2: "camera glitch"}
    rows = {row["episode"]: row for row in again.episodes()}
    assert rows[2]["flagged"] and not rows[1]["flagged"] and rows[2]["m_mean"] is None
    result = again.export()
    assert (result["kept"], result["dropped"], result["export"]) == (5, 1, None)


def test_review_folder_and_scores_must_be_the_reviews(imported, tmp_path):
    """-o is a new, empty or earlier review folder (never a file or another folder); scores
    that record another demos file are refused; an export alone makes a resumable folder."""
    import pyarrow.parquet as pq

    from elicit_jax.artifact import make_header, write_parquet
    from elicit_jax.curation.review import Review, ReviewConfig
    from elicit_jax.errors import ElicitError

    demos = str(imported / "demos.parquet")
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "n.txt").write_text("mine")
    with pytest.raises(ElicitError, match="not a review's"):
        Review(ReviewConfig(demos=demos, out=str(tmp_path / "notes")))
    with pytest.raises(ElicitError, match="is a file"):
        Review(ReviewConfig(demos=demos, out=str(imported / "quality.parquet")))
    table = pq.read_table(imported / "scores.parquet")
    for name, of in (("other.parquet", imported / "quality.parquet"), ("own.parquet", demos)):
        write_parquet(tmp_path / name, table, make_header("scores", 1, inputs={"demos": of}))
    with pytest.raises(ElicitError, match="another demos file"):
        Review(
            ReviewConfig(
                demos=demos, out=str(tmp_path / "a"), scores=str(tmp_path / "other.parquet")
            )
        )
    cfg = ReviewConfig(demos=demos, out=str(tmp_path / "b"), scores=str(tmp_path / "own.parquet"))
    assert Review(cfg).export()["kept"] == 6
    assert Review(cfg).flags == {}  # the exported folder resumes
    assert (tmp_path / "notes" / "n.txt").read_text() == "mine"
