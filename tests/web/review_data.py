"""The review tests' data: six robomimic demos (episode 3 with jumpy actions, a ``base``
mask of the first three) imported as square-nut data, their quality flags and hand-made
compatibility scores."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fixtures_data import cli_ok, robomimic_demo, write_robomimic

BASE_MASK = ["demo_0", "demo_1", "demo_2"]


def imported_demos(d: Path) -> Path:
    """Write ``d/teleop.hdf5`` (with ``mask/base``), ``d/demos.parquet``,
    ``d/quality.parquet`` and ``d/scores.parquet``; returns ``d``."""
    rng = np.random.default_rng(0)
    demos = {}
    for i in range(6):
        demo = robomimic_demo(rng, 12)
        smooth = np.linspace(-0.2, 0.2, 12)[:, None] * np.ones((1, 7))
        demo["actions"] = np.where(i == 3, demo["actions"], smooth)
        demos[f"demo_{i}"] = demo
    src = write_robomimic(d / "teleop.hdf5", demos, masks={"base": BASE_MASK})
    cli_ok("import", src, "--task", "square-nut", "-o", d / "demos.parquet")
    cli_ok("quality", d / "demos.parquet", "-o", d / "quality.parquet")
    m_scores(d / "scores.parquet")
    return d


def m_scores(path: Path) -> None:
    """Compatibility scores by hand: episode e's 12 steps have M = 1 - e / 10, except that
    episode 4's last 6 steps are incompatible (M = 0), so its mean M (0.3) is the lowest."""
    import pyarrow as pa

    from elicit_jax.artifact import make_header, write_parquet

    ep = np.repeat(np.arange(6), 12)
    m = 1 - ep / 10
    m[4 * 12 + 6 : 5 * 12] = 0.0
    table = pa.table(
        {
            "episode": pa.array(ep.astype(np.int64)),
            "operator": pa.array(["unknown"] * len(ep)),
            "step": pa.array(np.tile(np.arange(12), 6).astype(np.int32)),
            "compatibility": pa.array(m.astype(np.float32)),
            "incompatible": pa.array(m == 0),
        }
    )
    write_parquet(path, table, make_header("scores", 1))
