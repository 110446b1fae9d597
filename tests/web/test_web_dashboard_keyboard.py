"""The experimenter's dashboard by keyboard and screen reader, in real headless Chromium:
its cells are updated in place (a focused button and a ticked box survive the polls), the
live region announces what changed and not the clock, every issued link is listed with a
copy button, a new name is created only once confirmed and names ignore case, and the
selected operators are removed at once.

`elicit-jax serve --demo` runs as a subprocess; the operators are made by the dashboard's
own links (no operator page is needed)."""

from __future__ import annotations

import re

from test_web_browser import Server
from test_web_dashboard import row, serve_args


def test_the_dashboard_by_keyboard_links_names_and_bulk_remove(browser, demo, tmp_path):
    sessions = tmp_path / "sessions"
    server = Server(demo.dir.parent, sessions)
    server.args = serve_args(demo.dir.parent, sessions)
    url = server.start()
    admin_url = re.search(r"dashboard \(experimenter only\): (\S+)", "".join(server.output))[1]
    origin = url.split("?")[0].rstrip("/")
    context = browser.new_context(viewport={"width": 1100, "height": 700})
    context.grant_permissions(["clipboard-read", "clipboard-write"], origin=origin)
    dash = context.new_page()
    errors: list[str] = []
    dash.on("pageerror", lambda e: errors.append(str(e)))
    dialogs: list[str] = []
    answers: list[bool] = []

    def on_dialog(d):
        dialogs.append(d.message)
        d.accept() if answers.pop(0) else d.dismiss()

    dash.on("dialog", on_dialog)

    def issue(name: str, answer: bool | None) -> None:
        before = len(dialogs)
        if answer is not None:
            answers.append(answer)
        dash.fill("#link-name", name)
        dash.click("#link-form button")
        dash.wait_for_function(
            "() => /^a new link for|^no operator created/.test("
            "document.getElementById('action-out').textContent)"
        )
        dash.evaluate("document.getElementById('action-out').textContent = ''")
        assert len(dialogs) == before + (answer is not None), dialogs

    try:
        dash.goto(admin_url)
        dash.wait_for_selector("body[data-live=yes]")
        assert dash.get_attribute("#live", "aria-live") is None  # the clock is not announced

        # a new name needs a confirmation; a dismissed one creates nothing; names ignore case
        issue("ana", True)
        assert "not an operator yet" in dialogs[-1]
        issue("ben", True)
        issue("carl", False)
        issue("ANA", None)  # ana herself: no question, a new link for her
        assert dash.get_attribute("#link-out", "data-name") == "ana"
        dash.wait_for_selector(row("ben"))
        dash.wait_for_timeout(1500)
        assert dash.locator("#operators tbody tr").count() == 2  # no carl, no ANA

        # every issued link is listed (each operator's newest) with a copy button
        dash.wait_for_function("() => document.querySelectorAll('#links li').length === 2")
        ana_link = dash.inner_text("#link-out")
        assert dash.inner_text("#links li[data-name=ana] code") == ana_link
        dash.click("#links li[data-name=ben] button[data-action=copy]")
        dash.wait_for_function("() => /ben's link copied/.test(document.body.innerText)")
        copied = dash.evaluate("navigator.clipboard.readText()")
        assert copied == dash.inner_text("#links li[data-name=ben] code")
        assert "#op=ben&key=" in copied

        # focus and a ticked box survive the updates; nothing is announced while nothing changes
        dash.check(row("ana") + " input[type=checkbox]")
        dash.focus(row("ben") + " button[data-action=pause]")
        dash.evaluate("document.activeElement.__mark = 'ben-pause'")
        dash.evaluate(
            """() => { window.__announced = [];
            new MutationObserver(() => window.__announced.push(
              document.getElementById('announce').textContent))
              .observe(document.getElementById('announce'),
                       {childList: true, characterData: true, subtree: true}); }"""
        )
        t0 = dash.inner_text("#live")
        dash.wait_for_function(f"() => document.getElementById('live').textContent !== {t0!r}")
        dash.wait_for_timeout(2200)  # two more polls
        assert dash.evaluate("document.activeElement.__mark") == "ben-pause"
        assert dash.is_checked(row("ana") + " input[type=checkbox]")
        assert dash.evaluate("window.__announced") == []

        # Enter on the focused button pauses ben: announced, and focus moves to "resume"
        dash.keyboard.press("Enter")
        dash.wait_for_selector(row("ben", status="paused"))
        dash.wait_for_function("() => /ben: paused/.test(window.__announced.join(' | '))")
        assert dash.evaluate("document.activeElement.dataset.action") == "resume"
        assert not any(re.search(r"\d+:\d\d", a) for a in dash.evaluate("window.__announced"))

        # bulk remove: every operator selected, one confirmation, every row gone
        dash.check("#select-all")
        assert dash.inner_text("#bulk-count") == "2 selected"
        answers.append(True)
        dash.click("#bulk-remove")
        dash.wait_for_function("() => /removed: ana, ben/.test(document.body.innerText)")
        assert "Remove 2 operators (ana, ben)?" in dialogs[-1]
        dash.wait_for_selector("#empty:not([hidden])")
        assert dash.locator("#links li").count() == 0
        assert dash.inner_text("#bulk-count") == "none selected"
        removed = sorted(p.name for p in (sessions / ".removed").iterdir())
        assert removed == ["ana-1.key.json", "ben-1.key.json"]
        assert errors == []
    finally:
        context.close()
        server.stop()
