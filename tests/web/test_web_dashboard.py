"""The experimenter's dashboard in real headless Chromium: two operators live, a personal
link, pause and resume, and a download of the accepted demonstrations that reads back.

`elicit-jax serve --demo` runs as a subprocess in naive mode (no practice, one demonstration
wanted), so an operator's first completed episode is accepted. Operator ana types her name;
ben opens the link the experimenter issued him. The dashboard (a third page, opened with the
admin token the server printed) shows both, live; ana demonstrates by keyboard and the
dashboard's counts follow; the merged download is read by the demos reader and by
`elicit-jax info`, and `elicit-jax info SESSIONS/` summarises both operators.
ELICIT_JAX_SCREENSHOTS=DIR saves the dashboard's screenshot (docs/images/serve-admin.png).
"""

from __future__ import annotations

import re
from pathlib import Path

from test_web_browser import SHOTS, Server, drive, driven, screen
from typer.testing import CliRunner

from elicit_jax.cli import app
from elicit_jax.data.demos import read_demos


def serve_args(demo_root, sessions) -> list[str]:
    return [
        "serve", "--demo", "--demo-dir", str(demo_root), "--sessions", str(sessions),
        "--mode", "naive", "--practice", "0", "--demos", "1", "--max-episodes", "3",
        "--horizon", "200",
    ]  # fmt: skip


def row(name: str, **attrs: str) -> str:
    return f"tr[data-name={name}]" + "".join(f"[data-{k}={v}]" for k, v in attrs.items())


def test_the_dashboard_follows_two_operators_and_downloads_their_demos(browser, demo, tmp_path):
    sessions = tmp_path / "sessions"
    server = Server(demo.dir.parent, sessions)
    server.args = serve_args(demo.dir.parent, sessions)
    url = server.start()
    admin_url = re.search(r"dashboard \(experimenter only\): (\S+)", "".join(server.output))[1]
    assert "/admin?token=" in admin_url
    size = {"width": 1100, "height": 700}
    contexts = [browser.new_context(accept_downloads=True, viewport=size) for _ in range(3)]
    dash, ana, ben = (c.new_page() for c in contexts)
    errors: list[str] = []
    for p in (dash, ana, ben):
        p.on("pageerror", lambda e: errors.append(str(e)))
    try:
        assert ana.goto(url.split("?")[0] + "admin").status == 403  # no token, no dashboard
        dash.goto(admin_url)
        dash.wait_for_selector("body[data-live=yes]")
        assert dash.is_visible("#empty")

        ana.goto(url)
        ana.fill("#name", "ana")
        ana.keyboard.press("Enter")
        screen(ana, "demonstrate", "ready")
        dash.wait_for_selector(row("ana", status="active", screen="demonstrate"))

        dash.fill("#link-name", "ben")
        dash.once("dialog", lambda d: d.accept())  # ben is not an operator yet: confirmed
        dash.click("#link-form button")
        dash.wait_for_function(
            "() => /#op=ben&key=/.test(document.getElementById('link-out').textContent)"
        )
        link = dash.inner_text("#link-out")
        assert link.startswith(url.split("?")[0])
        ben.goto(link)
        screen(ben, "demonstrate", "ready")
        assert "#" not in ben.url  # the key left the address bar
        assert ben.get_attribute("#my-link", "href").endswith(link[link.index("#") :])
        dash.wait_for_selector(row("ben", screen="demonstrate") + " td[data-page=true]")

        # ben is paused: his page is closed with the reason, then let back in by itself
        dash.click(row("ben") + " button[data-action=pause]")
        dash.wait_for_selector(row("ben", status="paused") + " td[data-page=false]")
        ben.wait_for_function(  # the page shows why, and keeps retrying
            "() => /paused by the experimenter/.test(document.getElementById('conn').textContent)"
        )
        dash.click(row("ben") + " button[data-action=resume]")
        ben.wait_for_selector("#conn[data-conn=open]", timeout=30_000)
        dash.wait_for_selector(row("ben", status="active") + " td[data-page=true]")

        # ana demonstrates by keyboard; the dashboard follows her while ben waits
        for _ in range(3):
            drive(ana, +1)
            driven(ana)
            if dash.query_selector(row("ana") + " td[data-accepted='1']"):
                break
            dash.wait_for_timeout(1500)
            if dash.query_selector(row("ana") + " td[data-accepted='1']"):
                break
            ana.keyboard.press("Enter")
            screen(ana, "demonstrate", "ready")
        dash.wait_for_selector(row("ana", screen="done") + " td[data-accepted='1']")
        assert dash.inner_text(row("ben") + " td:nth-child(7)") == "0 of 1"
        if SHOTS:
            Path(SHOTS).mkdir(parents=True, exist_ok=True)
            dash.screenshot(path=str(Path(SHOTS) / "serve-admin.png"))

        with dash.expect_download() as dl:
            dash.click("#download-merged")
        merged = tmp_path / "merged.parquet"
        dl.value.save_as(merged)
        with dash.expect_download() as dl:
            dash.click(row("ana") + " a[download]")
        assert dl.value.suggested_filename == "ana-demos.parquet"
        assert errors == []
    finally:
        for c in contexts:
            c.close()
        server.stop()

    demos = read_demos(merged)
    ana_demos = read_demos(sessions / "ana" / "demos.parquet")
    assert demos.n_episodes == 1 and set(demos.operator) == {"ana"}
    assert (demos.obs == ana_demos.obs).all() and (demos.action == ana_demos.action).all()
    wide = {"COLUMNS": "200"}
    info = CliRunner().invoke(app, ["info", str(merged)], env=wide)
    assert info.exit_code == 0, info.output
    assert "demonstrations (schema v1)" in info.output and "merged sessions" in info.output
    assert re.search(r"│ ana +│ +1 │", info.output), info.output
    folder = CliRunner().invoke(app, ["info", str(sessions)], env=wide)
    assert folder.exit_code == 0, folder.output
    lines = folder.output.splitlines()
    assert any("ana" in ln and "1/1" in ln for ln in lines), folder.output
    assert any("ben" in ln and "0/1" in ln for ln in lines), folder.output
    assert "2 operator(s), 1 accepted demonstration(s) in all" in folder.output
