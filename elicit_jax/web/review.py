"""The review page's server: ``elicit-jax review`` (transport only; the review itself is
:class:`elicit_jax.curation.review.Review`).

Routes: ``GET /`` the page (``static/review.html``), ``/static/...`` its scripts (the same
three.js view as ``serve``), ``GET /api/episodes`` the episode table, ``GET /api/scene`` the
task's 3-D scene (or why there is none), ``GET /api/episode/{id}`` an episode's body poses and
per-step M, ``POST /api/flag`` flag/unflag an episode with a reason, ``POST /api/export`` write
the selection. The server binds 127.0.0.1 only, answers only requests whose ``Host`` is that
address (or ``localhost``) at its port (a DNS-rebinding page cannot reach it; the same
guard as ``serve``'s, :mod:`elicit_jax.web.access`), and requires the
access token it prints (``?token=`` on first load, then a cookie named after the port) on
every request. As on ``/admin``, a POST must come from the page itself (its ``Origin`` is
this server's, port included): a page of another site — another port of 127.0.0.1 — cannot
flag or export through the reviewer's browser. The POST bodies are strict JSON: an episode is
an integer, ``flagged`` true or false, NaN and Infinity are refused; anything else gets one
400 line saying what is wrong.
"""

from __future__ import annotations

import base64
from collections.abc import Callable
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

HOST = "127.0.0.1"


class Clips:
    """The task's scene and episode pose clips, or why there is no 3-D view."""

    def __init__(self, demos: Any) -> None:
        self.task, self.maker, self.why = None, None, ""
        name = str(demos.task)
        try:
            from elicit_jax.sim.env import OBS_DIM, make_task

            task = make_task(name)
        except ElicitError as e:
            self.why = f"no 3-D view: {e}"
            return
        if demos.obs_dim != OBS_DIM:
            self.why = f"no 3-D view: the demos' observations are not {name}'s ({OBS_DIM}-D)"
            return
        from elicit_jax.web.clips import ClipMaker

        self.task, self.maker = task, ClipMaker(task, demos)

    def scene(self) -> dict[str, Any]:
        from elicit_jax.web.scene import scene_description

        if self.task is None:
            return {"scene": None, "why": self.why}
        return {"scene": scene_description(self.task.mj_model, self.task.name), "why": ""}

    def poses(self, episode: int) -> np.ndarray | None:
        return None if self.maker is None else self.maker.base_episode(episode)


CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
"""The page's Content-Security-Policy: everything from this server, nothing inline."""


MAX_BODY = 4096
FLAG_FIELDS = {"episode": ("an episode number", int), "flagged": ("true or false", bool),
               "reason": ("a string", str)}  # fmt: skip
EXPORT_FIELDS = {"format": ("a string or null", (str, type(None))),
                 "mask_key": ("a string or null", (str, type(None)))}  # fmt: skip
REQUIRED = {"episode", "flagged"}


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


async def json_body(request: Any, fields: dict[str, tuple[str, Any]], what: str) -> dict:
    """The request's JSON object, each field of the type ``fields`` names (an integer is
    never a bool or a float, a flag never a string; NaN and Infinity are refused).

    Raises:
      ElicitError: one line naming the first problem (the page shows it).
    """
    import json

    raw = await request.body()
    try:
        if len(raw) > MAX_BODY:
            raise ValueError(f"longer than {MAX_BODY} bytes")
        body = json.loads(raw, parse_constant=_no_constant)
        if not isinstance(body, dict):
            raise ValueError("not a JSON object")
        extra = sorted(set(body) - set(fields))
        if extra:
            raise ValueError(f"unknown field(s) {', '.join(map(repr, extra))}")
        for key, (kind, types) in fields.items():
            if key not in body:
                if key in REQUIRED:
                    raise ValueError(f"no {key!r}")
                continue
            value = body[key]
            exact_int = types is int and type(value) is int  # bool is an int subclass
            if not (exact_int or (types is not int and isinstance(value, types))):
                raise ValueError(f"{key!r} must be {kind}, not {json.dumps(value)[:40]}")
    except (ValueError, RecursionError) as err:  # JSONDecodeError is a ValueError
        raise ElicitError(f"malformed {what} request: {err}") from None
    return body


def _bad(e: ElicitError) -> Any:
    from starlette.responses import JSONResponse

    return JSONResponse({"error": str(e)}, status_code=400)


