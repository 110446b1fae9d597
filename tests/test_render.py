"""One renderer (elicit_jax/render.py) for reports, session pages and maps.

The shared pieces are checked by hand; the session page, the session report and the
interactive map are checked against golden renderings made by the code before the renderers
were merged (tests/golden/render/): the same text, tags and attributes (stylesheet contents
and inlined PNG bytes aside, which the golden does not pin).
"""

from __future__ import annotations

import html.parser
import os
import types
from pathlib import Path

import numpy as np
import pytest

from elicit_jax.render import html_inline, html_page, html_table, img_tag, md_table

GOLDEN = Path(__file__).parent / "golden" / "render"
REGENERATE = os.environ.get("ELICIT_REGENERATE_GOLDEN") == "1"


class _Shape(html.parser.HTMLParser):
    """A page as lines: each start tag with its attributes, each run of text between tags
    with its white space collapsed (as a browser shows it); the stylesheet text and the bytes
    of inlined images are left out."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.lines: list[str] = []
        self._text: list[str] = []
        self._in_style = False

    def _flush(self) -> None:
        text = " ".join(" ".join(self._text).split())
        if text and not self._in_style:
            self.lines.append(text)
        self._text = []

    def handle_starttag(self, tag: str, attrs: list) -> None:
        self._flush()
        self._in_style = tag == "style"
        kept = []
        for k, v in attrs:
            if tag == "html" and k == "lang":
                continue
            if v and v.startswith("data:image/png;base64,"):
                v = "data:image/png;base64,…"
            kept.append(f"{k}={v!r}")
        self.lines.append(f"<{tag} {' '.join(kept)}>")

    def handle_endtag(self, tag: str) -> None:
        self._flush()
        self._in_style = False

    def handle_data(self, data: str) -> None:
        self._text.append(data)


def shape(page: str) -> str:
    """The page's tags, attributes and text, one per line (see :class:`_Shape`)."""
    parser = _Shape()
    parser.feed(page)
    parser.close()
    parser._flush()
    return "\n".join(parser.lines) + "\n"


def _check(name: str, text: str) -> None:
    path = GOLDEN / name
    if REGENERATE:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    assert text == path.read_text()


def _feedback(start, stop, base_episode, text):
    from elicit_jax.elicit.events import WindowFeedback

    return WindowFeedback(
        start=start,
        stop=stop,
        incompatibility=0.8125,
        base_episode=base_episode,
        base_start=3,
        base_stop=9,
        distance=0.5,
        fields=(),
        actions=(),
        operator_motion=0.0,
        base_motion=0.1,
        motion="still",
        text=text,
    )


def test_demo_page_renders_as_before(tmp_path):
    from elicit_jax.elicit.pages import write_demo_page

    m = np.clip(np.sin(np.arange(30) / 4.0), 0, 1)
    write_demo_page(
        tmp_path / "p.html",
        tmp_path / "p.png",
        title="demo 3 <of operator a&b>",
        verdict="rejected",
        summary=[("fraction incompatible", "40.0%"), ("rule", "reject if > 5% | any")],
        compatibility=m,
        feedback=[_feedback(4, 10, 2, "window: you hold still"), _feedback(20, 25, 0, "a|b")],
        obs=np.zeros((30, 3)),
        base=None,
    )
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"
    _check("demo-page.txt", shape((tmp_path / "p.html").read_text()))


