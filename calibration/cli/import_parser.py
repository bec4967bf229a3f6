"""``reach-cal import``'s parser: ``import edges`` and ``import vna`` and their options.

Light (argparse only), like every ``reach-cal`` parser; the commands are in
:mod:`calibration.cli.import_commands`. Defaults that the engine's importer holds
(:class:`calibration.io.edges_import.EdgesLayout`) are left ``None`` here and filled in there.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any, TypeVar

from ..core.constants import CELSIUS_SLIP_K
from ..rf.kit_format import KIT_FORMAT
from .args import add_command, band_arg, names_arg, number_arg, output_arg, positive_float

__all__ = ["add_import_command"]

#: The short-open-load standards (:data:`calibration.rf.cal_kit.STANDARD_NAMES`).
STANDARD_NAMES = ("short", "open", "load")
#: ``--integration-s``'s default: fastspec's accumulation, 2^31 samples at 400 MSPS
#: (:data:`calibration.io.edges_text.INTEGRATION_PER_POSITION_S`).
INTEGRATION_PER_POSITION_S = 2.0**31 / 400e6
#: ``--receiver-cable``'s fields (:class:`calibration.io.receiver_path.ReceiverCable`).
RECEIVER_CABLE_FIELDS = ("length_m", "eps_pct", "sigma_pct")
#: ``--hot-cable``'s fields (:data:`calibration.io.edges_text.UT141C`), SI units.
HOT_CABLE_FIELDS = "a, b (radii, m), eps_r, sigma_in, sigma_out (S/m), tan_d, length (m)"
DEFAULT_BAND = (50.0, 190.0)

EDGES_EPILOG = f"""the receiver's path: with --vna, a receiver with standards of its own (as
EDGES-3's *_lna_S/O/L.s1p) is read at another plane than the loads; its reading
is moved to theirs by eq. (4.7), G = S22 + S12 S21 G_read / (1 - S11 G_read):
  --receiver-cable edges3   EDGES' corrcsv line for EDGES-3: 4.26 in of
                            UT-141C-SP, permittivity -1.24 %, conductivity
                            -91.5 %
  --receiver-cable length_m=0.1082,eps_pct=-1.24,sigma_pct=-91.5
                            the same by its fields: length in m (> 0 adds
                            the line, < 0 removes it), percent changes of
                            UT-141C-SP's permittivity and conductivity
  --receiver-path P.s2p     a measured two-port, port 1 at the receiver's
                            standards, port 2 at the loads' (50 ohm)
  --receiver-path none      the planes coincide

EDGES-3, day 2022-316 with the raw readings of 2022-319 (kit.json as below):
  reach-cal import edges edges3-2022-316 -o run.h5 --hot-cable ut141c \\
    --temperatures amb=306.5,hot=393.22,open=306.5,short=306.5 \\
    --vna edges3-2022-319-vna --kit kit.json --device '2022_319_14_{{name}}.s1p' \\
    --standards short=2022_319_14_S.s1p,open=2022_319_14_O.s1p,\\
load=2022_319_14_L.s1p --standards-for lna:short=2022_319_14_lna_S.s1p,\\
open=2022_319_14_lna_O.s1p,load=2022_319_14_lna_L.s1p --receiver-cable edges3

