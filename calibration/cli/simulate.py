"""``reach-cal simulate``: a simulated run of REACH's receiver, with its truth, as a run file."""

from __future__ import annotations

import argparse

from ..core.errors import InvalidDataError
from ..io.hdf5_io import NC346A, write_run
from ..model.simulate import REACH_CALIBRATORS, SimulationConfig, simulate_run
from .files import check_outputs

#: The most channels ``simulate`` makes: the iTPM's 32768 over its whole band, twice.
MAX_SIM_CHANNELS = 65536


def cmd_simulate(args: argparse.Namespace) -> int:
    """Write a simulated run with the validation source ``ant`` and the truth."""
    unknown = [n for n in args.calibrators if n not in REACH_CALIBRATORS]
    if unknown:
        known = ", ".join(REACH_CALIBRATORS)
        raise InvalidDataError(f"unknown calibrators {unknown}; REACH has: {known}")
    check_outputs({"-o": (args.output, "run")}, [], remakes="simulation")
    lo, hi = args.band
    if not 0 < lo < hi:
        raise InvalidDataError(f"--band needs 0 < LO < HI (MHz), got {lo:g} {hi:g}")
    channels = (hi - lo) * 1e6 / args.channel_width_hz
    if not 1 <= channels <= MAX_SIM_CHANNELS:
        raise InvalidDataError(
            f"--channel-width-hz {args.channel_width_hz:g} makes {channels:.3g} channel "
            f"intervals over {lo:g}-{hi:g} MHz: give between 1 and {MAX_SIM_CHANNELS}"
        )
    config = SimulationConfig(
        f_lo_hz=lo * 1e6,
        f_hi_hz=hi * 1e6,
        channel_width_hz=args.channel_width_hz,
        integration_s=args.integration_s,
        calibrators=args.calibrators,
        vna_sigma=args.vna_sigma,
    )
    run = simulate_run(config, rng=args.seed)
    write_run(
        args.output,
        run.data,
        {run.validation.name: run.validation},
        attrs={"simulation_seed": args.seed, "noise_source_model": NC346A},  # its T_NS: NC346A
        truth=run.truth,
    )
    print(
        f"wrote {args.output}: {len(run.data.names)} calibrators + {run.validation.name!r}, "
        f"{run.data.n_channels} channels, {lo:g}-{hi:g} MHz, seed {args.seed}"
    )
    return 0
