"""The experimenter's dashboard: ``/admin`` (behind the admin token, see
:mod:`elicit_jax.web.access`).

The page (``static/admin.html``, ``admin.js``) polls ``GET /admin/api/state`` once a second:
one row per operator of the sessions directory — their status (active, paused, ended),
whether their page is here, the screen the server has them on, episode and step, accepted /
rejected / failed counts and the last verdict. Actions are POSTs:

=====================================  ===========================================================
``/admin/api/operators/NAME/link``     a new key for NAME: returns their personal link; their old
                                       key stops working. A name that is not an operator yet
                                       needs ``?create=1`` (the page asks first; 409 otherwise),
                                       and at most ``MAX_NEW_PER_MINUTE`` are created a minute
``/admin/api/operators/NAME/pause``    close their page and keep them out until resumed
``/admin/api/operators/NAME/resume``   let them in again (paused or ended)
``/admin/api/operators/NAME/end``      end their session: no more episodes (kept and counted)
``/admin/api/operators/NAME/remove``   take them out of the study: session moved to
                                       ``SESSIONS/.removed/`` (nothing deleted, not merged)
=====================================  ===========================================================

Names are case-insensitive (``ALICE`` is the existing ``alice``,
:meth:`~elicit_jax.web.hub.OperatorHub.canonical`). The links issued since the server started
are kept in memory (never on disk) and listed by ``/admin/api/state``, each operator's newest.

Downloads: ``/admin/download/NAME.parquet`` (one operator's accepted demonstrations, their
session's ``demos.parquet``) and ``/admin/download/merged.parquet`` (every operator's, one
demos artifact; :func:`~elicit_jax.elicit.sessions_folder.merge_accepted`). Both are the
demos format ``elicit-jax info`` / ``import`` / ``train`` read.
"""

from __future__ import annotations

import tempfile
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.web.keys import ACTIVE, ENDED, PAUSED
from elicit_jax.web.protocol import valid_name

STATIC = Path(__file__).parent / "static"
ACTIONS = {"pause": PAUSED, "resume": ACTIVE, "end": ENDED}
MAX_NEW_PER_MINUTE = 10
"""New operator names the dashboard creates in any minute (a runaway script, a stuck key)."""


class NewNames:
    """When the dashboard created its latest new names (the per-minute limit)."""

    def __init__(self, limit: int = MAX_NEW_PER_MINUTE, window_s: float = 60.0) -> None:
        self.limit, self.window_s = limit, window_s
        self.times: deque[float] = deque()
        self.lock = threading.Lock()

    def take(self) -> bool:
        """Count one more new name now; False (not counted) when the limit is reached."""
        now = time.monotonic()
        with self.lock:
            while self.times and now - self.times[0] > self.window_s:
                self.times.popleft()
            if len(self.times) >= self.limit:
                return False
            self.times.append(now)
            return True


def screen_of(status: dict[str, Any]) -> str:
    """The screen the operator's page shows, as the server sees it (``driver.status()``)."""
    state = status["state"]
    fixed = {"error": "error", "opening": "loading", "busy": "retrain", "done": "done"}
    if state in fixed:
        return fixed[state]
    if status["review_pending"]:
        return "review"
    kind = status["episode_kind"]
    if kind == "demonstration" and status["prompt_pending"]:
        return "prompt"
    return "practice" if kind == "practice" else "demonstrate"


def _counts(c: Any) -> dict[str, int]:
    get = c.get if isinstance(c, dict) else lambda k: getattr(c, k)
    return {k: int(get(k)) for k in ("accepted", "wanted", "rejected", "failed", "episodes")}


def operator_row(hub: Any, name: str) -> dict[str, Any]:
    """One dashboard row (see the module docstring)."""
    from elicit_jax.elicit.sessions_folder import session_summary

    row: dict[str, Any] = {"name": name, "status": hub.status_of(name), "page": False}
    d = hub.drivers.get(name)
    st = d.status() if d is not None else None
    if st is not None and st["counts"] is not None:
        screen = screen_of(st)
        row |= {"page": st["attached"], "screen": screen, "state": st["state"]}
        row |= {"episode": st["episode"], "step": st["step"], "kind": st["episode_kind"]}
        row |= {"counts": _counts(st["counts"]), "last_verdict": st["last_verdict"]}
        row |= {"message": st["message"]}
        return row
    row |= {"screen": "away", "state": "away", "episode": -1, "step": 0, "kind": ""}
    try:
        s = session_summary(hub.root / name)
    except ElicitError:
        return row | {"screen": "not started", "counts": None, "last_verdict": ""}
    if s["phase"].startswith("done"):
        row["screen"] = "done"
    return row | {"counts": _counts(s["counts"]), "last_verdict": s["last_verdict"]}


