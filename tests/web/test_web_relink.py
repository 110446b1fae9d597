"""A personal link re-issued by the experimenter, pasted into the operator's open tab, in real
headless Chromium: it takes effect at once, without a reload; until then the page says its
key was replaced (never that its own name "is taken")."""

from __future__ import annotations

import json
import re
import urllib.request

from chromium import page_with_errors, sign_in
from test_web_browser import Server, screen


def issue_link(admin_url: str, name: str) -> str:
    """The experimenter's "link" action, as the dashboard posts it; the link it returns."""
    base, query = admin_url.split("/admin?")
    req = urllib.request.Request(f"{base}/admin/api/operators/{name}/link?{query}", method="POST")
    with urllib.request.urlopen(req, timeout=30) as r:
        return json.loads(r.read())["link"]


def test_a_new_link_pasted_into_the_open_tab_takes_effect(browser, demo, tmp_path):
    server = Server(demo.dir.parent, tmp_path / "sessions")
    url = server.start()
    admin_url = re.search(r"dashboard \(experimenter only\): (\S+)", "".join(server.output))[1]
    page, errors = page_with_errors(browser)
    try:
        sign_in(page, url, "ana")
        screen(page, "practice", "ready")
        page.evaluate("window.__sameDocument = true")

        link = issue_link(admin_url, "ana")  # her old key stops working: her page is closed
        screen(page, "error")
        page.click("#reconnect")  # the old key again: refused, with what to do
        page.wait_for_function(
            "() => /newer personal link/.test(document.getElementById('error-text').textContent)"
        )
        assert "taken" not in page.inner_text("#error-text")

        page.goto(link)  # pasted into the address bar: only the hash changes
        screen(page, "practice", "ready")
        page.wait_for_selector("#conn[data-conn=open]")
        assert page.evaluate("window.__sameDocument === true")  # no reload happened
        assert "#" not in page.url and "key=" not in page.url  # the key left the address bar
        assert page.get_attribute("#my-link", "href").endswith(link[link.index("#") :])
        assert errors == []
    finally:
        page.close()
        server.stop()
