"""The session report (``elicit-jax report SESSION``): Markdown and one self-contained HTML page.

Contents: the settings; counts; accepted/rejected per batch and the policy that scored each
batch; each batch's retrained policy; every demonstration's verdict, incompatible fraction,
length and intervention rate; a figure of the incompatible fraction over the session (does
the operator improve?) with the trend's slope and a permutation p-value (so a trend inside
the noise says so), and demonstration lengths against the base demonstrations' mean.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import (
    PROVENANCE_KEY,
    atomic_path,
    dumps,
    make_header,
    provenance_line,
    read_header,
)
from elicit_jax.elicit.pages import PAGE_CSS
from elicit_jax.elicit.progress import Progress
from elicit_jax.elicit.store import SessionStore
from elicit_jax.render import figure_png, html_block, html_code, html_page, img_tag, markdown_block

TREND_PERMUTATIONS = 2000
TREND_TITLE = "Does the operator improve?"
FIGURE_ALT = "incompatible fraction and length per demonstration"


def trend(values: np.ndarray, seed: int = 0) -> tuple[float, float | None]:
    """Least-squares slope of ``values`` over their order, and a two-sided permutation
    p-value (None for fewer than 3 values)."""
    y = np.asarray(values, np.float64)
    if len(y) < 2:
        return 0.0, None
    x = np.arange(len(y)) - (len(y) - 1) / 2
    slope = float(x @ (y - y.mean()) / (x @ x))
    if len(y) < 3:
        return slope, None
    rng = np.random.default_rng(seed)
    perms = np.array([x @ rng.permutation(y) for _ in range(TREND_PERMUTATIONS)]) / (x @ x)
    p = float((np.sum(np.abs(perms) >= abs(slope) - 1e-12) + 1) / (TREND_PERMUTATIONS + 1))
    return slope, p


def _pct(x: Any) -> str:
    return "-" if x is None else f"{100 * x:.1f}%"


def _policies(store: SessionStore) -> list[list[Any]]:
    rows = []
    d = store.root / "policies"
    for p in sorted(d.glob("batch*"), key=lambda q: int(q.name[5:] or 0)) if d.is_dir() else []:
        try:
            run = read_header(p)
            seed_dir = p / next(iter(run.get("seed_dirs", {}).values()))
            h = read_header(seed_dir)
        except (Exception, StopIteration):
            rows.append([p.name, str(p), "-", "-", "-"])
            continue
        train_eps = len(h.get("train_episodes", [])) + len(h.get("val_episodes", []))
        val = h.get("best_val_loss")
        rows.append(
            [
                p.name,
                str(p),
                train_eps,
                h.get("best_epoch"),
                "-" if val is None else f"{val:.4g}",
            ]
        )
    return rows


def _figure(demos: list[dict[str, Any]], base_len: float, dagger: bool) -> bytes:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 6.4 if dagger else 4.6))
    axes = fig.subplots(3 if dagger else 2, 1, squeeze=False)[:, 0]
    order = np.arange(1, len(demos) + 1)
    colors = {"accepted": "#1a7f37", "rejected": "#b42318", "failed": "#999999"}
    c = [colors.get(r["verdict"], "#555555") for r in demos]
    frac = [r["fraction_incompatible"] or 0.0 for r in demos]
    edge = ["#b42318" if r["rule_verdict"] == "reject" else "none" for r in demos]
    axes[0].scatter(order, frac, c=c, s=30, edgecolors=edge, linewidths=1.5)
    axes[0].plot(order, frac, color="#888", lw=0.8)
    axes[0].set_ylabel("fraction incompatible")
    axes[0].set_title(
        "green accepted, red rejected, grey failed; red ring: the rule rejects (naive mode: "
        "recorded, not applied)",
        fontsize=9,
    )
    axes[1].scatter(order, [r["length"] for r in demos], c=c, s=22)
    axes[1].axhline(base_len, color="#1f77b4", ls="--", lw=1, label="base mean length")
    axes[1].set_ylabel("length (steps)")
    axes[1].legend(fontsize=8)
    if dagger:
        axes[2].bar(order, [r["intervention_rate"] or 0.0 for r in demos], color=c)
        axes[2].set_ylabel("intervention rate")
    axes[-1].set_xlabel("demonstration (in order)")
    fig.tight_layout()
    return figure_png(fig)


def session_report(root: str | Path) -> dict[str, Any]:
    """Everything the report shows, from a session directory."""
    from elicit_jax.data.demos import read_demos
    from elicit_jax.elicit.config import SessionConfig

    store = SessionStore(root)
    header = store.header()
    config = SessionConfig.from_dict(header["config"])
    progress = Progress.load(store, config)
    demos = [r for r in progress.rows if r["episode_kind"] == "demonstration"]
    try:
        base = read_demos(config.base_demos)
        base_len = float(np.mean([t - s for _, s, t in base.episode_bounds()]))
    except Exception:  # the base file moved: the report still renders, without it
        base_len = float("nan")
    return {
        "root": str(root),
        "header": header,
        "config": config,
        "progress": progress,
        "demos": demos,
        "base_length": base_len,
        "policies": _policies(store),
    }


def _batches(data: dict[str, Any]) -> list[list[Any]]:
    rows = []
    demos = data["demos"]
    for b in sorted({int(r["batch"] or 0) for r in demos}):
        sel = [r for r in demos if int(r["batch"] or 0) == b]
        judged = [r for r in sel if r["verdict"] in ("accepted", "rejected")]
        fr = [r["fraction_incompatible"] for r in sel if r["fraction_incompatible"] is not None]
        acc = sum(r["verdict"] == "accepted" for r in sel)
        rows.append(
            [
                b,
                len(sel),
                acc,
                sum(r["verdict"] == "rejected" for r in sel),
                sum(r["verdict"] == "failed" for r in sel),
                f"{acc / len(judged):.0%}" if judged else "-",
                _pct(float(np.mean(fr)) if fr else None),
                ", ".join(sorted({f"π_{r['policy_batch']}" for r in sel})),
            ]
        )
    return rows


def _trend_text(demos: list[dict[str, Any]]) -> str:
    """Does the incompatible fraction change over the session, beyond the noise?"""
    fr = [r["fraction_incompatible"] for r in demos if r["fraction_incompatible"] is not None]
    slope, pval = trend(np.array(fr))
    if pval is None:
        return f"{len(fr)} scored demonstrations: too few for a trend."
    verdict = "a trend" if pval < 0.05 else "no trend distinguishable from noise"
    return (
        f"Fraction incompatible changes by {100 * slope:+.2f} points per demonstration over "
        f"{len(fr)} demonstrations (permutation p = {pval:.2f}: {verdict})."
    )


def _settings(c: Any) -> list[list[Any]]:
    """The session's settings, as (setting, value) rows."""
    t = c.thresholds
    return [
        ["task", c.task],
        ["operator", c.operator],
        ["mode", c.mode + (" + HG-DAgger" if c.dagger else "")],
        ["thresholds", f"λ = {t.lam:.4g}, η = {t.eta:.4g} ({t.file or 'given'})"],
        ["rule", c.rule().describe()],
        ["batches", f"retrain every {c.batch}" if c.batch else "no retraining"],
        ["scoring", "fixed base" if c.fixed_base else "latest π_new"],
        ["policy / base demos", f"{c.policy} / {c.base_demos}"],
    ]


