"""The calibration corrections on the simulated receiver with its effects on (issue 14).

A schedule (S11s of every source and the LNA, one Dicke cycle of each, ``calibrate``) runs
through the run layer against :class:`~reach_receiver.sim.receiver.SimulatedReceiver` with
every effect of :mod:`reach_receiver.sim.effects` on (the MTS two-port, cables warmer at
the termination, the hot load's cable, RFI spikes). From the merged run file the
antenna is calibrated twice, with and without :func:`reach_receiver.store.corrections.
correct` (the ``calibrate`` step's corrections), and each error ``RMS(T_cal(Q) -
T_true(Q))`` over the channels used (``T_true`` the sky at the sources' plane,
:meth:`~reach_receiver.sim.physics.ReceiverPhysics.true_temperature_k`) is set against
the noise floor of that data (:func:`calibration.noise_floor.noise_floor` at the fitted
parameters)::

    python -m benchmarks.sim_corrections [--seeds 1 2 3 4 5] [--seconds 600]
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from calibration import CalibrationData, solve_radiometric
from calibration.data import SourceData
from calibration.noise_floor import noise_floor
from calibration.simulate import REACH_CALIBRATORS
from reach_receiver.run.session import RunSession
from reach_receiver.sim.effects import SimEffects
from reach_receiver.sim.physics import PhysicsConfig, ReceiverPhysics
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import HandOver, read_run_file
from reach_receiver.store.corrections import correct

SCHEDULE = """\
schedule: corrections
steps:
  - initialise: {{rails: [12v, 24v, 6v]}}
  - temperatures: {{period_s: 30}}
  - vna_calibrate: {{}}
  - s11: {{targets: [{sources}, ant, lna]}}
  - dicke: {{sources: [{sources}, ant], seconds: {seconds}}}
  - calibrate: {{}}
  - safe
"""


@dataclass(frozen=True)
class Outcome:
    """One run's antenna error and floor (K), with and without the corrections."""

    corrected_k: float
    corrected_floor_k: float
    uncorrected_k: float
    uncorrected_floor_k: float
    report: dict[str, Any]
    in_run: HandOver

    @property
    def ratio(self) -> float:
        """Error over floor with the corrections."""
        return self.corrected_k / self.corrected_floor_k


def antenna_error(
    physics: ReceiverPhysics, data: CalibrationData, antenna: SourceData
) -> tuple[float, float]:
    """RMS of ``T_cal(Q) - T_true(Q)`` of the antenna, and its noise floor (K)."""
    solution = solve_radiometric(data)
    spectrum = solution.calibrate(data.freq_hz, data.gamma_rec, antenna, data.channel_width_hz)
    truth = physics.true_temperature_k("ant", antenna.q, data.freq_hz)
    error = float(np.sqrt(np.mean((spectrum.mean - truth) ** 2)))
    return error, noise_floor(data, antenna, solution.parameters).rms


def run_once(seed: int, directory: Path, seconds: float = 600.0) -> Outcome:
    """Run the schedule on the simulated receiver with every effect on; calibrate both ways."""
    schedule = directory / "corrections.yaml"
    sources = ", ".join(REACH_CALIBRATORS)
    schedule.write_text(SCHEDULE.format(sources=sources, seconds=seconds))
    settings = SimulationSettings(
        compression=3000.0,
        spectrum_period_s=120.0,
        seed=seed,
        vna_drift_per_hour=0.0,
        physics=replace(PhysicsConfig(seed=seed), effects=SimEffects.all()),
    )
    with SimulatedReceiver(settings, workdir=directory) as sim:
        site = sim.site()
        session = RunSession.prepare(schedule, site, sim.clock, directory / "runs")
        session.metadata = {"simulated": True, "seed": seed}
        session.run()
        (run_dir,) = [p for p in (directory / "runs").iterdir() if p.is_dir()]
        contents = read_run_file(run_dir / "run.h5")
        data, others = contents.calibration_data()
        with h5py.File(run_dir / "run.h5") as f:
            handover = HandOver.from_json(f["observation_metadata"].attrs["handover"])
        (record,) = contents.of_kind("solution")
        in_run = HandOver.from_json(record.attrs["handover"])
        fixed, fixed_others, report = correct(data, others, handover, site.corrections, site.source)
        corrected = antenna_error(sim.physics, fixed, fixed_others["ant"])
        uncorrected = antenna_error(sim.physics, data, others["ant"])
    return Outcome(*corrected, *uncorrected, report, in_run)


def main(argv: list[str] | None = None) -> int:
    """Report the antenna's error and floor with and without the corrections, per seed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    parser.add_argument("--seconds", type=float, default=600.0, help="per Dicke position")
    args = parser.parse_args(argv)
    print("seed  corrected error / floor (ratio)   uncorrected error / floor (ratio)  RFI ch")
    ratios = []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory(prefix="sim-corrections-") as tmp:
            o = run_once(seed, Path(tmp), args.seconds)
        ratios.append((o.ratio, o.uncorrected_k / o.uncorrected_floor_k))
        print(
            f"{seed:4d}  {1e3 * o.corrected_k:7.1f} / {1e3 * o.corrected_floor_k:6.1f} mK "
            f"({ratios[-1][0]:5.2f})    {1e3 * o.uncorrected_k:8.1f} / "
            f"{1e3 * o.uncorrected_floor_k:6.1f} mK ({ratios[-1][1]:6.1f})   "
            f"{o.report.get('rfi_flagged_channels', 0)}"
        )
    mean = np.mean(ratios, axis=0)
    print(f"mean ratio: corrected {mean[0]:.2f}, uncorrected {mean[1]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
