"""``reach-cal import``'s commands: laboratory data into the engine's run file (or corrected S11s).

::

    reach-cal import edges DIR -o RUN.h5 --temperatures amb=K,hot=K,open=K,short=K [--cryogenic]
                     [--loads amb,hot,open,short] [--receiver lna]
                     [--spectrum 'sp{name}.txt'] [--s11-export 's11{name}.csv']
                     [--s11-modelled s11_modelled.txt] [--s11 modelled|raw]
                     [--hot-loss GAIN.txt | --hot-cable ut141c|KEY=V,...]
                     [--hot-load hot] [--cable-load amb] [--band LO,HI]
                     [--q-variance empirical|radiometer] [--integration-s S]
                     [--vna VNA_DIR [VNA options]]
                     [--receiver-cable edges3|length_m=M,... | --receiver-path FILE.s2p|none]
    reach-cal import vna VNA_DIR -o OUT_DIR --devices a,b,... [VNA options]
                     [--receiver NAME --receiver-cable ...|--receiver-path ...]

    VNA options: [--kit KIT.json] [--device '{name}.s1p']
                 [--standards short=P,open=P,load=P] [--standards-for NAME:short=P,...]

``import edges`` reads an EDGES text run (:mod:`calibration.io.edges_import`) and writes it with
:func:`calibration.io.hdf5_io.write_run`, so ``solve``, ``apply``, ``summary`` and ``validate``
read it. With ``--vna`` its S11s are the raw VNA exports of every load and the receiver,
corrected with their standards (:mod:`calibration.io.vna_import`). ``import vna`` writes those
corrected reflections as ``OUT_DIR/{name}.s1p``. A receiver with standards of its own is
read at another plane than the loads: its path to theirs (:mod:`calibration.io.receiver_path`)
must be given, or the planes said to coincide (``--receiver-path none``), else the import is
refused. A load below 150 K is refused as a likely Celsius value unless ``--cryogenic``.
The run file's root attribute ``power_spectra = "placeholder"`` marks its powers as
stand-ins (:mod:`calibration.io.hdf5_io`). Patterns take ``{name}`` and shell wildcards,
relative to the directory read; each must match one file. Bad input is reported as
``file:line: message`` (or ``file: message``), exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..checks.temperature_sanity import celsius_message, celsius_slips
from ..core.errors import InvalidDataError
from ..io.edges_import import (
    CableLoss,
    EdgesImport,
    EdgesLayout,
    MeasuredLoss,
    find_file,
    import_edges,
    read_gain_table,
)
from ..io.edges_text import UT141C
from ..io.hdf5_io import PLACEHOLDER_POWERS, write_run
from ..io.receiver_path import (
    EDGES3_RECEIVER_CABLE,
    ReceiverCable,
    ReceiverPath,
    read_measured_path,
)
from ..io.vna_import import VnaLayout, check_receiver_plane, correct_exports, read_cal_kit
from ..rf.cal_kit import IDEAL_KIT, CalKit
from ..rf.touchstone import write_touchstone
from .files import check_outputs, same_file

__all__ = ["cmd_import_edges", "cmd_import_vna"]

def _cable(changes: dict[str, float]) -> CableLoss:
    """The UT-141C cable model with ``--hot-cable``'s changes to its fields."""
    unknown = sorted(set(changes) - set(UT141C))
    if unknown:
        raise InvalidDataError(
            f"--hot-cable: unknown cable fields {', '.join(unknown)} (known: {', '.join(UT141C)})"
        )
    return CableLoss({**UT141C, **changes})


def _vna_layout(args: argparse.Namespace) -> VnaLayout:
    return VnaLayout(
        device=args.device,
        standards=args.standards,
        per_device=dict(args.standards_for or []),
    )


def _receiver_path(args: argparse.Namespace) -> ReceiverPath | None:
    if args.receiver_cable is not None:
        if not args.receiver_cable:
            return EDGES3_RECEIVER_CABLE
        try:
            return ReceiverCable(**args.receiver_cable)
        except InvalidDataError as err:
            raise InvalidDataError(f"--receiver-cable: {err}") from None
    if args.receiver_path is None or args.receiver_path.strip().lower() == "none":
        return None
    return read_measured_path(args.receiver_path)


