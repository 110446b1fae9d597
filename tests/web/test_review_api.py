"""The review server's API in-process (Starlette TestClient): the same access rules as
``/admin`` (another origin — another port of 127.0.0.1 — cannot flag or export; a cookie
named after the port), strict JSON bodies with one clear 400 line, and an export that never
replaces a mask the source file has and advises what the page offers."""

from __future__ import annotations

import json

import h5py
import pytest
from clients import client_for
from review_data import BASE_MASK, imported_demos

from elicit_jax.curation.review import Review, ReviewConfig
from elicit_jax.errors import ElicitError
from elicit_jax.web.access import access_policy
from elicit_jax.web.review import create_review_app

TOKEN = "review-token-0123456789"
OWN = {"origin": "http://127.0.0.1:8765"}


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    return imported_demos(tmp_path_factory.mktemp("review-api"))


@pytest.fixture
def review(imported, tmp_path):
    """(client holding the review's cookie, review) of a review served on 127.0.0.1:8765."""
    r = Review(ReviewConfig(demos=str(imported / "demos.parquet"), out=str(tmp_path / "rv")))
    client = client_for(create_review_app(r, TOKEN, 8765))
    page = client.get(f"/?token={TOKEN}")
    assert page.status_code == 200
    return client, r


def post(client, path: str, body, headers=None):
    raw = body if isinstance(body, str) else json.dumps(body)
    return client.post(path, content=raw, headers={**OWN, **(headers or {})})


def test_the_cookie_is_named_after_the_port_and_carries_the_token(review):
    client, _ = review
    assert set(client.cookies.keys()) == {"elicit_jax_token_8765"}
    assert client.get("/api/episodes").status_code == 200
    client.cookies.clear()
    assert client.get("/api/episodes").status_code == 403
    names = {access_policy("127.0.0.1", p, "t").token_cookie for p in (8765, 8766)}
    assert len(names) == 2  # two servers on one machine keep their own cookies
    admin = {access_policy("127.0.0.1", p).admin_cookie for p in (8765, 8766)}
    assert len(admin) == 2 and not names & admin


@pytest.mark.parametrize(
    "headers",
    [
        {"origin": "http://127.0.0.1:9999"},  # another port of the same address: another site
        {"origin": "http://localhost:9999"},
        {"origin": "null"},  # a sandboxed frame, a file:// page
        {"origin": "http://127.0.0.1"},
        {"origin": "", "sec-fetch-site": "same-site"},
    ],
)
def test_another_origin_cannot_flag_or_export_with_the_cookie(review, headers):
    client, r = review
    flag = {"episode": 2, "flagged": True, "reason": "csrf"}
    if headers.get("origin") == "":
        headers = {"sec-fetch-site": headers["sec-fetch-site"]}
        assert client.post("/api/flag", json=flag, headers=headers).status_code == 403
    else:
        assert post(client, "/api/flag", flag, headers).status_code == 403
        assert post(client, "/api/export", {"format": None}, headers).status_code == 403
        assert client.get("/api/episodes", headers=headers).status_code == 403
    assert r.flags == {} and not (r.out / "kept.parquet").exists()
    assert post(client, "/api/flag", flag).status_code == 200  # the page itself may
    assert r.flags == {2: "csrf"}


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ({"episode": 2, "flagged": "false", "reason": "x"}, "'flagged' must be true or false"),
        ({"episode": 6.7, "flagged": True, "reason": "x"}, "'episode' must be an episode number"),
        ({"episode": True, "flagged": True, "reason": "x"}, "'episode' must be an episode number"),
        ({"episode": "2", "flagged": True, "reason": "x"}, "'episode' must be an episode number"),
        ({"episode": 2, "flagged": True, "reason": 7}, "'reason' must be a string"),
        ({"episode": 2, "flagged": True, "why": "x"}, "unknown field(s) 'why'"),
        ({"flagged": True, "reason": "x"}, "no 'episode'"),
        ([2, True], "not a JSON object"),
        ('{"episode": Infinity, "flagged": true, "reason": "x"}', "Infinity is not a number"),
        ('{"episode": NaN, "flagged": true, "reason": "x"}', "NaN is not a number"),
        ('{"episode": 2, "flagged": tru', "malformed flag request"),
        ({"episode": 99, "flagged": True, "reason": "x"}, "no episode 99"),
    ],
)
def test_flag_bodies_are_strict_json_with_one_clear_error(review, body, says):
    client, r = review
    res = post(client, "/api/flag", body)
    assert res.status_code == 400, res.text
    assert says in res.json()["error"] and "\n" not in res.json()["error"]
    assert r.flags == {}


def test_export_bodies_and_episode_ids_are_strict(review):
    client, r = review
    for body, says in (
        ({"format": 1}, "'format' must be a string or null"),
        ({"mask_key": ["a"]}, "'mask_key' must be a string or null"),
        ({"format": "csv"}, "robomimic or lerobot"),
        ({"format": "robomimic", "mask_key": "a/b"}, "a mask key is"),
        ('{"format": -Infinity}', "-Infinity is not a number"),
    ):
        res = post(client, "/api/export", body)
        assert res.status_code == 400 and says in res.json()["error"], (body, res.text)
    for bad in ("6.7", "-1", "1e3", "x"):
        res = client.get(f"/api/episode/{bad}")
        assert res.status_code in (400, 404) and "Traceback" not in res.text, bad
    assert client.get("/api/episode/6.7").json()["error"] == "not an episode number: '6.7'"
    assert not (r.out / "kept.parquet").exists()


def test_export_refuses_a_mask_key_the_source_has(review, imported):
    client, r = review
    res = post(client, "/api/export", {"format": "robomimic", "mask_key": "base"})
    assert res.status_code == 400
    error = res.json()["error"]
    assert "already has a mask 'base'" in error and "type a new mask key" in error
    assert "--" not in error  # no command-line advice the page cannot follow
    assert not (r.out / "reviewed.hdf5").exists()
    with h5py.File(imported / "teleop.hdf5") as f:
        assert [n.decode() for n in f["mask/base"][()]] == BASE_MASK
    ok = post(client, "/api/export", {"format": "robomimic", "mask_key": "kept"})
    assert ok.status_code == 200 and ok.json()["kept"] == 6
    again = post(client, "/api/export", {"format": "robomimic", "mask_key": "kept"})
    assert again.status_code == 200  # its own earlier export is replaced, not the source's
    with h5py.File(r.out / "reviewed.hdf5") as f:
        assert sorted(f["mask"]) == ["base", "kept"]
        assert [n.decode() for n in f["mask/base"][()]] == BASE_MASK


def test_export_errors_advise_what_the_page_offers(demo, tmp_path):
    """Demos not imported from robomimic or LeRobot (serve --demo's base demos): the error
    names the page's own choice, never a command-line flag."""
    r = Review(ReviewConfig(demos=str(demo.base_demos), out=str(tmp_path / "rv")))
    for fmt in ("robomimic", "lerobot"):
        with pytest.raises(ElicitError, match="choose 'demos artifact only'") as e:
            r.export(fmt, "reviewed")
        assert "--" not in str(e.value), str(e.value)
    assert r.export(None)["kept"] == r.demos.n_episodes
