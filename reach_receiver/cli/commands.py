"""``reach-run``'s command words, shaped like git's or systemctl's.

``reach-run COMMAND [options]``: ``run``, ``check``, ``status``, ``queue``, ``attach``,
``cancel``, ``abort``, ``resume``, ``metrics``, ``recover``, ``completion``; each has its
own ``--help`` ending in its exit codes, and ``--version``. ``reach-run SCHEDULE.yaml``
(a path) runs a schedule, as ``reach-run run SCHEDULE.yaml`` does, and the flags that
came before the words (``--status``, ``--attach``, ``--validate``, ``--dry-run``, ...)
still work. A word that is neither a command nor a path is refused with the closest
command ("did you mean 'status'?"), exit 2; bare ``reach-run`` prints its usage, exit 2.

This module imports only the standard library and the small modules each command needs,
after its arguments are read: ``--help``, ``--version`` and ``status`` start in a tenth
of a second, where the engine, astropy and matplotlib cost a second.
"""

from __future__ import annotations

import argparse
import difflib
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from .logs import add_version, version

#: Each command: its one-line description and its exit codes.
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("check a schedule, then run it (here, or in reachd when it runs)",
            "0 the run completed; 1 it did not (stopped, failed, busy); 2 invalid input"),
    "check": ("check a schedule against the site; --dry-run prints its timeline",
              "0 valid; 2 invalid (every problem printed as file:line: key: message)"),
    "status": ("the daemon's state, job, alarms, last calibration and devices",
               "0 printed; 1 no daemon answers; 2 invalid input"),
    "queue": ("the daemon's jobs", "0 printed; 1 no daemon answers; 2 invalid input"),
    "attach": ("follow a job of the daemon again (the current one by default)",
               "0 the job completed; 1 it did not, or no daemon answers"),
    "cancel": ("drop a queued job, or stop the running one",
               "0 done; 1 refused or no daemon answers; 2 invalid input"),
    "abort": ("stop the running job now and make the front-end safe",
              "0 done; 1 refused or no daemon answers"),
    "resume": ("run the daemon's queue again after an abort",
               "0 done; 1 refused or no daemon answers"),
    "metrics": ("a series of the daemon's metrics: a summary, or --all/--csv/--json",
                "0 printed; 1 no metrics database; 2 invalid input or no such series"),
    "recover": ("merge the parts of a killed run into its run.h5",
                "0 merged; 1 the merge failed; 2 not a run directory"),
    "completion": ("print a shell completion script (bash): "
                   "source <(reach-run completion bash)", "0 printed; 2 unknown shell"),
}

#: The commands that ask the daemon over its control socket.
DAEMON = ("status", "queue", "attach", "cancel", "abort", "resume")


def usage() -> str:
    """``reach-run``'s own help: its commands, one line each."""
    width = max(map(len, COMMANDS))
    lines = [
        "usage: reach-run COMMAND [options]   (reach-run COMMAND --help for one)",
        "       reach-run [options] SCHEDULE.yaml   (same as: reach-run run SCHEDULE.yaml)",
        "",
        "commands:",
        *(f"  {name:<{width}}  {text}" for name, (text, _) in COMMANDS.items()),
        "",
        "options: --version, -h/--help",
        "exit codes: 0 success; 1 the run or request failed; 2 invalid input",
    ]
    return "\n".join(lines)


def subparser(name: str, description: str = "") -> argparse.ArgumentParser:
    """A command's parser: its prog, description, exit codes and ``--version``."""
    text, codes = COMMANDS[name]
    p = argparse.ArgumentParser(
        prog=f"reach-run {name}",
        description=description or text,
        epilog=f"exit codes: {codes}",
    )
    add_version(p)
    return p


