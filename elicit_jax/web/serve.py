"""``elicit-jax serve``: check the inputs, bind, print the URL, serve until Ctrl-C, summarise.

Without ``--horizon``, episodes last :func:`~elicit_jax.elicit.config.person_horizon` steps
(4 × the base demonstrations' 95th-percentile length: time a person at a keyboard can meet;
:func:`with_person_horizon`, called by the CLI; ``--horizon 0`` keeps the task's).
Before binding, :func:`preflight` opens a throwaway session with the server's settings, so a
bad input fails at start with the session's own one-line error (not when the first operator
arrives), and the scorers are compiled by then. The server binds 127.0.0.1 by default;
binding any other address requires an access token (:mod:`elicit_jax.web.access`), made up
and printed once in the URL unless ``--token`` gives one. The experimenter's dashboard
(``/admin``) always needs the admin token, made up and printed once unless ``--admin-token``
gives one. Requests naming the server by any other ``Host`` than the bound names are refused.
"""

from __future__ import annotations

import dataclasses
import logging
import re
import socket
import tempfile
from collections.abc import Callable
from pathlib import Path

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.errors import ElicitError
from elicit_jax.web.access import access_policy, is_loopback, new_token
from elicit_jax.web.hub import OperatorHub, session_names

_TOKEN_RE = re.compile(r"[A-Za-z0-9_.~-]+")
_HOST_RE = re.compile(r"[A-Za-z0-9.-]{1,253}|\[?[0-9A-Fa-f:.]{2,45}\]?")


@dataclasses.dataclass(frozen=True)
class ServeConfig:
    """How to serve.

    Attributes:
      session: the settings every operator's session gets (their operator becomes
        ``browser:NAME``).
      sessions: the sessions directory (one subdirectory per operator).
      host: address to bind (127.0.0.1: this machine only).
      port: port to bind (0: any free one; the printed URL says which).
      token: the access token (off loopback: made up when not given).
      max_operators: most operators at once.
      admin_token: the dashboard's token (made up when not given).
      allow_hosts: more names operators reach the server by (a DNS name, a proxy's name).
    """

    session: SessionConfig
    sessions: str
    host: str = "127.0.0.1"
    port: int = 8765
    token: str | None = None
    max_operators: int = 16
    admin_token: str | None = None
    allow_hosts: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise ElicitError(f"--port must be in 0..65535, got {self.port}")
        if self.max_operators < 1:
            raise ElicitError(f"--max-operators must be >= 1, got {self.max_operators}")
        for flag, tok in (("--token", self.token), ("--admin-token", self.admin_token)):
            if tok is not None and (len(tok) < 8 or not _TOKEN_RE.fullmatch(tok)):
                raise ElicitError(f"{flag} must be at least 8 of A-Z a-z 0-9 _ - . ~")
        if self.token is not None and self.token == self.admin_token:
            raise ElicitError("--admin-token must differ from --token (operators hold --token)")
        bad = [h for h in self.allow_hosts if not _HOST_RE.fullmatch(h)]
        if bad:
            raise ElicitError(f"--allow-host takes a host name or address, got {bad[0]!r}")
        if Path(self.sessions).exists() and not Path(self.sessions).is_dir():
            raise ElicitError("is a file, not a sessions directory", self.sessions)


def preflight(template: SessionConfig) -> None:
    """Open (then delete) a session with ``template``'s settings: the inputs are checked by
    the session's own code, the live and prompt scorers are compiled, and the task's scene
    is described once (a robosuite task builds its environment here, kept for the first
    operator)."""
    import numpy as np

    from elicit_jax.elicit.setup import open_session
    from elicit_jax.web import operator as browser_operator
    from elicit_jax.web.scene import scene_description

    config = dataclasses.replace(template, operator=f"{browser_operator.KIND}:preflight")
    with tempfile.TemporaryDirectory(prefix="elicit-serve-") as tmp:
        setup, _, _ = open_session(config, Path(tmp) / "check")
        zeros_o = np.zeros(setup.obs_dim, np.float32)
        setup.scorer.score(setup.policy.policy, zeros_o, np.zeros(setup.action_dim, np.float32))
        if config.mode == "informed" and config.prompt:
            setup.prompt_event()
        scene_description(setup.task.mj_model, setup.task.name)


