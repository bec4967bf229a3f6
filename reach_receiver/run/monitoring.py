"""A run's side of the daemon's monitor: its drivers lent, its readings stored.

When ``reachd`` runs a schedule, :func:`watch` lends the run's drivers to the monitor
(:meth:`~reach_receiver.monitor.Monitor.watch_run`): the Teensy and the TEC are then
read by the run's own thread at its safe points, and what the run reads anyway (the
board's state, the temperature log, the spectrometer's counters) is shared. Until the
run has connected its instruments (and after it closed them) the devices are not asked:
the monitor shows them as unknown, not as silent. At the end,
:func:`store_readings` puts every health reading taken during the run in its run file
(measurement kind ``monitoring``). A plain ``reach-run`` has no monitor: nothing changes.
"""

from __future__ import annotations

from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import Tec
from reach_receiver.devices.teensy import Teensy
from reach_receiver.monitor import STATUSES, DeviceSet, Monitor, Reading, RunWatch
from reach_receiver.monitor.monitor import TemperatureLogState
from reach_receiver.store.run_store import RunStore

from .context import RunContext


def watch(monitor: Monitor, run: RunContext) -> RunWatch:
    """Lend the run's drivers to ``monitor``; the run's safe points then sample."""
    instruments = run.instruments
    teensy, tec, tc08 = instruments.teensy, instruments.tec, instruments.tc08
    devices = DeviceSet(
        teensy if isinstance(teensy, Teensy) else None,
        tec if isinstance(tec, Tec) else None,
        tc08 if isinstance(tc08, Tc08) else None,
        dict(tc08.ports) if isinstance(tc08, Tc08) else {},
        tec_usable=lambda: instruments.tec_connected,
        connected=lambda: instruments.connected,
    )

    def temperature_log() -> TemperatureLogState:
        logger = run.temperatures
        if logger is None:
            return TemperatureLogState()
        readings = logger.readings(run.clock.now() - 2 * monitor.cadence_s)
        return TemperatureLogState(True, readings[-1] if readings else None, logger.failures)

    spectrometer = instruments.spectrometer
    taken = monitor.watch_run(
        devices, spectrometer if isinstance(spectrometer, Spectrometer) else None,
        temperature_log,
    )
    run.watch = taken
    return taken


def store_readings(store: RunStore, readings: list[Reading]) -> int:
    """The health readings taken during a run, into its run file; returns how many."""
    if not readings:
        return 0
    keys: dict[str, int] = {}
    units: list[str] = []
    for reading in readings:
        if reading.key not in keys:
            keys[reading.key] = len(keys)
            units.append(reading.unit)
    store.add_monitoring(
        [r.timestamp for r in readings],
        [keys[r.key] for r in readings],
        [r.value for r in readings],
        [STATUSES.index(r.status) for r in readings],
        keys=list(keys),
        units=units,
        status_names=STATUSES,
    )
    return len(readings)
