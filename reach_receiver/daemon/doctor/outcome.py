"""One check's outcome (``ok``, ``warn``, ``fail`` and the evidence) and how the lines print."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

Status = Literal["ok", "warn", "fail"]
STATUSES: tuple[Status, ...] = ("ok", "warn", "fail")


@dataclass(frozen=True)
class Check:
    """The outcome of one check: what was checked, how it went, and the evidence.

    Attributes
    ----------
    name
        What was checked, as the operator knows it (``"teensy"``, ``"disk"``...).
    status
        ``"ok"``; ``"warn"`` (usable, but look at it); ``"fail"`` (do not observe).
    detail
        One line: the address or path from the site file and what was found there.
    """

    name: str
    status: Status
    detail: str

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"check status must be one of {STATUSES}, not {self.status!r}")


def failed(checks: Iterable[Check]) -> bool:
    """Whether any check failed (the command's exit status is non-zero then)."""
    return any(check.status == "fail" for check in checks)


def format_checks(checks: Iterable[Check]) -> str:
    """One aligned line per check: ``  <status> <name> <detail>``, no trailing newline."""
    checks = list(checks)
    width = max((len(check.name) for check in checks), default=0)
    return "\n".join(
        f"  {check.status:<5} {check.name:<{width}} {' '.join(check.detail.splitlines())}"
        for check in checks
    )


__all__ = ["STATUSES", "Check", "Status", "failed", "format_checks"]