def state(hub: Any, links: dict[str, str] | None = None) -> dict[str, Any]:
    """Everything the dashboard shows (``links``: the issued links, by operator)."""
    c = hub.template
    names = hub.names()
    return {
        "task": c.task,
        "mode": c.mode + (" + HG-DAgger" if c.dagger else ""),
        "wanted": c.demos,
        "sessions": str(hub.root),
        "operators": [operator_row(hub, n) for n in names],
        "links": [{"name": n, "link": (links or {})[n]} for n in names if n in (links or {})],
    }


def _json(data: Any, status: int = 200) -> Any:
    from starlette.responses import JSONResponse

    return JSONResponse(data, status, headers={"Cache-Control": "no-store"})


def _page(request: Any) -> Any:
    from starlette.responses import FileResponse

    from elicit_jax.web.access import PAGE_HEADERS

    response = FileResponse(STATIC / "admin.html", headers=PAGE_HEADERS)
    token, cookie = request.query_params.get("token"), request.app.state.access.admin_cookie
    if token:  # the guard let it in: it is the admin token
        response.set_cookie(cookie, token, httponly=True, samesite="strict")
    return response


def _links(request: Any) -> dict[str, str]:
    return request.app.state.links


def _state(request: Any) -> Any:
    return _json(state(request.app.state.hub, _links(request)))


def _name(request: Any) -> str:
    """The operator the path names, in their existing spelling (names ignore case)."""
    name = request.path_params["name"]
    if not valid_name(name):
        raise ElicitError(f"not an operator name: {name[:40]!r}")
    return request.app.state.hub.canonical(name)


def _link(request: Any) -> Any:
    app = request.app.state
    try:
        name = _name(request)
    except ElicitError as e:
        return _json({"error": str(e)}, 400)
    if name not in app.hub.names():
        if request.query_params.get("create") != "1":
            why = f"{name!r} is not an operator yet: confirm creating a new operator"
            return _json({"error": why, "new": True}, 409)
        if not app.new_names.take():
            why = f"more than {MAX_NEW_PER_MINUTE} new operators in a minute: wait a little"
            return _json({"error": why}, 429)
    key = app.hub.issue_key(name)
    query = f"?token={app.access.token}" if app.access.token else ""
    link = f"{app.base_url}{query}#op={name}&key={key}"
    _links(request)[name] = link
    return _json({"name": name, "link": link})


def _act(request: Any) -> Any:
    hub, action = request.app.state.hub, request.path_params["action"]
    try:
        name = _name(request)
    except ElicitError as e:
        return _json({"error": str(e)}, 400)
    if name not in hub.names():
        return _json({"error": f"no operator {name!r}"}, 404)
    if action == "remove":
        try:
            dest = hub.remove(name)
        except ElicitError as e:
            return _json({"error": str(e)}, 409)
        _links(request).pop(name, None)
        return _json({"name": name, "moved_to": None if dest is None else str(dest)})
    if action not in ACTIONS:
        return _json({"error": f"unknown action {action[:20]!r}"}, 404)
    hub.set_status(name, ACTIONS[action])
    return _json({"name": name, "status": ACTIONS[action]})


def _download(request: Any) -> Any:
    from starlette.background import BackgroundTask
    from starlette.responses import FileResponse, PlainTextResponse

    from elicit_jax.elicit.sessions_folder import merge_accepted

    hub, which = request.app.state.hub, request.path_params["which"]
    if which != "merged" and not valid_name(which):
        return PlainTextResponse("not an operator name\n", 400)
    tmp = tempfile.TemporaryDirectory(prefix="elicit-download-")
    out = Path(tmp.name) / f"{which}-demos.parquet"
    try:
        merge_accepted(hub.root, out, None if which == "merged" else [which])
    except ElicitError as e:
        tmp.cleanup()
        return PlainTextResponse(f"{e}\n", 404)
    return FileResponse(
        out,
        media_type="application/vnd.apache.parquet",
        filename=out.name,
        headers={"Cache-Control": "no-store"},
        background=BackgroundTask(tmp.cleanup),
    )


def admin_routes() -> list[Any]:
    """The dashboard's routes (sync handlers: Starlette runs them in its thread pool)."""
    from starlette.routing import Route

    return [
        Route("/admin", _page),
        Route("/admin/api/state", _state),
        Route("/admin/api/operators/{name}/link", _link, methods=["POST"]),
        Route("/admin/api/operators/{name}/{action}", _act, methods=["POST"]),
        Route("/admin/download/{which}.parquet", _download),
    ]
