"""Compatibility maps: PNG and self-contained interactive HTML."""

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from elicit_jax.compat.maps import write_map
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError

T = Thresholds(0.4, 0.05, "given")


def _scores(n=3000):
    rng = np.random.default_rng(0)
    return {
        "likelihood": 10 ** rng.normal(-2, 1, n),
        "novelty": np.abs(rng.normal(0.05, 0.03, n)),
        "compatibility": rng.random(n),
        "operator": np.array(["base", "op 1", "op<2>"], dtype=object)[rng.integers(0, 3, n)],
        "episode": rng.integers(0, 10, n),
        "step": np.arange(n),
    }


@pytest.mark.parametrize("axis", ["likelihood-error", "neg-likelihood-error"])
def test_png_map(tmp_path, axis):
    out = tmp_path / "map.png"
    write_map(_scores(), T, out, axis)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_html_map_is_self_contained(tmp_path):
    out = tmp_path / "map.html"
    s = _scores()
    write_map(
        s,
        T,
        out,
        "neg-likelihood-error",
    )
    text = out.read_text()
    assert "http://" not in text.replace("http://www.w3.org/2000/svg", "")
    assert "https://" not in text and "<script src" not in text
    # one group per operator (names escaped), one point per pair (below the subsample cap)
    assert text.count('<g class="op"') == 3
    assert "op&lt;2&gt;" in text
    assert text.count("<circle") == len(s["likelihood"])
    assert "−ℓ" in text
    # the inline SVG is well-formed XML
    svg = ET.fromstring(re.search(r"<svg.*</svg>", text, re.S).group(0))
    assert svg.tag.endswith("svg")


def test_bad_map_output(tmp_path):
    with pytest.raises(ElicitError, match=r"png or \.html"):
        write_map(_scores(10), T, tmp_path / "map.pdf")
