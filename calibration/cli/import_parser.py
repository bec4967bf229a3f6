"""``reach-cal import``'s parser: ``import edges`` and ``import vna`` and their options.

Light (argparse only), like every ``reach-cal`` parser; the commands are in
:mod:`calibration.cli.import_commands`. Defaults that the engine's importer holds
(:class:`calibration.edges_import.EdgesLayout`) are left ``None`` here and filled in there.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any, TypeVar

from .args import add_command, names_arg, number_arg, output_arg, positive_float

__all__ = ["add_import_command"]

#: The short-open-load standards (:data:`calibration.cal_kit.STANDARD_NAMES`).
STANDARD_NAMES = ("short", "open", "load")
#: ``--integration-s``'s default: fastspec's accumulation, 2^31 samples at 400 MSPS
#: (:data:`calibration.edges_text.INTEGRATION_PER_POSITION_S`).
INTEGRATION_PER_POSITION_S = 2.0**31 / 400e6

T = TypeVar("T")


def _assignments(convert: Callable[[str], T], what: str) -> Callable[[str], dict[str, T]]:
    """An argparse type for ``key=value,key=value`` with values converted by ``convert``."""

    def parse(text: str) -> dict[str, T]:
        out: dict[str, T] = {}
        for item in (i.strip() for i in text.split(",") if i.strip()):
            key, sep, value = item.partition("=")
            try:
                if not (sep and key.strip()):
                    raise ValueError
                out[key.strip()] = convert(value.strip())
            except (ValueError, argparse.ArgumentTypeError):
                raise argparse.ArgumentTypeError(
                    f"expected KEY=VALUE,... with {what} values, got {item!r}"
                ) from None
        if not out:
            raise argparse.ArgumentTypeError(f"expected KEY=VALUE,... with {what} values")
        return out

    parse.__name__ = f"{what} assignments"
    return parse


def _standards(text: str) -> dict[str, str]:
    """``short=P,open=P,load=P`` (argparse type): a pattern for each standard."""
    patterns = _assignments(str, "file-pattern")(text)
    if set(patterns) != set(STANDARD_NAMES):
        raise argparse.ArgumentTypeError(f"expected {'=P,'.join(STANDARD_NAMES)}=P, got {text!r}")
    return patterns


def _standards_for(text: str) -> tuple[str, dict[str, str]]:
    """``NAME:short=P,open=P,load=P`` (argparse type): one device's own standards."""
    name, sep, rest = text.partition(":")
    if not (sep and name.strip()):
        raise argparse.ArgumentTypeError(f"expected NAME:short=P,open=P,load=P, got {text!r}")
    return name.strip(), _standards(rest)


def _cable(text: str) -> dict[str, float]:
    """``ut141c`` (``{}``) or ``KEY=VALUE,...`` changing the UT-141C's fields (argparse type).

    The fields' names are checked by the command (:mod:`.import_commands`).
    """
    if text.strip().lower() == "ut141c":
        return {}
    return _assignments(number_arg(float, -math.inf), "finite number")(text)


def _add_vna_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--kit", help="calibration kit (JSON); default ideal short/open/load")
    parser.add_argument(
        "--device", default="{name}.s1p", help="pattern of a device's raw file ({name}.s1p)"
    )
    parser.add_argument(
        "--standards",
        type=_standards,
        default={s: f"cal_{s}.s1p" for s in STANDARD_NAMES},
        help="patterns of the standards' raw files (short=cal_short.s1p,open=...,load=...)",
    )
    parser.add_argument(
        "--standards-for",
        type=_standards_for,
        action="append",
        metavar="NAME:short=P,open=P,load=P",
        help="a device's own standards (repeatable)",
    )


def _add_edges_options(edges: argparse.ArgumentParser) -> None:
    edges.add_argument("directory", help="the run's directory")
    edges.add_argument("-o", "--output", type=output_arg, required=True, help="run file (HDF5)")
    edges.add_argument(
        "--temperatures",
        type=_assignments(positive_float, "kelvin (> 0)"),
        required=True,
        help="physical temperature of every load, K: amb=306.5,hot=393.22,...",
    )
    edges.add_argument("--loads", type=names_arg, help="the loads (default amb,hot,open,short)")
    edges.add_argument("--receiver", help="the receiver's S11 name (default lna)")
    edges.add_argument("--spectrum", help="spectrum pattern (default sp{name}.txt)")
    edges.add_argument("--s11-export", help="S11 CSV pattern (default s11{name}.csv)")
    edges.add_argument("--s11-modelled", help="modelled S11 file (default s11_modelled.txt)")
    edges.add_argument(
        "--modelled-columns", type=names_arg, help="the modelled file's columns (amb,...,lna)"
    )
    edges.add_argument("--s11", choices=("modelled", "raw"), default="modelled")
    loss = edges.add_mutually_exclusive_group()
    loss.add_argument("--hot-loss", help="measured power gain of the hot load's cable")
    loss.add_argument(
        "--hot-cable", type=_cable, help="cable model: ut141c, or changes KEY=VALUE,..."
    )
    edges.add_argument("--hot-load", default="hot", help="the load behind the cable")
    edges.add_argument("--cable-load", default="amb", help="the load at the cable's temperature")
    edges.add_argument(
        "--band", type=positive_float, nargs=2, default=(50.0, 190.0), metavar=("LO", "HI")
    )
    edges.add_argument("--q-variance", choices=("empirical", "radiometer"), default="empirical")
    edges.add_argument(
        "--integration-s",
        type=positive_float,
        default=INTEGRATION_PER_POSITION_S,
        help="accumulation of one Dicke position of one cycle, s",
    )
    edges.add_argument("--vna", help="directory of raw VNA exports to correct for the S11s")
    _add_vna_options(edges)


def add_import_command(sub: Any) -> None:
    """Register ``import edges`` and ``import vna`` on the ``reach-cal`` subparsers ``sub``."""
    doc = "Import laboratory data: an EDGES text run, or raw VNA exports with their standards."
    parent = sub.add_parser("import", help=doc, description=doc)
    kinds = parent.add_subparsers(dest="kind", required=True, metavar="KIND")
    _add_edges_options(add_command(
        kinds, "edges", ".import_commands:cmd_import_edges",
        "Import an EDGES text run (spectra, S11s, temperatures) into a run file (HDF5).",
    ))
    vna = add_command(
        kinds, "vna", ".import_commands:cmd_import_vna",
        "Correct raw VNA exports with their standards; write each device's S11 as Touchstone.",
    )
    vna.add_argument("directory", help="directory of the raw exports")
    vna.add_argument("-o", "--output", type=output_arg, required=True, help="directory to write")
    vna.add_argument("--devices", type=names_arg, required=True, help="devices to correct")
    _add_vna_options(vna)
