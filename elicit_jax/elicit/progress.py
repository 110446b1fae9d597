"""Session progress, recomputed from the episode files: counts, next episode, accepted demos.

Nothing about progress is stored on its own. A session's state after any number of episodes
— which phase it is in, how many demonstrations were accepted, which batch a demonstration
counts toward, which policy scores next, the next episode's seeds — is a function of the
finished episodes' headers and the config, so resuming after a crash cannot disagree with
what was recorded.
"""

from __future__ import annotations

import dataclasses
import zlib
from typing import Any

from elicit_jax.elicit.events import DEMONSTRATION, PRACTICE, Counts

SUMMARY_KEYS = (
    "index",
    "episode_kind",
    "verdict",
    "rule_verdict",
    "success",
    "length",
    "operator_steps",
    "n_scored",
    "n_incompatible",
    "batch",
    "policy_batch",
    "interventions",
    "seconds",
    "text",
)


def operator_seed(config: Any, index: int) -> int:
    """Seed of the operator's randomness in episode ``index`` (from the session seed, the
    operator's name and the index: a resumed session repeats it)."""
    return zlib.crc32(f"{config.operator}|{config.seed}|{index}".encode())


def summary_row(header: dict[str, Any]) -> dict[str, Any]:
    """The per-episode summary kept in the manifest, ``info`` and the report."""
    row = {k: header.get(k) for k in SUMMARY_KEYS}
    length = int(header.get("length") or 0)
    row["intervention_rate"] = (
        int(header.get("operator_steps") or 0) / length if length and header.get("dagger") else None
    )
    scored = int(header.get("n_scored") or 0)
    row["fraction_incompatible"] = (
        int(header.get("n_incompatible") or 0) / scored if scored else None
    )
    return row


def session_phase(config: Any, progress: Any) -> str:
    """Where a (possibly interrupted) session stands."""
    c = progress.counts
    if c.accepted >= config.demos:
        return "done (all demonstrations accepted)"
    if c.episodes >= config.episode_limit:
        return f"done (episode limit {config.episode_limit} reached)"
    if c.practice < config.practice:
        return f"practice ({c.practice} of {config.practice} done)"
    return "demonstrate"


@dataclasses.dataclass(frozen=True)
class Progress:
    """Where a session stands.

    Attributes:
      counts: episode counts.
      next_index: index of the next episode.
      accepted: indices of the accepted episodes, in order.
      rows: one summary row per finished episode (see :data:`SUMMARY_KEYS`).
    """

    counts: Counts
    next_index: int = 0
    accepted: tuple[int, ...] = ()
    rows: tuple[dict[str, Any], ...] = ()

    @classmethod
    def load(cls, store: Any, config: Any) -> Progress:
        """Progress from a session's episode files."""
        out = cls(Counts(wanted=config.demos))
        for h in store.episode_headers():
            out = out.add_header(h)
        return out

    def add_header(self, h: dict[str, Any]) -> Progress:
        """Progress after one more finished episode (by its file header)."""
        c, verdict = self.counts, str(h["verdict"])
        kind = str(h["episode_kind"])
        counts = dataclasses.replace(
            c,
            episodes=c.episodes + 1,
            practice=c.practice + (kind == PRACTICE),
            accepted=c.accepted + (verdict == "accepted"),
            rejected=c.rejected + (verdict == "rejected"),
            failed=c.failed + (verdict == "failed" and kind == DEMONSTRATION),
            unused=c.unused + (verdict == "unused"),
        )
        accepted = self.accepted + ((int(h["index"]),) if verdict == "accepted" else ())
        return Progress(
            counts=counts,
            next_index=max(self.next_index, int(h["index"]) + 1),
            accepted=accepted,
            rows=(*self.rows, summary_row(h)),
        )

    def add(self, rec: Any) -> Progress:
        """Progress after one more finished episode (by its record)."""
        import numpy as np

        return self.add_header(
            {
                "index": rec.index,
                "episode_kind": rec.kind,
                "verdict": rec.verdict,
                "rule_verdict": rec.rule_verdict,
                "success": rec.success,
                "length": rec.length,
                "operator_steps": int(np.sum(rec.operator)),
                "n_scored": rec.n_scored,
                "n_incompatible": rec.n_incompatible,
                "batch": rec.batch,
                "policy_batch": rec.policy_batch,
                "text": rec.text,
                **rec.meta,
            }
        )

    def batch_of_next(self, batch_size: int) -> int:
        """The batch (1-based) the next accepted demonstration counts toward."""
        return self.counts.accepted // batch_size + 1 if batch_size else 1
