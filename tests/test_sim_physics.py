"""The simulated receiver's physics agrees with the calibration engine's model."""

import numpy as np
import pytest

from calibration.model.noise_waves import design_terms, model_q
from reach_receiver.clock import ManualClock
from reach_receiver.frontend.layout import REACH_SOURCES, VNA_STANDARDS
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.sim.physics import ReceiverPhysics

BAND = slice(4096, 10650)  # channels of 50-130 MHz at 12.207 kHz


def pins_for(source: str, to: str = "lna", ns_on: bool = False) -> dict[str, str]:
    path = FrontEnd(matrix=None, sources=REACH_SOURCES).path(source, to)  # type: ignore[arg-type]
    pins = {"ms1": "0", "ms2": "0", "ms3": "0", "ms4": "0", "mts": "lna"}
    pins.update({switch: str(position) for switch, position in path.switches})
    pins.update({rail: "1" for rail in path.rails_on})
    pins.update({rail: "0" for rail in path.rails_off})
    if ns_on:
        pins["ns"] = "1"
    return pins


@pytest.fixture
def physics() -> ReceiverPhysics:
    return ReceiverPhysics(ManualClock())


@pytest.mark.parametrize("source", sorted(REACH_SOURCES))
def test_every_source_path_reaches_the_lna_and_the_vna(physics, source):
    physics.update_pins(pins_for(source, "lna"))
    assert physics.lna_input() == source
    physics.update_pins(pins_for(source, "vna"))
    assert physics.vna_target() == source
    assert physics.lna_input() == "open"


@pytest.mark.parametrize("standard", sorted(VNA_STANDARDS))
def test_vna_standards(physics, standard):
    physics.update_pins(pins_for(standard, "vna"))
    assert physics.vna_target() == standard


def test_switches_without_their_rail_connect_nothing(physics):
    pins = pins_for("hot", "lna")
    pins["12v"] = "0"
    physics.update_pins(pins)
    assert physics.lna_input() == "open"


@pytest.mark.parametrize("source", ["hot", "c10open", "c2r91", "r25", "ant"])
def test_dicke_ratio_matches_engine_model_with_effective_truth(physics, source):
    """Q of noiseless spectra equals model_q(effective theta) to rounding: exact truth."""
    t = physics.clock.now()
    powers = {}
    for name, ns_on in ((source, False), ("cold", False), ("ns", True)):
        physics.update_pins(pins_for(name, "lna", ns_on))
        powers[name] = physics.noiseless_power(physics.lna_input(), t)[BAND]
    q = (powers[source] - powers["cold"]) / (powers["ns"] - powers["cold"])
    freq = physics.freq_hz[BAND]
    theta = physics.effective_theta(freq)
    terms = design_terms(physics.reflection(source, freq), physics.reflection("lna", freq))
    t_src = (
        physics.sky_temperature_k(freq, t)
        if source == "ant"
        else physics.source_temperature_k(source, t)
    )
    np.testing.assert_allclose(q, model_q(theta, terms, t_src), rtol=1e-10, atol=1e-12)


def test_radiometer_noise_follows_the_radiometer_equation(physics):
    physics.update_pins(pins_for("cold", "lna"))
    tau = 2.0
    spectra = np.stack([physics.spectrum(0.0, tau)[0, BAND] for _ in range(40)])
    relative = spectra.std(axis=0, ddof=1) / spectra.mean(axis=0)
    expected = 1 / np.sqrt(physics.config.channel_width_hz * tau)
    # 40 samples per channel, 6554 channels: the mean of the std is known to ~0.2 %.
    assert np.mean(relative) == pytest.approx(expected, rel=0.02)


def test_lna_unpowered_gives_no_signal(physics):
    pins = pins_for("hot", "lna")
    pins["6v"] = "0"
    physics.update_pins(pins)
    assert np.max(physics.spectrum(0.0, 1.0)[0]) < 1e-9