def _daemon_parser(name: str) -> argparse.ArgumentParser:
    p = subparser(name)
    if name == "attach":
        p.add_argument("job", type=int, nargs="?", help="the job (default: the current one)")
    if name == "cancel":
        p.add_argument("job", type=int, help="the job")
    if name in ("status", "queue"):
        p.add_argument("--json", action="store_true", help="the daemon's reply as JSON")
    if name == "status":
        p.add_argument("--all", action="store_true",
                       help="every latest reading, not the summary")
    p.add_argument("--site", type=Path,
                   help="site file (default: $REACH_SITE, else /etc/reach/site.yaml)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """``reach-run``: dispatch a command word, a schedule path, or the older flags."""
    words = list(sys.argv[1:] if argv is None else argv)
    if not words:
        print(usage(), file=sys.stderr)
        return 2
    first = words[0]
    if first in ("-h", "--help"):
        print(usage())
        return 0
    if first == "--version":
        print(f"reach-run {version()}")
        return 0
    command = COMMANDS_RUN.get(first)
    if command is not None:
        return command(words[1:])
    if first.startswith("-") or _is_path(first):
        return _legacy(words)
    close = difflib.get_close_matches(first, list(COMMANDS), n=1, cutoff=0.5)
    hint = f"; did you mean {close[0]!r}?" if close else "; see reach-run --help"
    print(f"reach-run: unknown command {first!r}{hint}", file=sys.stderr)
    return 2


def _is_path(word: str) -> bool:
    """A schedule is a YAML file: a word with a slash or a YAML suffix, or a file."""
    return "/" in word or word.endswith((".yaml", ".yml")) or Path(word).is_file()


def _legacy(words: list[str]) -> int:
    """The flags before the command words (``--status``, ``--attach``, ``--validate``...)."""
    from .run import run_main

    return run_main(words)


def _run(words: list[str]) -> int:
    from .run import parser, run_main

    if any(w in ("-h", "--help") for w in words):
        p = parser()
        p.prog, p.epilog = "reach-run run", f"exit codes: {COMMANDS['run'][1]}"
        p.print_help()
        return 0
    return run_main(words)


def _check(words: list[str]) -> int:
    p = subparser("check")
    p.add_argument("schedule", type=Path, help="the schedule, e.g. schedules/observe.yaml")
    target = p.add_mutually_exclusive_group()
    target.add_argument("--site", type=Path, help="site file ($REACH_SITE, /etc/reach/site.yaml)")
    target.add_argument("--sim", action="store_true", help="against the simulated receiver")
    p.add_argument("--dry-run", action="store_true", help="print the step list and its timing")
    p.add_argument("--json", action="store_true", help="the checked schedule as JSON")
    args = p.parse_args(words)
    forwarded = ["--dry-run" if args.dry_run else "--validate", str(args.schedule)]
    forwarded += ["--sim"] if args.sim else (["--site", str(args.site)] if args.site else [])
    forwarded += ["--json"] if args.json else []
    from .run import run_main

    return run_main(forwarded)


def _daemon(name: str, words: list[str]) -> int:
    args = _daemon_parser(name).parse_args(words)
    from .steer import steer

    return steer(name, args)


def _metrics(words: list[str]) -> int:
    from .health import metrics_main

    return metrics_main(words)


def _recover(words: list[str]) -> int:
    p = subparser("recover", "Merge the parts a killed run left in its directory into run.h5, "
                  "its status 'interrupted'. Only for a run whose writer is gone: never while "
                  "reach-run or reachd still writes it.")
    p.add_argument("run", type=Path, help="the run's directory, e.g. runs/20260301T120000Z-x")
    p.add_argument("--json", action="store_true", help="the result as JSON")
    args = p.parse_args(words)
    from .recover import recover

    return recover(args.run, args.json)


def _completion(words: list[str]) -> int:
    p = subparser("completion")
    p.add_argument("shell", choices=["bash"], help="the shell")
    p.parse_args(words)
    from .completion import bash_script

    print(bash_script(COMMANDS))
    return 0


def _daemon_command(name: str) -> Callable[[list[str]], int]:
    return lambda words: _daemon(name, words)


COMMANDS_RUN: dict[str, Callable[[list[str]], int]] = {
    "run": _run,
    "check": _check,
    **{name: _daemon_command(name) for name in DAEMON},
    "metrics": _metrics,
    "recover": _recover,
    "completion": _completion,
}


def dumps(value: object) -> str:
    """JSON as every ``--json`` prints it."""
    return json.dumps(value, indent=1, sort_keys=True, default=str)