def _session_data() -> dict:
    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.elicit.events import Counts

    config = types.SimpleNamespace(
        task="reach-pillar", operator="ann <a>", mode="informed", dagger=False,
        thresholds=Thresholds(0.4, 0.05, "given"), batch=2, fixed_base=True,
        policy="runs/p", base_demos="base.parquet",
        rule=lambda: types.SimpleNamespace(describe=lambda: "reject if > 5% incompatible"),
    )  # fmt: skip
    demos = [
        {"index": i, "verdict": v, "rule_verdict": r, "batch": b, "policy_batch": 0,
         "length": 40 + i, "fraction_incompatible": f, "intervention_rate": None,
         "text": f"demo {i} | ok", "episode_kind": "demonstration"}
        for i, (v, r, b, f) in enumerate(
            [("accepted", "accept", 1, 0.01), ("rejected", "reject", 1, 0.3),
             ("failed", None, 2, None), ("accepted", "accept", 2, 0.02)]
        )
    ]  # fmt: skip
    return {
        "root": "sessions/ann",
        "header": {"kind": "session", "seed": 7, "config": {"task": "reach-pillar"}},
        "config": config,
        "progress": types.SimpleNamespace(counts=Counts(accepted=2, rejected=1, failed=1)),
        "demos": demos,
        "base_length": 38.5,
        "policies": [],
    }


def test_session_report_renders_as_before():
    from elicit_jax.elicit.report import render_html, render_markdown

    data = _session_data()
    _check("session-report.md", render_markdown(data, "session.png"))
    _check("session-report.txt", shape(render_html(data, b"\x89PNG fake")))


@pytest.mark.parametrize("axis", ["likelihood-error", "neg-likelihood-error"])
def test_html_map_renders_as_before(tmp_path, axis):
    from elicit_jax.compat.maps import write_html
    from elicit_jax.compat.thresholds import Thresholds

    rng = np.random.default_rng(3)
    n = 40
    scores = {
        "likelihood": 10 ** rng.normal(-2, 1, n),
        "novelty": np.abs(rng.normal(0.05, 0.03, n)),
        "compatibility": rng.random(n),
        "operator": np.array(["base", "op<2>"], dtype=object)[rng.integers(0, 2, n)],
        "episode": rng.integers(0, 5, n),
        "step": np.arange(n),
    }
    write_html(scores, Thresholds(0.04, 0.05, "given"), tmp_path / "m.html", axis, bins=8)
    _check(f"map-{axis}.txt", shape((tmp_path / "m.html").read_text()))


def test_shared_pieces_by_hand():
    assert md_table(["a", "b|c"], [[1, "x|y"]]) == "| a | b\\|c |\n|---|---|\n| 1 | x\\|y |"
    assert html_table(["<h>"], [[3], ["a&b"]]) == (
        "<table><thead><tr><th>&lt;h&gt;</th></tr></thead>"
        "<tbody><tr><td>3</td></tr><tr><td>a&amp;b</td></tr></tbody></table>"
    )
    assert html_inline("a **b<c>** `d`") == "a <b>b&lt;c&gt;</b> d"
    assert img_tag(b"\x89PNG", 'a"b') == '<img alt="a&quot;b" src="data:image/png;base64,iVBORw==">'
    page = html_page("t<1>", "<p>x</p>", "p{color:red}")
    assert page.startswith('<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">')
    assert "<title>t&lt;1&gt;</title><style>p{color:red}</style>" in page
    assert page.endswith("<body><p>x</p></body></html>\n")


def test_blocks_render_each_kind_in_both_formats():
    from elicit_jax.render import html_blocks, markdown_blocks

    def figure(title, item):
        return [f"[{title}:{item}]"]

    blocks = [("T", (["h"], [["1"]])), ("P", "a < b"), ("C", ("code", "x = 1\n")), ("F", [7])]
    assert "\n".join(markdown_blocks(blocks, figure)) == (
        "## T\n\n| h |\n|---|\n| 1 |\n\n## P\n\na < b\n\n## C\n\n```\nx = 1\n```\n\n## F\n\n[F:7]"
    )
    assert "".join(html_blocks(blocks, figure)) == (
        "<h2>T</h2><table><thead><tr><th>h</th></tr></thead><tbody><tr><td>1</td></tr></tbody>"
        "</table><h2>P</h2><p>a &lt; b</p><h2>C</h2><details><summary>show</summary>"
        "<pre>x = 1\n</pre></details><h2>F</h2>[F:7]"
    )
    with pytest.raises(TypeError, match="no figure renderer"):
        markdown_blocks([("F", [1])])