def _summary(data: dict[str, Any]) -> list[list[Any]]:
    counts, demos = data["progress"].counts, data["demos"]
    lengths = [r["length"] for r in demos if r["verdict"] == "accepted"]
    rates = [r["intervention_rate"] for r in demos if r["intervention_rate"] is not None]
    return [
        ["practice episodes", counts.practice],
        ["accepted", f"{counts.accepted} of {counts.wanted} wanted"],
        ["rejected", counts.rejected],
        ["failed the task", counts.failed],
        ["episodes", counts.episodes],
        [
            "mean length (accepted) vs base",
            f"{np.mean(lengths):.0f} vs "
            + ("-" if np.isnan(data["base_length"]) else f"{data['base_length']:.0f}")
            if lengths
            else "-",
        ],
        ["mean intervention rate", _pct(float(np.mean(rates))) if rates else "-"],
    ]


def _sections(data: dict[str, Any]) -> list[tuple[str, Any]]:
    demos = data["demos"]
    settings, summary, trend_text = _settings(data["config"]), _summary(data), _trend_text(demos)
    per_demo = [
        [
            r["index"],
            r["verdict"],
            r["rule_verdict"] or "-",
            r["batch"],
            f"π_{r['policy_batch']}",
            r["length"],
            _pct(r["fraction_incompatible"]),
            "-" if r["intervention_rate"] is None else _pct(r["intervention_rate"]),
            r["text"],
        ]
        for r in demos
    ]
    return [
        ("Settings", (["setting", "value"], settings)),
        ("Summary", (["", ""], summary)),
        (
            "Per batch",
            (
                [
                    "batch",
                    "demos",
                    "accepted",
                    "rejected",
                    "failed",
                    "accept rate",
                    "mean incompatible",
                    "scored by",
                ],
                _batches(data),
            ),
        ),
        (
            "Batch policies (π_b: trained on D_base + the first b batches)",
            (["policy", "path", "episodes", "best epoch", "best val loss"], data["policies"])
            if data["policies"]
            else "None: no batch was completed with retraining on (--batch).",
        ),
        (TREND_TITLE, trend_text),
        (
            "Demonstrations",
            (
                [
                    "episode",
                    "verdict",
                    "rule",
                    "batch",
                    "scored by",
                    "length",
                    "incompatible",
                    "intervention rate",
                    "summary",
                ],
                per_demo,
            ),
        ),
    ]