def with_person_horizon(session: SessionConfig) -> SessionConfig:
    """``session`` with its horizon (0: the task's) set for people at a keyboard
    (:func:`~elicit_jax.elicit.config.person_horizon` of the base demonstrations' lengths);
    ``serve`` uses it when ``--horizon`` is not given."""
    if session.horizon:
        return session
    from elicit_jax.data.demos import read_demos
    from elicit_jax.elicit.config import person_horizon
    from elicit_jax.sim.env import make_task

    lengths = [e - s for _, s, e in read_demos(session.base_demos).episode_bounds()]
    task_horizon = make_task(session.task).config.horizon
    return dataclasses.replace(session, horizon=person_horizon(task_horizon, lengths))


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (IPv4 or IPv6)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as e:
        sock.close()
        raise ElicitError(f"cannot listen on {host}:{port}: {e.strerror}") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


def url_of(host: str, port: int, token: str | None, path: str = "/") -> str:
    """The URL operators open (``path``: another page of the server)."""
    shown = socket.gethostname() if host in ("0.0.0.0", "::") else host
    shown = f"[{shown}]" if ":" in shown else shown
    return f"http://{shown}:{port}{path}" + (f"?token={token}" if token else "")


class _DenialNoise(logging.Filter):
    """Drops uvicorn's spurious error after a WebSocket denial response (the 400 of the Host
    check): its websockets-sansio protocol never marks such a handshake complete (uvicorn
    pull request 3138); the client gets the 400 all the same."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "ASGI callable returned without completing handshake."


def serve(
    config: ServeConfig,
    echo: Callable[[str], None],
    summary: Callable[[OperatorHub], None] | None = None,
) -> None:
    """Serve operators until interrupted (see the module docstring).

    Args:
      config: what to serve, where.
      echo: shows one line (the start-up lines, the hub's log).
      summary: called with the hub after the server stopped, when it served anyone (the CLI
        prints a table per operator).
    """
    import uvicorn

    root = Path(config.sessions)
    token = config.token
    if token is None and not is_loopback(config.host):
        token = new_token()
    echo(f"checking the inputs and compiling the scorer for {config.session.task} ...")
    preflight(config.session)
    root.mkdir(parents=True, exist_ok=True)
    hub = OperatorHub(config.session, root, config.max_operators, log=echo)
    from elicit_jax.web.server import create_app

    sock = bind(config.host, config.port)
    port = sock.getsockname()[1]
    access = access_policy(config.host, port, token, config.admin_token, config.allow_hosts)
    app = create_app(hub, access, url_of(config.host, port, None))
    known = session_names(root)
    c = config.session
    echo(
        f"serving {c.task} ({c.mode}{', HG-DAgger' if c.dagger else ''}; {c.demos} demonstrations "
        f"wanted per operator; episodes of up to {c.horizon} steps) — sessions in {root}"
        + (f"; {len(known)} to resume: {', '.join(known)}" if known else "")
    )
    if token is not None:
        echo("access token required (it is in the URL below; share it only with operators)")
    echo(
        f"dashboard (experimenter only): {url_of(config.host, port, access.admin_token, '/admin')}"
    )
    echo(f"open {url_of(config.host, port, token)}   (Ctrl-C stops)")
    server = uvicorn.Server(
        uvicorn.Config(app, log_level="warning", ws_per_message_deflate=False, lifespan="on")
    )
    noise = _DenialNoise()
    logging.getLogger("uvicorn.error").addFilter(noise)
    try:
        server.run(sockets=[sock])
    finally:
        logging.getLogger("uvicorn.error").removeFilter(noise)
        sock.close()
        hub.shutdown()
        if hub.drivers and summary is not None:
            summary(hub)
