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
                                                               the queue is paused (refused
                                                               once the job is closing)
``resume``     none                                            the queue runs again (after
                                                               ``abort``, or a fault)
``follow``     ``job`` (id, default the current or next one)    a stream: one ``event`` per
                                                               line (progress, log, state),
                                                               then one with ``"end": true``
``solutions``  ``limit`` (default 20)                           ``solutions``: run files with
                                                               a calibration, newest first
=============  ==============================================  ==============================

A refused schedule comes back as ``{"ok": false, "error": "...", "problems":
["file:line: key: message", ...]}`` and nothing is queued. A request whose fields have
the wrong type (or an unknown ``op``) is refused and the connection stays open.

The daemon may end a connection; it then says why in one last refusal with
``"closed"``: ``refused`` (the peer is not in the service's group), ``busy`` (too many
connections), ``idle`` (no request for a while, or room made for a new client),
``timeout`` (a line begun and not finished in time), ``long`` (a line over
:data:`MAX_LINE` bytes, refused as soon as it is seen) or ``protocol`` (a line that is
not a request of this version: not UTF-8, not JSON, too deeply nested, a number too
long, not an object). A job is a mapping with
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


class Closed(ControlError):
    """The daemon ended the connection and said why (``why``: see the module's text)."""

    def __init__(self, message: str, why: str) -> None:
        self.why = why
        super().__init__(message)


def encode(message: dict[str, Any]) -> bytes:
    """One message as a line."""
    return json.dumps({"v": VERSION, **message}, separators=(",", ":")).encode() + b"\n"


def decode(line: bytes) -> dict[str, Any]:
    """One line as a message, checked for its version.

    Every way a line can fail to be a message is a :class:`ControlError`: invalid UTF-8,
    bad JSON, nesting deep enough for Python's recursion limit, an integer longer than
    Python converts, ``NaN`` or ``Infinity``, anything but an object.
    """
    if len(line) > MAX_LINE + 1:  # its newline aside
        raise ControlError(f"message longer than {MAX_LINE} bytes")
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ControlError(f"not UTF-8: byte {err.start}") from None
    try:
        message = json.loads(text, parse_constant=_no_constant)
    except RecursionError:
        raise ControlError("not JSON: nested too deeply") from None
    except ValueError as err:  # JSONDecodeError, and int()'s limit on digits
        raise ControlError(f"not JSON: {str(err).split(';')[0][:120]}") from None
    if not isinstance(message, dict):
        raise ControlError("a message is a JSON object")
    if message.get("v") != VERSION:
        version = _short(message.get("v"))
        raise ControlError(f"protocol version {version}; this side speaks {VERSION}")
    return message


#: The fields each op takes: name -> (the types allowed, whether it must be given).
FIELDS: dict[str, dict[str, tuple[tuple[type, ...], bool]]] = {
    "submit": {"schedule": ((str,), True), "files": ((dict,), True)},
    "cancel": {"job": ((int,), True)},
    "follow": {"job": ((int, type(None)), False)},
    "solutions": {"limit": ((int,), False)},
}
#: The most solutions one request lists.
MAX_SOLUTIONS = 1000


def check_request(message: dict[str, Any]) -> dict[str, Any]:
    """A decoded request checked for its op and its fields' types (the daemon's side)."""
    op = message.get("op")
    if not isinstance(op, str) or op not in OPS:
        raise ControlError(f"unknown op {_short(op)} (ops: {', '.join(OPS)})")
    for name, (types, required) in FIELDS.get(op, {}).items():
        if name not in message:
            if required:
                raise ControlError(f"{op} needs {name!r}")
            continue
        value = message[name]
        if isinstance(value, bool) or not isinstance(value, types):
            wanted = " or ".join("null" if t is type(None) else t.__name__ for t in types)
            raise ControlError(f"{op}: {name!r} must be {wanted}, not {_short(value)}")
    files: dict[Any, Any] = message["files"] if op == "submit" else {}
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        raise ControlError("submit: 'files' maps each path to its text (strings)")
    job = message.get("job")
    if isinstance(job, int) and job < 0:
        raise ControlError(f"{op}: 'job' is a job's id (0 or more), not {job}")
    limit = message.get("limit", 1)
    if op == "solutions" and not 1 <= limit <= MAX_SOLUTIONS:
        raise ControlError(f"solutions: 'limit' is 1 to {MAX_SOLUTIONS}, not {limit}")
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


def closing(error: str, why: str) -> dict[str, Any]:
    """The last message of a connection the daemon ends, and why (module's text)."""
    return {"ok": False, "error": error, "closed": why}


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number here")


def _short(value: Any) -> str:
    """A value as the client sent it, cut short for a message."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}..."
