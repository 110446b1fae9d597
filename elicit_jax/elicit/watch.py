"""``elicit-jax watch``: verdicts and feedback for demonstrations landing in a folder.

The real-robot flow: another stack records demonstrations (a robomimic HDF5 file, a LeRobot
dataset folder) into an inbox folder; each one gets a verdict (the accept/reject rule) and,
when rejected, feedback — no simulator needed. Items are read with ``import``'s own reader
and options, so any dataset that imports can be watched.

**Not read half-written.** An item is read only once it has been *settled*: its size and
modification time (for a folder, those of every file in it) unchanged for ``settle``
seconds. Names starting with ``.`` or ``~`` and ending in ``.tmp``, ``.part``,
``.partial``, ``.crdownload`` or ``.lock`` are ignored (write there, then rename). An HDF5
file another process still holds open for writing (HDF5 file locking) is retried, not
reported. A settled item that still cannot be read gets one error line and is retried when
it changes.

**Output** (``out``, default ``INBOX/verdicts``): one line per demonstration on the console,
a page per demonstration (``<item>__<episode>.html`` with its ``.png``: M over time, the
flagged windows, the worst window's states beside the retrieved base segment's), and
``verdicts.jsonl``, one JSON line per judged demonstration (and per unreadable item). A
demonstration is keyed by item, episode and a hash of its content: a restarted watcher skips
what it judged, and a LeRobot folder that grows gets verdicts for its new episodes only.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError

IGNORED_SUFFIXES = (".tmp", ".part", ".partial", ".crdownload", ".lock")
DATA_SUFFIXES = (".hdf5", ".h5", ".he5", ".npz")
LOG_FILE = "verdicts.jsonl"


@dataclasses.dataclass(frozen=True)
class WatchConfig:
    """Settings of a watcher.

    Attributes:
      inbox: the folder to watch.
      out: where pages and the verdict log go (default ``inbox/verdicts``).
      policy, which, policy_seed: the policy to score against.
      base_demos: D_base (retrieval for feedback).
      thresholds: λ and η, with where they came from.
      likelihood, ddof: score definitions.
      accept_fraction, reject_count: the accept/reject rule.
      window, windows, retrieval: feedback settings.
      import_options: ``ImportConfig`` fields (format, obs_keys, operator, ...), as ``import``.
      settle: seconds an item must stay unchanged before it is read.
      poll: seconds between scans.
      once: stop when every item present has been handled.
      timeout: stop after this many seconds (None: run until interrupted).
    """

    inbox: str
    policy: str
    base_demos: str
    thresholds: Thresholds
    out: str | None = None
    which: str = "best"
    policy_seed: int | None = None
    likelihood: str = "ensemble-mean"
    ddof: int = 0
    accept_fraction: float = 0.05
    reject_count: int | None = None
    window: int = 10
    windows: int = 3
    retrieval: str = "l2"
    import_options: tuple[tuple[str, Any], ...] = ()
    settle: float = 2.0
    poll: float = 1.0
    once: bool = False
    timeout: float | None = None

    def __post_init__(self) -> None:
        if self.settle < 0 or self.poll <= 0:
            raise ElicitError(
                f"--settle must be >= 0 and --poll > 0 (got {self.settle}, {self.poll})"
            )
        if self.timeout is not None and self.timeout <= 0:
            raise ElicitError(f"--timeout must be > 0, got {self.timeout}")
        if self.window < 1 or self.windows < 1:
            raise ElicitError("--window and --windows must be >= 1")

    @property
    def out_dir(self) -> Path:
        return Path(self.out) if self.out else Path(self.inbox) / "verdicts"


def candidates(inbox: Path, out: Path) -> list[Path]:
    """Items in the inbox that may be demonstrations (see the module docstring)."""
    items = []
    for p in sorted(inbox.iterdir()):
        name = p.name
        if name.startswith((".", "~")) or name.endswith(IGNORED_SUFFIXES):
            continue
        if p.resolve() == out.resolve():
            continue
        if (p.is_file() and p.suffix.lower() in DATA_SUFFIXES) or (
            p.is_dir() and (p / "meta" / "info.json").is_file()
        ):
            items.append(p)
    return items


def signature(path: Path) -> tuple:
    """What changes while an item is being written: sizes and modification times."""
    if path.is_file():
        st = path.stat()
        return ((path.name, st.st_size, st.st_mtime_ns),)
    out = []
    for p in sorted(path.rglob("*")):
        if p.is_file() and not p.name.startswith("."):
            st = p.stat()
            out.append((str(p.relative_to(path)), st.st_size, st.st_mtime_ns))
    return tuple(out)


class Settler:
    """Tracks items until they have stayed unchanged for ``settle`` seconds."""

    def __init__(self, settle: float) -> None:
        self.settle = settle
        self.seen: dict[Path, tuple[tuple, float]] = {}

    def ready(self, path: Path, now: float) -> tuple | None:
        """The item's signature if it has settled, else None."""
        try:
            sig = signature(path)
        except OSError:
            return None
        old = self.seen.get(path)
        if old is None or old[0] != sig:
            self.seen[path] = (sig, now)
            return sig if self.settle == 0 else None
        return sig if now - old[1] >= self.settle else None


