"""The review page's access rules and messages in real headless Chromium.

* A page served from another port of 127.0.0.1 (a dev server, Jupyter) cannot flag or export
  through the reviewer's browser, although the browser holds the review's cookie.
* Two reviews open in one browser keep working side by side (their cookies are named after
  their ports); a call that fails says so in a page-level message — never a JSON parse
  error — and the replay of the last episode is not left under the next one's title.
* Writing the selection with a mask key the source file already has is refused on the page.
"""

from __future__ import annotations

import functools
import http.server
import threading

import h5py
import pytest
from cli_server import CliServer
from review_data import BASE_MASK, imported_demos


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    return imported_demos(tmp_path_factory.mktemp("review-pages"))


def review_server(d, out: str) -> CliServer:
    return CliServer("review", d / "demos.parquet", "--scores", d / "scores.parquet", "-o", d / out)


ATTACK = """<!doctype html><title>a page of another local server</title><script>
const target = new URLSearchParams(location.search).get('target');
const send = (path, body) => fetch(target + path, {
  method: 'POST', mode: 'no-cors', credentials: 'include',
  headers: {'content-type': 'text/plain'}, body: JSON.stringify(body),
}).then(() => 'sent', (e) => 'failed: ' + e);
window.attack = Promise.all([
  send('/api/flag', {episode: 2, flagged: true, reason: 'flagged by another page'}),
  send('/api/export', {format: null}),
]);
</script>"""


@pytest.fixture
def other_site(tmp_path):
    """An HTTP server on another port of 127.0.0.1 serving ATTACK; its base URL."""
    (tmp_path / "site").mkdir()
    (tmp_path / "site" / "attack.html").write_text(ATTACK)
    handler = functools.partial(
        http.server.SimpleHTTPRequestHandler, directory=str(tmp_path / "site")
    )
    handler.log_message = lambda *a: None
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


def ready(page, url: str) -> None:
    page.goto(url)
    page.wait_for_selector("body[data-ready='true']", timeout=60_000)


def test_a_page_on_another_local_port_cannot_flag_or_export(browser, imported, other_site):
    server = review_server(imported, "rv-csrf")
    context = browser.new_context()
    try:
        url = server.start()
        base = url.split("?")[0].rstrip("/")
        review = context.new_page()
        ready(review, url)  # the browser now holds the review's cookie
        attacker = context.new_page()
        attacker.goto(f"{other_site}/attack.html?target={base}")
        assert attacker.evaluate("window.attack") == ["sent", "sent"]
        ready(review, base + "/")
        assert review.get_attribute("#counts", "data-flagged") == "0"
        assert not (imported / "rv-csrf" / "kept.parquet").exists()
        # the review's own page still may (the cookie was there all along)
        review.click("tr[data-episode='2']")
        review.fill("#flag-reason", "my own flag")
        review.click("#flag-btn")
        review.wait_for_selector("tr[data-episode='2'][data-flagged='true']")
    finally:
        context.close()
        server.stop()


def test_two_reviews_in_one_browser_and_page_level_messages(browser, imported):
    first, second = review_server(imported, "rv-a"), review_server(imported, "rv-b")
    context = browser.new_context()
    errors: list[str] = []
    try:
        url_a, url_b = first.start(), second.start()
        a, b = context.new_page(), context.new_page()
        for page in (a, b):
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.set_default_timeout(60_000)
        ready(a, url_a)
        ready(b, url_b)  # the second review's cookie must not replace the first's
        a.click("tr[data-episode='1']")
        a.wait_for_selector("body[data-episode='1']")
        assert a.is_hidden("#page-error")
        a.fill("#flag-reason", "operator hesitated")
        a.click("#flag-btn")
        a.wait_for_selector("tr[data-episode='1'][data-flagged='true']")
        b.click("tr[data-episode='0']")
        b.wait_for_selector("body[data-episode='0']")

        # an answer that arrives after the next episode was picked is dropped, not replayed
        held = []
        a.route("**/api/episode/3", lambda route: held.append(route))
        a.click("tr[data-episode='3']")
        a.wait_for_function("() => /Episode 3 .*loading/.test(document.body.innerText)")
        a.click("tr[data-episode='5']")
        a.wait_for_selector("body[data-episode='5']")
        assert len(held) == 1
        held[0].continue_()  # episode 3's late answer
        a.wait_for_timeout(1000)
        assert a.get_attribute("body", "data-episode") == "5"
        assert a.inner_text("#detail-title").startswith("Episode 5 ·")
        a.unroute("**/api/episode/3")

        # the access is gone (cookies cleared): a failed call is said on the page, and the
        # last episode's replay is not shown under the next one's title
        context.clear_cookies()
        a.click("tr[data-episode='4']")
        a.wait_for_selector("#page-error:not([hidden])")
        said = a.inner_text("#page-error")
        assert "Could not load episode 4" in said and "open the URL" in said, said
        assert "JSON" not in said and "Unexpected token" not in said, said
        assert a.inner_text("#detail-title") == "Episode 4 could not be loaded"
        assert a.get_attribute("body", "data-episode") is None
        assert "stale" in a.get_attribute("#view", "class")
        assert a.inner_text("#step") == ""

        # the mask key 'base' is the source's own: refused with a page-level message
        ready(a, url_a)
        a.select_option("#export-format", "robomimic")
        a.fill("#mask-key", "base")
        a.click("#export-btn")
        a.wait_for_selector("#export-result[data-done='error']")
        said = a.inner_text("#page-error")
        assert "already has a mask 'base'" in said and "type a new mask key" in said, said
        assert not (imported / "rv-a" / "reviewed.hdf5").exists()
        with h5py.File(imported / "teleop.hdf5") as f:
            assert [n.decode() for n in f["mask/base"][()]] == BASE_MASK
        a.fill("#mask-key", "reviewed")
        a.click("#export-btn")
        a.wait_for_selector("#export-result[data-done='true']")
        assert "kept 5, dropped 1" in a.inner_text("#export-result")
        assert a.is_hidden("#page-error")
        assert errors == []
    finally:
        context.close()
        first.stop()
        second.stop()
