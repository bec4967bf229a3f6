"""``reach-cal import``: laboratory data into the engine's run file (or corrected S11s).

::

    reach-cal import edges DIR -o RUN.h5 --temperatures amb=K,hot=K,open=K,short=K
                     [--loads amb,hot,open,short] [--receiver lna]
                     [--spectrum 'sp{name}.txt'] [--s11-export 's11{name}.csv']
                     [--s11-modelled s11_modelled.txt] [--s11 modelled|raw]
                     [--hot-loss GAIN.txt | --hot-cable ut141c|KEY=V,...]
                     [--hot-load hot] [--cable-load amb] [--band LO HI]
                     [--q-variance empirical|radiometer] [--integration-s S]
                     [--vna VNA_DIR [VNA options]]
    reach-cal import vna VNA_DIR -o OUT_DIR --devices a,b,... [VNA options]

    VNA options: [--kit KIT.json] [--device '{name}.s1p']
                 [--standards short=P,open=P,load=P] [--standards-for NAME:short=P,...]

``import edges`` reads an EDGES text run (:mod:`calibration.edges_import`) and writes it with
:func:`calibration.hdf5_io.write_run`, so ``solve``, ``apply``, ``summary`` and ``validate``
read it. With ``--vna`` its S11s are the raw VNA exports of every load and the receiver,
corrected with their standards (:mod:`calibration.vna_import`). ``import vna`` writes those
corrected reflections as ``OUT_DIR/{name}.s1p``. Patterns take ``{name}`` and shell
wildcards, relative to the directory read; each must match one file. Bad input is
reported as ``file:line: message`` (or ``file: message``), exit status 2.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from .cal_kit import IDEAL_KIT, STANDARD_NAMES, CalKit
from .cli_args import add_command, names_arg, number_arg, output_arg, positive_float
from .cli_files import check_outputs, same_file
from .edges_import import (
    CableLoss,
    EdgesImport,
    EdgesLayout,
    MeasuredLoss,
    find_file,
    import_edges,
    read_gain_table,
)
from .edges_text import UT141C
from .errors import InvalidDataError
from .hdf5_io import write_run
from .touchstone import write_touchstone
from .vna_import import VnaLayout, correct_exports, read_cal_kit

__all__ = ["add_import_command", "cmd_import_edges", "cmd_import_vna"]

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


def _cable(text: str) -> CableLoss:
    """``ut141c`` or ``KEY=VALUE,...`` changing its fields (argparse type)."""
    if text.strip().lower() == "ut141c":
        return CableLoss(dict(UT141C))
    changes = _assignments(number_arg(float, -math.inf), "finite number")(text)
    unknown = sorted(set(changes) - set(UT141C))
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown cable fields {', '.join(unknown)} (known: {', '.join(UT141C)})"
        )
    return CableLoss({**UT141C, **changes})


def _vna_layout(args: argparse.Namespace) -> VnaLayout:
    return VnaLayout(
        device=args.device,
        standards=args.standards,
        per_device=dict(args.standards_for or []),
    )


def _kit(args: argparse.Namespace) -> CalKit:
    return read_cal_kit(args.kit) if args.kit else IDEAL_KIT


def cmd_import_edges(args: argparse.Namespace) -> int:
    """Import an EDGES text run (spectra, S11s, temperatures) into a run file (HDF5)."""
    inputs = [args.directory, args.hot_loss, args.vna, args.kit]
    check_outputs({"-o": (args.output, "run")}, inputs, remakes=str(args.directory))
    if not args.band[0] < args.band[1]:
        raise InvalidDataError(f"--band needs LO < HI (MHz), got {args.band[0]:g} {args.band[1]:g}")
    layout = EdgesLayout(
        loads=args.loads,
        receiver=args.receiver,
        spectrum=args.spectrum,
        s11_export=args.s11_export,
        s11_modelled=args.s11_modelled,
        modelled_columns=args.modelled_columns or EdgesLayout.modelled_columns,
    )
    loss: MeasuredLoss | CableLoss | None = args.hot_cable
    if args.hot_loss:
        loss = read_gain_table(args.hot_loss)
    spec = EdgesImport(
        temperatures_k=args.temperatures,
        layout=layout,
        band_mhz=tuple(args.band),
        s11=args.s11,
        q_variance=args.q_variance,
        hot_loss=loss,
        lossy_load=args.hot_load,
        cable_load=args.cable_load,
        integration_per_position_s=args.integration_s,
    )
    reflections = None
    if args.vna:
        names = (*layout.loads, layout.receiver)
        reflections = correct_exports(args.vna, names, _vna_layout(args), _kit(args))
    data = import_edges(args.directory, spec, reflections)
    write_run(args.output, data, attrs={"imported_from": str(args.directory)})
    gain = np.asarray(data.metadata["hot_load_gain"])
    print(
        f"imported {args.directory}: {', '.join(data.names)}, receiver {layout.receiver!r}, "
        f"{data.n_channels} channels, {data.freq_hz[0] / 1e6:.3f}-{data.freq_hz[-1] / 1e6:.3f} MHz"
    )
    print(f"S11s: {data.metadata['s11'] if not args.vna else f'{args.vna} corrected'}")
    print(
        f"hot-load loss: {data.metadata['hot_load_loss']} "
        f"(power gain {gain.min():.5f}-{gain.max():.5f})"
    )
    print(f"wrote {args.output}")
    return 0


def cmd_import_vna(args: argparse.Namespace) -> int:
    """Correct raw VNA exports with their standards; write each device's S11 as Touchstone."""
    out_dir = Path(args.output)
    check_outputs({"-o": (args.output, "directory")}, [args.directory, args.kit])
    kit = _kit(args)
    layout = _vna_layout(args)
    corrected = correct_exports(args.directory, args.devices, layout, kit)
    read = [
        find_file(Path(args.directory), pattern, name)
        for name in corrected
        for pattern in (layout.device, *layout.standards_of(name))
    ]
    for name in corrected:
        target = out_dir / f"{name}.s1p"
        if any(same_file(target, path) for path in read):
            raise InvalidDataError(
                f"-o {out_dir}: {target} is an export read to correct it: it would be "
                "overwritten; nothing written, choose another directory"
            )
    out_dir.mkdir(exist_ok=True)
    for name, (freq, gamma) in corrected.items():
        note = f"{name}: corrected from {args.directory} with kit {kit.name or 'unnamed'}"
        write_touchstone(out_dir / f"{name}.s1p", freq, gamma, comment=note)
    print(
        f"corrected {len(corrected)} devices from {args.directory} "
        f"(kit {kit.name or 'unnamed'}); wrote {out_dir}/{{{','.join(corrected)}}}.s1p"
    )
    return 0


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
    edges.add_argument("--loads", type=names_arg, default=EdgesLayout.loads)
    edges.add_argument("--receiver", default=EdgesLayout.receiver)
    edges.add_argument("--spectrum", default=EdgesLayout.spectrum, help="spectrum pattern")
    edges.add_argument("--s11-export", default=EdgesLayout.s11_export, help="S11 CSV pattern")
    edges.add_argument("--s11-modelled", default=EdgesLayout.s11_modelled)
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
        default=EdgesImport.integration_per_position_s,
        help="accumulation of one Dicke position of one cycle, s",
    )
    edges.add_argument("--vna", help="directory of raw VNA exports to correct for the S11s")
    _add_vna_options(edges)


def add_import_command(sub: Any) -> None:
    """Register ``import edges`` and ``import vna`` on the ``reach-cal`` subparsers ``sub``."""
    doc = "Import laboratory data: an EDGES text run, or raw VNA exports with their standards."
    parent = sub.add_parser("import", help=doc, description=doc)
    kinds = parent.add_subparsers(dest="kind", required=True, metavar="KIND")
    _add_edges_options(add_command(kinds, "edges", cmd_import_edges))
    vna = add_command(kinds, "vna", cmd_import_vna)
    vna.add_argument("directory", help="directory of the raw exports")
    vna.add_argument("-o", "--output", type=output_arg, required=True, help="directory to write")
    vna.add_argument("--devices", type=names_arg, required=True, help="devices to correct")
    _add_vna_options(vna)