{KIT_FORMAT}"""

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


def _band(text: str) -> tuple[float, float]:
    """``LO,HI`` in MHz, as ``solve --band`` takes it (argparse type)."""
    if "," not in text:
        raise argparse.ArgumentTypeError(
            f"expected LO,HI in MHz, one argument as solve takes it (--band 50,190), got {text!r}"
        )
    return band_arg(text)


def _receiver_cable(text: str) -> dict[str, float]:
    """``edges3`` (``{}``) or ``length_m=...[,eps_pct=...][,sigma_pct=...]`` (argparse type)."""
    if text.strip().lower() == "edges3":
        return {}
    fields = _assignments(number_arg(float, -math.inf), "finite number")(text)
    unknown = sorted(set(fields) - set(RECEIVER_CABLE_FIELDS))
    if unknown or "length_m" not in fields:
        raise argparse.ArgumentTypeError(
            f"expected edges3 or length_m=M[,eps_pct=P][,sigma_pct=P], got {text!r}"
        )
    return fields


def _cable(text: str) -> dict[str, float]:
    """``ut141c`` (``{}``) or ``KEY=VALUE,...`` changing the UT-141C's fields (argparse type).

    The fields' names are checked by the command (:mod:`.import_commands`).
    """
    if text.strip().lower() == "ut141c":
        return {}
    return _assignments(number_arg(float, -math.inf), "finite number")(text)


def _add_vna_options(parser: argparse.ArgumentParser) -> None:
    vna = parser.add_argument_group("raw VNA readings")
    vna.add_argument(
        "--kit", metavar="KIT.json",
        help="the standards' model, JSON (format below; default: ideal short -1, open +1, load 0)",
    )
    vna.add_argument(
        "--device", default="{name}.s1p",
        help="pattern of a device's raw file, {name} the device (default: %(default)s)",
    )
    vna.add_argument(
        "--standards",
        type=_standards,
        default={s: f"cal_{s}.s1p" for s in STANDARD_NAMES},
        metavar="short=P,open=P,load=P",
        help="patterns of the standards' raw files "
        "(default: short=cal_short.s1p,open=cal_open.s1p,load=cal_load.s1p)",
    )
    vna.add_argument(
        "--standards-for",
        type=_standards_for,
        action="append",
        metavar="NAME:short=P,open=P,load=P",
        help="a device's own standards (repeatable; default: none)",
    )


def _add_edges_options(edges: argparse.ArgumentParser) -> None:
    edges.add_argument("directory", help="the run's directory")
    edges.add_argument("-o", "--output", type=output_arg, required=True, help="run file (HDF5)")
    edges.add_argument(
        "--temperatures",
        type=_assignments(positive_float, "kelvin (> 0)"),
        required=True,
        metavar="NAME=K,...",
        help="physical temperature of every load, K (no default): amb=306.5,hot=393.22,...",
    )
    edges.add_argument(
        "--cryogenic", action="store_true",
        help=f"accept loads below {CELSIUS_SLIP_K:g} K (default: refused as a likely Celsius slip)",
    )
    files = edges.add_argument_group("files (patterns: {name} and shell wildcards, one match)")
    files.add_argument(
        "--loads", type=names_arg, metavar="A,B,...",
        help="the loads (default: amb,hot,open,short)",
    )
    files.add_argument("--receiver", help="the receiver's S11 name (default: lna)")
    files.add_argument("--spectrum", help="spectrum pattern (default: sp{name}.txt)")
    files.add_argument("--s11-export", help="S11 CSV pattern (default: s11{name}.csv)")
    files.add_argument("--s11-modelled", help="modelled S11 file (default: s11_modelled.txt)")
    files.add_argument(
        "--modelled-columns", type=names_arg, metavar="A,B,...",
        help="the modelled file's columns (default: amb,hot,open,short,lna)",
    )
    files.add_argument(
        "--s11", choices=("modelled", "raw"), default="modelled",
        help="the pipeline's modelled S11s, or splines through the CSV exports "
        "(default: %(default)s; --vna replaces both)",
    )
    loss = edges.add_argument_group("the hot load's cable (T = G T_hot + (1 - G) T_cable)")
    which = loss.add_mutually_exclusive_group()
    which.add_argument(
        "--hot-loss", metavar="GAIN.txt",
        help="measured power gain G: rows 'freq_MHz gain', read over --band only "
        "(default: no loss)",
    )
    which.add_argument(
        "--hot-cable", type=_cable, metavar="SPEC",
        help="UT-141C-SP cable model: ut141c, or its fields changed, KEY=V,...: "
        f"{HOT_CABLE_FIELDS} (default: no loss)",
    )
    loss.add_argument("--hot-load", default="hot", help="the load behind the cable (default: hot)")
    loss.add_argument(
        "--cable-load", default="amb",
        help="the load at the cable's temperature T_cable (default: amb)",
    )
    edges.add_argument(
        "--band", type=_band, default=DEFAULT_BAND, metavar="LO,HI",
        help="channels kept, MHz, inclusive (default: 50,190)",
    )
    edges.add_argument(
        "--q-variance", choices=("empirical", "radiometer"), default="empirical",
        help="var(Q) from the spectra's own scatter, or the radiometer equation's bound for "
        "a noiseless receiver (default: %(default)s)",
    )
    edges.add_argument(
        "--integration-s",
        type=positive_float,
        default=INTEGRATION_PER_POSITION_S,
        help="accumulation of one Dicke position of one cycle, s (default: %(default).4g, "
        "fastspec's 2^31 samples at 400 MS/s)",
    )
    edges.add_argument(
        "--vna", metavar="VNA_DIR",
        help="directory of raw VNA readings of every load and the receiver, corrected for the "
        "S11s (default: none)",
    )
    _add_vna_options(edges)
    _add_receiver_path_options(edges)


def _add_receiver_path_options(parser: argparse.ArgumentParser) -> None:
    path = parser.add_argument_group("the receiver's path (below)")
    where = path.add_mutually_exclusive_group()
    where.add_argument(
        "--receiver-cable", type=_receiver_cable, metavar="SPEC",
        help="a UT-141C-SP line between the receiver's reading and the loads' plane: edges3, "
        "or length_m=M[,eps_pct=P][,sigma_pct=P] (m, percent; default: none)",
    )
    where.add_argument(
        "--receiver-path", metavar="FILE",
        help="a measured two-port between them (.s2p), or none: the planes coincide (default: none "
        "unless the receiver has its own standards, which is refused)",
    )


def add_import_command(sub: Any) -> None:
    """Register ``import edges`` and ``import vna`` on the ``reach-cal`` subparsers ``sub``."""
    doc = "Import laboratory data: an EDGES text run, or raw VNA exports with their standards."
    parent = sub.add_parser("import", help=doc, description=doc)
    kinds = parent.add_subparsers(dest="kind", required=True, metavar="KIND")
    _add_edges_options(add_command(
        kinds, "edges", ".import_commands:cmd_import_edges",
        "Import an EDGES text run (spectra, S11s, temperatures) into a run file (HDF5).",
        epilog=EDGES_EPILOG,
    ))
    vna = add_command(
        kinds, "vna", ".import_commands:cmd_import_vna",
        "Correct raw VNA readings with their standards; write each S11 as Touchstone.",
        epilog=f"the receiver's path: as for import edges (see its --help)\n\n{KIT_FORMAT}",
    )
    vna.add_argument("directory", help="directory of the raw exports")
    vna.add_argument("-o", "--output", type=output_arg, required=True, help="directory to write")
    vna.add_argument(
        "--devices", type=names_arg, required=True, metavar="A,B,...", help="devices to correct"
    )
    _add_vna_options(vna)
    vna.add_argument(
        "--receiver", metavar="NAME",
        help="the device moved to the loads' plane by the receiver's path (default: none)",
    )
    _add_receiver_path_options(vna)