def _busy(error: BaseException) -> bool:
    """An HDF5 file still open for writing elsewhere (file locking)."""
    text = str(error).lower()
    return "unable to lock file" in text or "resource temporarily unavailable" in text


def page_stem(item: str, episode: str) -> str:
    """The file stem of a demonstration's page: ``<item>__<episode>``, one-to-one.

    Characters other than ``A-Za-z0-9._-`` become ``_`` and each part is cut at 80; when that
    changes either part (``a b.hdf5`` and ``a_b.hdf5`` would share a page) or a part holds
    ``__`` (the separator), ``~`` and a hash of the original names follow. A name needing no
    change never contains ``~``, so no two inputs share a stem.
    """
    parts = [re.sub(r"[^A-Za-z0-9._-]+", "_", p)[:80] for p in (item, episode)]
    stem = "__".join(parts)
    if parts != [item, episode] or any("__" in p for p in parts):
        digest = hashlib.sha256(f"{item}\0{episode}".encode()).hexdigest()[:12]
        stem += f"~{digest}"
    return stem


def episode_hash(obs: np.ndarray, action: np.ndarray) -> str:
    h = hashlib.sha256(np.ascontiguousarray(obs, np.float32).tobytes())
    h.update(np.ascontiguousarray(action, np.float32).tobytes())
    return h.hexdigest()[:16]


