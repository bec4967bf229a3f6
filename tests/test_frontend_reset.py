"""A front-end that moves during an integration: the integration is repeated, never stored.

The whole simulated receiver runs 3000x faster than real time (a 60 s spectrum every
20 ms of real time). In the middle of a Dicke cycle's source position the Teensy's main
loop is hung (``sim.teensy.hang()``); a second later its watchdog resets it into the
power-on state, every switch released and the LNA unpowered, while the spectrometer goes
on integrating. Without the check around each integration the source spectrum silently
took in the dead LNA (its band mean fell by a third here; see ``test_unchecked_...``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from reach_receiver.devices.spectra import AccumulatedSpectrum
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.teensy import Teensy
from reach_receiver.errors import DeviceError
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.run.measure import (
    MAX_REPEATS,
    DickeCycle,
    integrate_connected,
    take_dicke_cycle,
)
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings

PERIOD_S = 60.0
#: Spectra per position: 1.6 s of real time, so the reset (1 s after the hang, the
#: simulated watchdog's timeout) lands well inside the source's integration.
SPECTRA = 80
HANG_AFTER = 2  # spectra of the source position averaged when the board hangs
BAND_HZ = (50e6, 130e6)
SIGMAS = 5.0


@dataclass
class Receiver:
    sim: SimulatedReceiver
    teensy: Teensy
    frontend: FrontEnd
    spectra: Spectrometer


@pytest.fixture(scope="module")
def receiver() -> Iterator[Receiver]:
    settings = SimulationSettings(compression=3000.0, spectrum_period_s=PERIOD_S, seed=21)
    with SimulatedReceiver(settings) as sim:
        devices = sim.site().devices
        teensy = Teensy(devices.teensy.port)
        spectra = Spectrometer(
            ("127.0.0.1", devices.spectrometer.port), clock=sim.clock, period_s=PERIOD_S
        )
        with teensy, spectra:
            yield Receiver(sim, teensy, FrontEnd(teensy), spectra)


@pytest.fixture(scope="module")
def clean(receiver: Receiver) -> DickeCycle:
    """A Dicke cycle of the antenna with nothing going wrong."""
    cycle = take_dicke_cycle(receiver.frontend, receiver.spectra, "ant", SPECTRA)
    assert dict(cycle.repeats) == {"source": 0, "load": 0, "ns": 0}
    return cycle


def band_mean(receiver: Receiver, spectrum: AccumulatedSpectrum) -> tuple[float, float]:
    """The LNA input's mean power over the band and its radiometer noise.

    Each channel's noise is ``P / sqrt(B tau)`` with ``tau`` the whole integration; the
    mean of N channels has ``sqrt(sum sigma_i^2) / N``.
    """
    freq = receiver.sim.physics.freq_hz
    band = (freq >= BAND_HZ[0]) & (freq <= BAND_HZ[1])
    power = spectrum.mean[0][band]
    tau = spectrum.n_spectra * PERIOD_S
    sigma = power / np.sqrt(receiver.sim.physics.config.channel_width_hz * tau)
    return float(power.mean()), float(np.sqrt(np.sum(sigma**2)) / power.size)


def assert_same(receiver: Receiver, got: AccumulatedSpectrum, clean: AccumulatedSpectrum) -> None:
    (a, sigma_a), (b, sigma_b) = band_mean(receiver, got), band_mean(receiver, clean)
    assert abs(a - b) < SIGMAS * np.hypot(sigma_a, sigma_b), (a, b, np.hypot(sigma_a, sigma_b))


def test_a_reset_mid_source_is_repeated_and_the_stored_source_is_clean(receiver, clean, caplog):
    hung: list[int] = []

    def hang_mid_source(position: str, done: int, total: int) -> None:
        if position == "source" and done == HANG_AFTER and not hung:
            hung.append(done)
            receiver.sim.teensy.hang()

    with caplog.at_level(logging.WARNING, logger="reach_receiver.run.measure"):
        cycle = take_dicke_cycle(
            receiver.frontend, receiver.spectra, "ant", SPECTRA, progress=hang_mid_source
        )
    assert hung == [HANG_AFTER]
    assert receiver.teensy.read_state().boot == "wdog"  # the board really was reset
    assert dict(cycle.repeats) == {"source": 1, "load": 0, "ns": 0}
    assert "Dicke cycle of ant, source position" in caplog.text
    assert "board restarted (boot=wdog" in caplog.text
    for position in ("source", "load", "ns"):
        assert cycle.spectra[position].n_spectra == SPECTRA
        assert_same(receiver, cycle.spectra[position], clean.spectra[position])
    assert cycle.switch_states["source"]["6v"] == "1"  # the path as connected again


def test_unchecked_integration_would_have_mixed_in_the_dead_lna(receiver, clean):
    """What the repeat prevents: the same fault under a bare connect-and-integrate."""
    receiver.frontend.connect("ant", "lna")

    def hang(done: int, total: int) -> None:
        if done == HANG_AFTER:
            receiver.sim.teensy.hang()

    mixed = receiver.spectra.integrate(SPECTRA, on_spectrum=hang)
    after = receiver.teensy.read_state()  # waits out the reset
    assert after.boot == "wdog"
    (good, _), (bad, _) = (band_mean(receiver, s) for s in (clean.spectra["source"], mixed))
    assert bad < 0.9 * good


def test_an_output_change_is_caught_too_and_repeats_are_bounded(receiver, caplog):
    """Not a reset: another output moved (here the fan) while the load integrated."""
    receiver.frontend.connect("cold", "lna")  # 24v on, so the fan may switch
    fan = [False]

    def toggle_fan(done: int, total: int) -> None:
        if done == 1:
            fan[0] = not fan[0]
            receiver.teensy.set_rail("fan", fan[0])

    with (
        caplog.at_level(logging.WARNING, logger="reach_receiver.run.measure"),
        pytest.raises(DeviceError, match=f"during all {MAX_REPEATS} repeats"),
    ):
        integrate_connected(receiver.frontend, receiver.spectra, "cold", 3, on_spectrum=toggle_fan)
    assert caplog.text.count("1 output change(s)") == MAX_REPEATS

    moved = []

    def toggle_once(done: int, total: int) -> None:
        if done == 1 and not moved:
            moved.append(done)
            receiver.teensy.set_rail("fan", not fan[0])

    taken = integrate_connected(
        receiver.frontend, receiver.spectra, "cold", 3, on_spectrum=toggle_once
    )
    assert taken.repeats == 1
    assert taken.spectrum.n_spectra == 3