class ReviewRoutes:
    """The endpoints of one review (the routes of the module docstring), as methods."""

    def __init__(self, review: Any) -> None:
        self.review = review
        self.clips = Clips(review.demos)

    def index(self, request: Any) -> Any:
        """The page; a ``?token=`` becomes the access cookie."""
        from starlette.responses import FileResponse

        from elicit_jax.web.server import STATIC

        response = FileResponse(
            STATIC / "review.html",
            headers={"Cache-Control": "no-store", "Content-Security-Policy": CSP},
        )
        if request.query_params.get("token"):  # the guard let it in: it is the token
            cookie = request.app.state.access.token_cookie
            response.set_cookie(
                cookie, request.query_params["token"], httponly=True, samesite="strict"
            )
        return response

    def episodes(self, request: Any) -> Any:
        """The episode table."""
        from starlette.responses import JSONResponse

        review, task = self.review, self.clips.task
        return JSONResponse(
            {
                "demos": str(review.config.demos),
                "task": task.name if task else "",
                "has_m": bool(review.m),
                "has_quality": bool(review.quality),
                "episodes": review.episodes(),
            }
        )

    def scene(self, request: Any) -> Any:
        """The task's 3-D scene, or why there is none."""
        from starlette.responses import JSONResponse

        return JSONResponse(self.clips.scene())

    def episode(self, request: Any) -> Any:
        """An episode's body poses (base64 float32) and per-step M."""
        from starlette.responses import JSONResponse

        given = request.path_params["episode"]
        if not given.isdecimal() or len(given) > 9:
            return _bad(ElicitError(f"not an episode number: {given[:20]!r}"))
        e = int(given)
        try:
            data = self.review.episode(e)
        except ElicitError as err:
            return _bad(err)
        poses = self.clips.poses(e)
        return JSONResponse(
            {
                "episode": e,
                "steps": len(data["obs"]),
                "m": None if data["m"] is None else [round(float(v), 4) for v in data["m"]],
                "poses": None
                if poses is None
                else base64.b64encode(np.ascontiguousarray(poses, "<f4").tobytes()).decode(),
                "nbody": 0 if poses is None else int(poses.shape[1]),
            }
        )

    async def flag(self, request: Any) -> Any:
        """Flag or unflag an episode, with a reason."""
        from starlette.responses import JSONResponse

        try:
            body = await json_body(request, FLAG_FIELDS, "flag")
            self.review.flag(body["episode"], body["flagged"], body.get("reason", ""))
        except ElicitError as err:
            return _bad(err)
        return JSONResponse({"ok": True, "flagged": len(self.review.flags)})

    async def export(self, request: Any) -> Any:
        """Write the selection (the review's export)."""
        from starlette.responses import JSONResponse

        try:
            body = await json_body(request, EXPORT_FIELDS, "export")
            fmt = body.get("format") or None
            result = self.review.export(fmt, body.get("mask_key") or "reviewed")
        except ElicitError as err:
            return _bad(err)
        return JSONResponse(result)


def create_review_app(review: Any, token: str, port: int) -> Any:
    """The Starlette application of one review (see the module docstring)."""
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    from elicit_jax.web.access import AccessGuard, access_policy
    from elicit_jax.web.server import STATIC

    r = ReviewRoutes(review)
    policy = access_policy(HOST, port, token)
    app = Starlette(
        routes=[
            Route("/", r.index),
            Route("/api/episodes", r.episodes),
            Route("/api/scene", r.scene),
            Route("/api/episode/{episode}", r.episode),
            Route("/api/flag", r.flag, methods=["POST"]),
            Route("/api/export", r.export, methods=["POST"]),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ],
        middleware=[Middleware(AccessGuard, policy=policy)],
    )
    app.state.access = policy
    return app


def serve_review(review: Any, port: int, echo: Callable[[str], None]) -> None:
    """Serve ``review`` on 127.0.0.1 until interrupted; ``echo`` says the URL (with its
    token): the CLI passes its printer."""
    import uvicorn

    from elicit_jax.web.access import new_token
    from elicit_jax.web.serve import bind, url_of

    token = new_token()
    sock = bind(HOST, port)
    port = sock.getsockname()[1]
    app = create_review_app(review, token, port)
    echo(f"reviewing {review.config.demos}: {len(review.bounds)} episodes; state in {review.out}")
    echo(f"open {url_of(HOST, port, token)}   (Ctrl-C stops)")
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off"))
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()