class Watcher:
    """Scans an inbox and judges settled items (call :meth:`scan` repeatedly, or :meth:`run`).

    Attributes:
      done: keys ``(item, episode, content hash)`` already judged.
      handled: ``(item, signature)`` of items read (or failed) as they are now.
    """

    def __init__(self, config: WatchConfig, echo: Callable[[str], None]) -> None:
        from elicit_jax.compat.feedback import normalizer
        from elicit_jax.data.demos import read_demos
        from elicit_jax.elicit.inputs import load_session_policy
        from elicit_jax.elicit.rules import AcceptRule

        self.config = config
        self.echo = echo
        self.inbox = Path(config.inbox)
        if not self.inbox.is_dir():
            raise ElicitError("inbox is not a folder", self.inbox)
        self.out = config.out_dir
        self.base = read_demos(config.base_demos)
        self.policy = load_session_policy(
            config.policy, config.which, config.policy_seed, self.base, config.base_demos
        )
        self.rule = AcceptRule(config.accept_fraction, config.reject_count)
        self.stats = normalizer(self.base.obs)
        self.settler = Settler(config.settle)
        self.out.mkdir(parents=True, exist_ok=True)
        self.done: set[tuple[str, str, str]] = set()
        self.handled: set[tuple[str, str]] = set()
        self._load_log()

    @property
    def log_path(self) -> Path:
        return self.out / LOG_FILE

    def _load_log(self) -> None:
        if not self.log_path.exists():
            return
        for line in self.log_path.read_text().splitlines():
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut by a crash; its demonstration is judged again
            if "episode" in r:
                self.done.add((r["item"], str(r["episode"]), r["content"]))

    def _log(self, record: dict[str, Any]) -> None:
        with open(self.log_path, "a") as f:
            f.write(json.dumps(record, sort_keys=True) + "\n")
            f.flush()
            os.fsync(f.fileno())

    def pending(self) -> list[Path]:
        """Items not yet handled in their current state."""
        return [
            p
            for p in candidates(self.inbox, self.out)
            if (p.name, repr(signature(p))) not in self.handled
        ]

    def scan(self, now: float | None = None) -> int:
        """Judge every settled, unhandled item once; returns demonstrations judged."""
        now = time.monotonic() if now is None else now
        judged = 0
        for item in candidates(self.inbox, self.out):
            sig = self.settler.ready(item, now)
            if sig is None or (item.name, repr(sig)) in self.handled:
                continue
            try:
                judged += self.judge_item(item)
            except (ElicitError, OSError, ValueError) as e:
                if (e.__cause__ is not None and _busy(e.__cause__)) or _busy(e):
                    continue  # still open for writing: try again on the next scan
                # every line names the item; a reader's own error (not an ElicitError) too,
                # and the watch goes on with the next item
                text = str(e) if isinstance(e, ElicitError) else f"{type(e).__name__}: {e}"
                text = text if str(item) in text else f"{item}: {text}"
                self.echo(f"error: {text}")
                self._log({"item": item.name, "error": text, "time": time.time()})
            self.handled.add((item.name, repr(sig)))
        return judged

    def run(self) -> int:
        """Scan until ``once`` has nothing left, the timeout, or an interrupt."""
        c, t0, total = self.config, time.monotonic(), 0
        while True:
            total += self.scan()
            if c.once and not self.pending():
                return total
            if c.timeout is not None and time.monotonic() - t0 >= c.timeout:
                return total
            time.sleep(c.poll)

    def load(self, item: Path) -> Any:
        """Read an item with ``import``'s reader and options, and check it fits the policy."""
        import warnings

        from elicit_jax.compat.score import check_dims
        from elicit_jax.data.convert import ImportConfig, load_dataset
        from elicit_jax.data.demos import DemosWarning, validate
        from elicit_jax.sim.task_match import check_same_task

        cfg = ImportConfig(source=str(item), out="", **dict(self.config.import_options))
        try:
            demos = load_dataset(cfg)
        except OSError as e:
            raise ElicitError(f"cannot read ({e})", item) from e
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DemosWarning)
            demos = validate(demos, str(item), bounds=cfg.bounds)
        names = tuple(f.name for f in demos.obs_fields)
        check_dims(self.policy.policy, demos.obs_dim, demos.action_dim, str(item), names)
        check_same_task(demos.task, self.config.policy, item)
        return demos

    def judge_item(self, item: Path) -> int:
        """Score every new demonstration of ``item``; print, page and log each verdict."""
        from elicit_jax.compat.measures import ScoreConfig
        from elicit_jax.compat.score import score_demos
        from elicit_jax.data.demos import SOURCE_EPISODE

        c = self.config
        demos = self.load(item)
        config = ScoreConfig(
            likelihood=c.likelihood,  # type: ignore[arg-type]
            ddof=c.ddof,
            thresholds=c.thresholds,
            accept_fraction=c.accept_fraction,
        )
        todo = []
        for e, s, t in demos.episode_bounds():
            src = demos.extra.get(SOURCE_EPISODE)
            name = str(src[s]) if src is not None else str(e)
            key = (item.name, name, episode_hash(demos.obs[s:t], demos.action[s:t]))
            if key not in self.done:
                todo.append((e, name, key))
        if not todo:
            return 0
        chosen = demos.select_episodes([e for e, _, _ in todo])
        scores = score_demos(self.policy.policy, chosen, config)
        rows = {e: (s, t) for e, s, t in chosen.episode_bounds()}
        for e, name, key in todo:
            s, t = rows[e]
            self._judge_one(item, name, key, chosen, scores, s, t)
        return len(todo)

    def _judge_one(
        self, item: Path, name: str, key: tuple, demos: Any, scores: dict, s: int, t: int
    ) -> None:
        from elicit_jax.elicit.explain import explain_episode, summary_text
        from elicit_jax.elicit.pages import write_demo_page

        c = self.config
        m = scores["compatibility"][s:t]
        n_inc = int(scores["incompatible"][s:t].sum())
        length = t - s
        if not bool(demos.success[s]):
            verdict = "failed"
        else:
            verdict = "rejected" if self.rule.rejects(n_inc, length) else "accepted"
        feedback = explain_episode(
            m,
            demos.obs[s:t],
            demos.action[s:t],
            self.base,
            window=c.window,
            k=c.windows,
            method=c.retrieval,
            stats=self.stats,
        )
        shown = feedback if verdict == "rejected" else []
        text = summary_text(verdict, n_inc, length, self.rule.describe(), shown)
        if verdict == "failed":
            text = f"failed: the demonstration is marked unsuccessful ({length} steps)"
        stem = page_stem(item.name, name)
        page = self.out / f"{stem}.html"
        write_demo_page(
            page,
            self.out / f"{stem}.png",
            title=f"{item.name} / {name}",
            verdict=verdict,
            summary=[
                ("verdict", text),
                ("rule", self.rule.describe()),
                ("thresholds", f"λ = {c.thresholds.lam:.4g}, η = {c.thresholds.eta:.4g}"),
                ("length", f"{length} steps (base mean {self._base_length():.0f})"),
                ("policy", c.policy),
            ],
            compatibility=m,
            feedback=feedback,
            obs=demos.obs[s:t],
            base=self.base,
        )
        self.echo(f"{item.name} / {name}: {text} [{page}]")
        self._log(
            {
                "item": item.name,
                "episode": name,
                "content": key[2],
                "verdict": verdict,
                "length": length,
                "incompatible": n_inc,
                "fraction": n_inc / length,
                "text": text,
                "feedback": [f.text for f in shown],
                "page": page.name,
                "time": time.time(),
            }
        )
        self.done.add(key)

    def _base_length(self) -> float:
        b = self.base.episode_bounds()
        return float(np.mean([t - s for _, s, t in b]))
