"""The control socket's protocol, version 1: newline-delimited JSON, one request, one reply.

A client connects to ``<runtime_dir>/control.sock`` (a Unix stream socket that only the
service's group may open), writes one JSON object per line and reads one JSON object per
line back. Every request carries ``"v": 1`` and an ``"op"``; every reply carries
``"v": 1`` and ``"ok"`` (with ``"error"``, and for a refused schedule ``"problems"``,
when it is false). A connection may carry many requests in turn.

=============  ==============================================  ==============================
op             request fields                                  reply fields (``ok`` true)
=============  ==============================================  ==============================
``status``     none                                            ``state``, ``job`` (current or
                                                               null), ``step``, ``left_s``,
                                                               ``queue`` (ids), ``alarms``,
                                                               ``since`` (of the state)
``submit``     ``schedule`` (its path as the client names it),  ``job`` (the new job)
               ``files`` ({path: text} of it and its includes)
``queue``      none                                            ``jobs`` (queued and recent)
``cancel``     ``job`` (id)                                    ``job``: a queued job is
                                                               dropped, a running one stopped
                                                               cooperatively
``abort``      none                                            ``job``: the running job stops
                                                               now, the front-end goes safe;
                                                               the queue is paused
``resume``     none                                            the queue runs again (after
                                                               ``abort``, or a fault)
``follow``     ``job`` (id, default the current or next one)    a stream: one ``event`` per
                                                               line (progress, log, state),
                                                               then one with ``"end": true``
``solutions``  ``limit`` (default 20)                           ``solutions``: run files with
                                                               a calibration, newest first
=============  ==============================================  ==============================

A refused schedule comes back as ``{"ok": false, "error": "...", "problems":
["file:line: key: message", ...]}`` and nothing is queued. A job is a mapping with
``id``, ``name``, ``state`` (``queued``, ``running``, ``completed``, ``failed``,
``interrupted``, ``cancelled``), ``origin`` (``socket`` with the submitter's uid, a
timer, or a resumption), ``submitted``, ``started``, ``ended`` (Unix seconds or null),
``run`` (its run directory) and ``reason``.
"""

from __future__ import annotations

import json
from typing import Any

from reach_receiver.errors import ReceiverError

VERSION = 1
#: The longest line either side accepts: a schedule and its includes fit many times.
MAX_LINE = 4 * 2**20
OPS = ("status", "submit", "queue", "cancel", "abort", "resume", "follow", "solutions")


class ControlError(ReceiverError):
    """A request or reply that breaks the protocol, or a refusal from the daemon."""

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        self.problems = list(problems or [])
        super().__init__(message)


def encode(message: dict[str, Any]) -> bytes:
    """One message as a line."""
    return json.dumps({"v": VERSION, **message}, separators=(",", ":")).encode() + b"\n"


def decode(line: bytes) -> dict[str, Any]:
    """One line as a message, checked for its version."""
    if len(line) > MAX_LINE:
        raise ControlError(f"message longer than {MAX_LINE} bytes")
    try:
        message = json.loads(line)
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ControlError(f"not JSON: {err}") from err
    if not isinstance(message, dict):
        raise ControlError("a message is a JSON object")
    if message.get("v") != VERSION:
        raise ControlError(f"protocol version {message.get('v')!r}; this side speaks {VERSION}")
    return message


def reply(**fields: Any) -> dict[str, Any]:
    """A successful reply."""
    return {"ok": True, **fields}


def refusal(error: str, problems: list[str] | None = None) -> dict[str, Any]:
    """A refused request."""
    out: dict[str, Any] = {"ok": False, "error": error}
    if problems:
        out["problems"] = problems
    return out
