"""What the ``reach-cal`` parsers share: argument types, option groups, registration.

Every command's parser is built from these, so that ``solve`` and ``validate`` read
``--method``, ``--orders`` and ``--max-orders`` the same way, and every band is ``LO,HI``
in MHz. This module imports only :mod:`argparse` and :mod:`calibration.core.constants`: a
parser is built (and ``--help`` printed) before any of the engine is imported; a
command's module is imported by name when it runs (:func:`add_command`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from ..core.constants import (
    CELSIUS_SLIP_K,
    DEFAULT_ALPHA,
    METHODS,
    ORDER_CEILING,
    PARAMETER_NAMES,
)

__all__ = [
    "MAX_ORDER",
    "ORDER_NAMES",
    "add_command",
    "add_correction_options",
    "add_solver_options",
    "alpha_arg",
    "band_arg",
    "joined_band",
    "names_arg",
    "number_arg",
    "orders_arg",
    "output_arg",
]

ORDER_NAMES = ", ".join(PARAMETER_NAMES)
#: The most terms one parameter's polynomial may have: the order search's own ceiling,
#: beyond which its Legendre terms only fit noise (and the normal equations grow as n^2).
MAX_ORDER = ORDER_CEILING
#: The automatic order box: its start and its step (``calibration.choice.model_fit.OrderChoice``;
#: held equal by a test, since this module must not import the engine).
AUTO_BOX_START, AUTO_BOX_STEP = 8, 4
Orders = tuple[int, int, int, int, int]
N = TypeVar("N", int, float)


def number_arg(
    kind: Callable[[str], N], low: float, high: float = math.inf, *, open_low: bool = False
) -> Callable[[str], N]:
    """An argparse type: a finite ``kind`` (``int`` or ``float``) in ``[low, high]``.

    ``open_low`` excludes ``low`` itself (``number_arg(float, 0, open_low=True)``: > 0).
    Every numeric option of ``reach-cal`` is read through one of these, so that a
    negative width, a NaN or a count of zero is refused before any work, by name.
    """
    span = f"> {low:g}" if open_low else f">= {low:g}"
    if high < math.inf:
        span += f" and <= {high:g}"
    if low == -math.inf:
        span = "(finite)" if high == math.inf else f"<= {high:g}"
    what = "an integer" if kind is int else "a number"

    def parse(text: str) -> N:
        try:
            value = kind(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"expected {what} {span}, got {text!r}") from None
        inside = (value > low if open_low else value >= low) and value <= high
        if not (math.isfinite(value) and inside):
            raise argparse.ArgumentTypeError(f"expected {what} {span}, got {text!r}")
        return value

    parse.__name__ = f"{what} {span}"
    return parse


#: The commonest kinds: a count >= 0, a count >= 1, a quantity > 0.
count_arg = number_arg(int, 0)
positive_int = number_arg(int, 1)
positive_float = number_arg(float, 0.0, open_low=True)


def orders_arg(text: str) -> Orders:
    """Parse ``n_unc,n_cos,n_sin,n_NS,n_L``, each 0..:data:`MAX_ORDER` (argparse type)."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != len(PARAMETER_NAMES) or not all(0 <= v <= MAX_ORDER for v in values):
        raise argparse.ArgumentTypeError(
            f"expected {len(PARAMETER_NAMES)} comma-separated term counts 0-{MAX_ORDER} "
            f"({ORDER_NAMES}; {MAX_ORDER} is the order search's ceiling), got {text!r}"
        )
    return values  # type: ignore[return-value]