def _kit(args: argparse.Namespace) -> CalKit:
    return read_cal_kit(args.kit) if args.kit else IDEAL_KIT


def cmd_import_edges(args: argparse.Namespace) -> int:
    """Import an EDGES text run (spectra, S11s, temperatures) into a run file (HDF5)."""
    path_file = args.receiver_path if (args.receiver_path or "none").lower() != "none" else None
    inputs = [args.directory, args.hot_loss, args.vna, args.kit, path_file]
    check_outputs({"-o": (args.output, "run")}, inputs, remakes=str(args.directory))
    if not args.band[0] < args.band[1]:
        raise InvalidDataError(f"--band needs LO < HI (MHz), got {args.band[0]:g} {args.band[1]:g}")
    slips = celsius_slips(args.temperatures)
    if slips and not args.cryogenic:
        raise InvalidDataError(f"--temperatures: {celsius_message(slips)}")
    given = {
        "loads": args.loads, "receiver": args.receiver, "spectrum": args.spectrum,
        "s11_export": args.s11_export, "s11_modelled": args.s11_modelled,
        "modelled_columns": args.modelled_columns,
    }
    layout = EdgesLayout(**{k: v for k, v in given.items() if v is not None})
    loss: MeasuredLoss | CableLoss | None = None
    if args.hot_cable is not None:
        loss = _cable(args.hot_cable)
    if args.hot_loss:
        loss = read_gain_table(args.hot_loss)
    receiver_path = _receiver_path(args)
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
        receiver_path=receiver_path,
    )
    reflections = None
    if args.vna:
        names = (*layout.loads, layout.receiver)
        vna_layout = _vna_layout(args)
        check_receiver_plane(
            vna_layout, layout.receiver, receiver_path is not None, args.receiver_path is not None
        )
        reflections = correct_exports(args.vna, names, vna_layout, _kit(args))
    data = import_edges(args.directory, spec, reflections)
    # the spectra are T* stand-ins (P_load = 300, P_NS = 1300): no measured powers, no diode
    attrs = {"imported_from": str(args.directory), "power_spectra": PLACEHOLDER_POWERS}
    write_run(args.output, data, attrs=attrs)
    gain = np.asarray(data.metadata["hot_load_gain"])
    print(
        f"imported {args.directory}: {', '.join(data.names)}, receiver {layout.receiver!r}, "
        f"{data.n_channels} channels, {data.freq_hz[0] / 1e6:.3f}-{data.freq_hz[-1] / 1e6:.3f} MHz"
    )
    print(f"S11s: {data.metadata['s11'] if not args.vna else f'{args.vna} corrected'}")
    if receiver_path is not None:
        print(f"receiver {layout.receiver!r} moved to the loads' plane: {receiver_path.describe()}")
    print(
        f"hot-load loss: {data.metadata['hot_load_loss']} "
        f"(power gain {gain.min():.5f}-{gain.max():.5f})"
    )
    print(f"wrote {args.output}")
    return 0


def cmd_import_vna(args: argparse.Namespace) -> int:
    """Correct raw VNA exports with their standards; write each device's S11 as Touchstone."""
    out_dir = Path(args.output)
    path_file = args.receiver_path if (args.receiver_path or "none").lower() != "none" else None
    check_outputs({"-o": (args.output, "directory")}, [args.directory, args.kit, path_file])
    kit = _kit(args)
    layout = _vna_layout(args)
    receiver_path = _receiver_path(args)
    if (receiver_path is not None) != (args.receiver is not None):
        raise InvalidDataError(
            "--receiver NAME and --receiver-cable or --receiver-path go together: "
            "give both or neither"
        )
    if args.receiver is not None and args.receiver not in args.devices:
        raise InvalidDataError(f"--receiver {args.receiver}: not one of --devices")
    corrected = correct_exports(args.directory, args.devices, layout, kit)
    if receiver_path is not None:
        f_rec, g_rec = corrected[args.receiver]
        corrected[args.receiver] = (f_rec, receiver_path.apply(f_rec, g_rec))
        print(f"{args.receiver} moved to the loads' plane: {receiver_path.describe()}")
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