def _provenance(data: dict[str, Any]) -> str:
    """Where the session came from (its header's provenance) and its seed."""
    header = data["header"]
    return f"{provenance_line(header.get(PROVENANCE_KEY, {}))} Session seed: {header.get('seed')}."


def render_markdown(data: dict[str, Any], figure: str | None) -> str:
    """The session report as Markdown; ``figure`` is the trend figure's path, if any."""
    out = [f"# Elicitation session `{data['root']}`", "", _provenance(data), ""]
    for title, content in _sections(data):
        out += markdown_block(title, content)
        if title == TREND_TITLE and figure:
            out += [f"![{FIGURE_ALT}]({figure})", ""]
    out += markdown_block("Session header", ("code", dumps(data["header"])))
    return "\n".join(out)


def render_html(data: dict[str, Any], png: bytes | None) -> str:
    """The session report as one self-contained page; ``png`` is the trend figure, if any."""
    body = [f"<h1>Elicitation session {html.escape(data['root'])}</h1>"]
    body.append(f"<p>{html.escape(_provenance(data))}</p>")
    for title, content in _sections(data):
        body += html_block(title, content)
        if title == TREND_TITLE and png:
            body.append(img_tag(png, FIGURE_ALT))
    body.append(html_code(dumps(data["header"]), "session header"))
    return html_page(f"session {data['root']}", "".join(body), PAGE_CSS)


def write_session_report(root: str | Path, out: str | Path | None = None) -> tuple[Path, Path]:
    """Write ``report.md``, ``report.html`` and ``session.png`` (default ``SESSION/report``)."""
    data = session_report(root)
    out_dir = Path(out) if out else Path(root) / "report"
    png = (
        _figure(data["demos"], data["base_length"], data["config"].dagger)
        if data["demos"]
        else None
    )
    with atomic_path(out_dir) as tmp:
        tmp.mkdir(parents=True)
        if png:
            (tmp / "session.png").write_bytes(png)
        (tmp / "report.md").write_text(render_markdown(data, "session.png" if png else None))
        (tmp / "report.html").write_text(render_html(data, png))
        header = make_header(
            "session-report", 1, config={"session": str(root)}, files=["report.md", "report.html"]
        )
        (tmp / "artifact.json").write_text(dumps(header) + "\n")
    return out_dir / "report.md", out_dir / "report.html"
