"""What the ``reach-cal`` commands share: argument types, the solver options, registration.

:mod:`calibration.cli` and the modules of its other commands (:mod:`calibration.cli_import`,
:mod:`calibration.cli_validate`) build their parsers from these, so that ``solve`` and
``validate`` read ``--method``, ``--orders`` and ``--max-orders`` the same way.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from .data import CalibrationData
from .errors import InvalidDataError
from .model_fit import OrderChoice
from .noise_waves import PARAMETERS
from .polynomial_model import Orders
from .solvers import METHODS, AnySolution, solver

__all__ = [
    "MAX_ORDER",
    "ORDER_NAMES",
    "add_command",
    "add_solver_options",
    "names_arg",
    "number_arg",
    "orders_arg",
    "output_arg",
    "solver_from_args",
]

ORDER_NAMES = ", ".join(PARAMETERS)
#: The most terms one parameter's polynomial may have: the order search's own ceiling,
#: beyond which its Legendre terms only fit noise (and the normal equations grow as n^2).
MAX_ORDER = OrderChoice.ceiling
Command = Callable[[argparse.Namespace], int]
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
    if len(values) != len(PARAMETERS) or not all(0 <= v <= MAX_ORDER for v in values):
        raise argparse.ArgumentTypeError(
            f"expected {len(PARAMETERS)} comma-separated term counts 0-{MAX_ORDER} "
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


def add_command(sub: Any, name: str, func: Command, **kwargs: Any) -> argparse.ArgumentParser:
    """A subcommand whose help is the first line of ``func``'s docstring, which runs it."""
    doc = func.__doc__ or ""
    parser: argparse.ArgumentParser = sub.add_parser(
        name, help=doc.split("\n")[0], description=doc, **kwargs
    )
    parser.set_defaults(func=func)
    return parser


def add_solver_options(parser: argparse.ArgumentParser) -> None:
    """``--method``, ``--basis``, ``--orders`` | ``--max-orders``, ``--calibrators``."""
    parser.add_argument(
        "--method",
        choices=METHODS,
        default="radiometric",
        help="noise-wave solver (calibration.solvers): polynomial radiometric (default) or "
        "thesis, or per channel least-squares (thesis 4.7) or bayesian (4.8), which need "
        ">= 5 calibrators",
    )
    parser.add_argument(
        "--basis",
        choices=("legendre", "power"),
        help="polynomial basis of the polynomial solvers (default legendre)",
    )
    orders = parser.add_mutually_exclusive_group()
    orders.add_argument("--orders", type=orders_arg, help=f"fixed orders ({ORDER_NAMES})")
    orders.add_argument(
        "--max-orders", type=orders_arg, help="upper limits of the evidence search (default 8 each)"
    )
    parser.add_argument("--calibrators", type=names_arg, help="use only these calibrators")


def solver_from_args(args: argparse.Namespace) -> Callable[[CalibrationData], AnySolution]:
    """The solve that :func:`add_solver_options`'s options ask for (without the subset).

    Orders, order limits or a basis with a per-channel ``--method`` are refused
    (:func:`calibration.solvers.solver`).
    """
    choice = None
    if args.orders is not None:
        choice = OrderChoice.fixed(args.orders)
    elif args.max_orders is not None:
        if min(args.max_orders) < 1:
            raise InvalidDataError("--max-orders must be >= 1 for every parameter")
        choice = OrderChoice(max_orders=args.max_orders)
    return solver(args.method, choice, args.basis)
