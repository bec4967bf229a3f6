"""``reach-run status|queue|attach|cancel|abort|resume``: one request to ``reachd``.

The site file names the daemon's runtime directory, where its control socket answers.
Each command sends one request and prints the reply: ``status`` as a short summary
within 80 columns (:mod:`.status_summary`), every reading with ``--all``
(:func:`.health.format_health`), the whole reply with ``--json``; ``attach`` follows a
job (:func:`.remote.follow`, imported only then: it needs the run layer).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from reach_receiver.config.site_file import find_site, load_daemon_settings
from reach_receiver.daemon.client import DaemonClient, daemon_answers, socket_path
from reach_receiver.daemon.protocol import Closed, ControlError
from reach_receiver.errors import ReceiverError


def steer(op: str, args: argparse.Namespace) -> int:
    """Find the daemon from the site file and send it ``op``; exit 0, 1 or 2."""
    try:
        daemon = load_daemon_settings(find_site(args.site))
    except ReceiverError as err:
        print(f"reach-run {op}: {err}", file=sys.stderr)
        return 2
    path = socket_path(daemon.runtime_directory())
    if not daemon_answers(path):
        print(f"reach-run {op}: no daemon answers at {path}", file=sys.stderr)
        return 1
    with DaemonClient(path) as client:
        if op == "attach":
            from .remote import follow

            return follow(client, args.job or None)
        fields = {"job": args.job} if op == "cancel" else {}
        return request(client, op, json_out=getattr(args, "json", False),
                       every=getattr(args, "all", False), **fields)


def request(client: DaemonClient, op: str, json_out: bool = False, every: bool = False,
            **fields: Any) -> int:
    """One request (status, queue, cancel, abort, resume), its reply printed."""
    try:
        answer = client.request(op, **fields)
        if op == "status" and not every:
            answer["last_calibration"] = _last_calibration(client)
    except ControlError as err:
        print(f"reach-run {op}: {err}", file=sys.stderr)
        return 1
    except (Closed, OSError) as err:
        print(f"reach-run {op}: {unreached(client, err)}", file=sys.stderr)
        return 1
    if json_out:
        from .commands import dumps

        print(dumps({k: v for k, v in answer.items() if k != "ok"}))
    elif op == "status":
        _print_status(answer, every)
    elif op == "queue":
        for job in answer["jobs"]:
            line = f"{job['id']:>5} {job['state']:<11} {job['name']}  {job['origin']}"
            print(f"{line}  {job['reason']}".rstrip())
    else:
        print(f"{op}: done" + (f" (job {answer['job']['id']})" if answer.get("job") else ""))
    return 0


def _last_calibration(client: DaemonClient) -> dict[str, Any] | None:
    """The newest run with a solution (the daemon's ``solutions`` request), or None."""
    found = client.request("solutions", limit=1).get("solutions") or []
    return dict(found[0]) if found else None


def _print_status(answer: dict[str, Any], every: bool) -> None:
    if not every:
        from .status_summary import summary_lines

        print("\n".join(summary_lines(answer)))
        return
    from .health import format_health

    print(answer["status"])
    if answer["queue"]:
        print(f"queued: {', '.join(map(str, answer['queue']))}")
    for name, at in sorted(answer.get("timers", {}).items()):
        print(f"timer {name}: next at {at:.0f} (Unix s)")
    for line in format_health(answer.get("health"), answer.get("now")):
        print(line)


def unreached(client: DaemonClient, err: Exception) -> str:
    """What went wrong with the daemon, as a user reads it (an ``OSError`` named)."""
    if isinstance(err, OSError):
        return f"the daemon at {client.path} cannot be reached: {err.strerror or err}"
    return str(err)