def names_arg(text: str) -> tuple[str, ...]:
    """Parse a comma-separated list of source names (argparse type)."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError("expected comma-separated source names")
    return names


def output_arg(text: str) -> str:
    """An output path whose directory exists (argparse type): fail before the work."""
    parent = Path(text).parent
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"directory {str(parent)!r} does not exist")
    return text


def add_command(
    sub: Any, name: str, target: str, doc: str, **kwargs: Any
) -> argparse.ArgumentParser:
    """A subcommand described by ``doc`` (its first line is the help) that runs ``target``.

    ``target`` is ``"module:function"``, the module relative to :mod:`calibration.cli`;
    :func:`calibration.cli.main.main` imports it only when the command runs.
    """
    parser: argparse.ArgumentParser = sub.add_parser(
        name, help=doc.split("\n")[0], description=doc,
        formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs,
    )
    parser.set_defaults(target=target)
    return parser


def band_arg(text: str) -> tuple[float, float]:
    """Parse ``LO,HI`` in MHz with ``0 < LO < HI`` (argparse type).

    Every command's band is this one word; ``simulate``'s older ``--band LO HI`` is
    joined into it before parsing (:func:`joined_band`).
    """
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO,HI in MHz, got {text!r}") from None
    if not (0 <= lo < hi and math.isfinite(hi)):
        raise argparse.ArgumentTypeError(f"expected finite 0 <= LO < HI (MHz), got {text!r}")
    return lo, hi


def joined_band(argv: list[str]) -> list[str]:
    """``argv`` with an older two-word ``--band LO HI`` joined into ``--band LO,HI``."""
    out = list(argv)
    for i, word in enumerate(out[:-2]):
        if word == "--band" and "," not in out[i + 1]:
            try:
                float(out[i + 1]), float(out[i + 2])
            except ValueError:
                continue
            out[i + 1 : i + 3] = [f"{out[i + 1]},{out[i + 2]}"]
            break
    return out


def alpha_arg(text: str) -> float:
    """A false-alarm rate in (0, 1) (argparse type)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a rate in (0, 1), got {text!r}")
    return value


def add_correction_options(parser: argparse.ArgumentParser) -> None:
    """Register the preparation and consistency options (module doc) on ``parser``."""
    group = parser.add_argument_group("data preparation and calibrator consistency")
    group.add_argument(
        "--band", type=band_arg, metavar="LO,HI",
        help="solve in LO-HI MHz (default: every channel of the run)",
    )
    group.add_argument(
        "--mask-band",
        type=band_arg,
        action="append",
        default=[],
        metavar="LO,HI",
        help="drop the channels in LO-HI MHz (repeatable; default: none)",
    )
    group.add_argument(
        "--rfi",
        action="store_true",
        help="drop channels with spikes in a calibrator's load or noise-source spectrum "
        "(default: off)",
    )
    group.add_argument(
        "--smooth-s11",
        type=number_arg(float, 0.0, 1.0, open_low=True),
        metavar="P",
        help="smooth every reflection with a spline of factor P in (0, 1] (default: no "
        "smoothing, as 1)",
    )
    consistency = group.add_mutually_exclusive_group()
    consistency.add_argument(
        "--check-consistency",
        action="store_true",
        help="test each calibrator held out against the others and report (default: off)",
    )
    consistency.add_argument(
        "--exclude-inconsistent",
        type=positive_int,
        nargs="?",
        const=2,
        metavar="N",
        help="also exclude the calibrator that disagrees, at most N times (default 2)",
    )
    group.add_argument(
        "--alpha",
        type=alpha_arg,
        default=DEFAULT_ALPHA,
        help=f"false-alarm rate of a consistency round (default {DEFAULT_ALPHA})",
    )


def add_solver_options(parser: argparse.ArgumentParser) -> None:
    """``--method``, ``--basis``, ``--orders`` | ``--max-orders``, ``--calibrators``."""
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="radiometric",
        help="noise-wave solver (calibration.solve.solvers): polynomial radiometric (default) or "
        "thesis, or per channel least-squares (thesis 4.7) or bayesian (4.8), which need "
        ">= 5 calibrators",
    )
    parser.add_argument(
        "--basis",
        choices=("legendre", "power"),
        help="polynomial basis of the polynomial solvers (default: legendre)",
    )
    orders = parser.add_mutually_exclusive_group()
    orders.add_argument(
        "--orders", type=orders_arg, metavar="N,N,N,N,N",
        help=f"fixed numbers of polynomial terms ({ORDER_NAMES}), each 0-{MAX_ORDER} "
        "(default: chosen by the evidence search)",
    )
    orders.add_argument(
        "--max-orders", type=orders_arg, metavar="N,N,N,N,N",
        help=f"hard upper limits of the evidence search ({ORDER_NAMES}), each 1-{MAX_ORDER}; "
        f"the search never goes beyond them, a value above {MAX_ORDER} is refused "
        f"(default: none; the box starts at {AUTO_BOX_START} terms each and a parameter "
        f"whose best model reaches its edge is raised by {AUTO_BOX_STEP}, up to {MAX_ORDER})",
    )
    parser.add_argument(
        "--calibrators", type=names_arg, metavar="A,B,...",
        help="use only these calibrators of the run (default: all of them)",
    )
    parser.add_argument(
        "--cryogenic", action="store_true",
        help=f"accept calibrators below {CELSIUS_SLIP_K:g} K (default: refused as a likely "
        "Celsius slip: 22.85 C is 296 K)",
    )
