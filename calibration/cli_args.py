"""What the ``reach-cal`` commands share: argument types, the solver options, registration.

:mod:`calibration.cli` and the modules of its other commands (:mod:`calibration.cli_import`,
:mod:`calibration.cli_validate`) build their parsers from these, so that ``solve`` and
``validate`` read ``--method``, ``--orders`` and ``--max-orders`` the same way.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .data import CalibrationData
from .errors import InvalidDataError
from .model_fit import OrderChoice
from .noise_waves import PARAMETERS
from .polynomial_model import Orders
from .solvers import METHODS, AnySolution, solver

__all__ = [
    "ORDER_NAMES",
    "add_command",
    "add_solver_options",
    "names_arg",
    "orders_arg",
    "output_arg",
    "solver_from_args",
]

ORDER_NAMES = ", ".join(PARAMETERS)
Command = Callable[[argparse.Namespace], int]


def orders_arg(text: str) -> Orders:
    """Parse ``n_unc,n_cos,n_sin,n_NS,n_L`` (argparse type)."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != len(PARAMETERS) or min(values) < 0:
        raise argparse.ArgumentTypeError(
            f"expected {len(PARAMETERS)} comma-separated term counts >= 0 ({ORDER_NAMES}), "
            f"got {text!r}"
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
