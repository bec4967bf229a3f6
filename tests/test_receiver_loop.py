"""The loop: drivers take everything from the simulated receiver, the engine recovers its truth.

Every instrument is reached through its real transport: the Teensy's firmware (host
build) on a pty, the TEC through the Teensy's UART passthrough, the VNA over a pyvisa-py
TCP socket, the spectra over UDP and the TC-08 through its ctypes binding loading the
stand-in library. Nothing of ours is mocked. The simulated receiver runs 3000x faster
than real time; each Dicke position integrates 600 simulated seconds (5 spectra of
120 s), as the engine's own simulations do.
"""

import numpy as np
import pytest

from calibration import solve_radiometric
from calibration.model.simulate import REACH_CALIBRATORS
from reach_receiver.devices.spectrometer import Spectrometer
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.devices.tec import Tec
from reach_receiver.devices.tec_via_teensy import TeensyTecLink
from reach_receiver.devices.teensy import Teensy
from reach_receiver.devices.vna import SweepSettings, Vna
from reach_receiver.frontend.layout import SOURCE_THERMOCOUPLE
from reach_receiver.frontend.paths import FrontEnd
from reach_receiver.run.measure import (
    TemperatureLogger,
    source_temperature,
    take_dicke_cycle,
    take_s11,
)
from reach_receiver.sim.receiver import SimulatedReceiver, SimulationSettings
from reach_receiver.store import RunStore
from reach_receiver.transports.tc08_library import load_libusbtc08

SPECTRA_PER_POSITION = 5
PERIOD_S = 120.0
#: REACH's sweep (40-180 MHz, 1 kHz IFBW, 20 averages). The engine's posterior does not
#: include S11 uncertainty: this sweep's noise (~2e-4) raises the fitted noise scale s^2
#: to about 1.13; a 100 Hz IFBW brings it to 1.03. VNA drift is switched off here (the
#: test-load check tests it): 0.1 %/h over the S11 section biases T_sin by several sigma.
VNA_SETTINGS = SweepSettings()
VNA_DRIFT = 0.0


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    settings = SimulationSettings(
        compression=3000.0, spectrum_period_s=PERIOD_S, seed=3, vna_drift_per_hour=VNA_DRIFT
    )
    with SimulatedReceiver(settings) as sim:
        devices = sim.site().devices
        clock = sim.clock
        teensy = Teensy(devices.teensy.port)
        vna = Vna(devices.vna.resource, clock=clock, timeout_s=10.0)
        spectra = Spectrometer(
            ("127.0.0.1", devices.spectrometer.port), clock=clock, period_s=PERIOD_S
        )
        tc08 = Tc08(load_libusbtc08(devices.tc08.library), clock, period_s=1.0)
        with teensy, vna, spectra, tc08:
            frontend = FrontEnd(teensy)
            teensy.set_rail("tec", True)
            with Tec(TeensyTecLink(teensy), clock) as tec:
                tec.set_setpoint(25.0)
                tec_status = tec.status()
            vna.configure(VNA_SETTINGS)
            vna.calibrate_sol(lambda standard: frontend.connect(standard, "vna"))
            targets = (*REACH_CALIBRATORS, "ant", "lna")
            s11 = {name: take_s11(frontend, vna, name) for name in targets}
            with TemperatureLogger(tc08, clock, period_s=60.0) as temperatures:
                cycles = {
                    name: take_dicke_cycle(
                        frontend, spectra, name, SPECTRA_PER_POSITION, temperatures
                    )
                    for name in (*REACH_CALIBRATORS, "ant")
                }
            final_state = frontend.safe()
            losses = spectra.statistics
        yield {
            "sim": sim,
            "store": stored(tmp_path_factory.mktemp("loop"), s11, cycles),
            "s11": s11,
            "cycles": cycles,
            "tec": tec_status,
            "state": final_state,
            "stats": losses,
        }


def stored(directory, s11, cycles):
    """The measurements in a run store, as the run layer keeps them."""
    store = RunStore(
        directory / "run",
        name="loop",
        schedule_files=(),
        site_yaml="",
        metadata={},
        channel_width_hz=SimulationSettings().physics.channel_width_hz,
    )
    store.open()
    for name, m in s11.items():
        store.add_s11(name, m.freq_hz, m.s11, timestamp=m.timestamp, settings={}, calibrated=True)
    for name, cycle in cycles.items():
        port = SOURCE_THERMOCOUPLE[name] if name in REACH_CALIBRATORS else None
        temperature, std = source_temperature(cycle, port)
        store.add_dicke(
            name,
            spectra={k: v.mean for k, v in cycle.spectra.items()},
            timestamps={k: v.timestamps for k, v in cycle.spectra.items()},
            integration_s=dict(cycle.integration_s),
            n_spectra={k: v.n_spectra for k, v in cycle.spectra.items()},
            temperature_k=temperature,
            temperature_std_k=std,
            switch_states={},
            counters={},
            timestamp=0.0,
        )
    return store


def engine_data(measured):
    """The engine's view through the store's hand-over (the run layer's one path)."""
    view = measured["store"].engine_view((50e6, 130e6))
    data = view.data
    assert sorted(data.names) == sorted(REACH_CALIBRATORS)
    return data, view.others["ant"], None, data.freq_hz


def test_every_measurement_arrived_complete(measured):
    for name, cycle in measured["cycles"].items():
        for position, spectrum in cycle.spectra.items():
            assert spectrum.n_spectra == SPECTRA_PER_POSITION, (name, position)
            assert spectrum.packets_lost == 0
        assert cycle.integration_s["source"] == pytest.approx(SPECTRA_PER_POSITION * PERIOD_S)
    assert measured["stats"].heaps_dropped == 0
    assert measured["tec"].setpoint == pytest.approx(25.0)
    assert measured["state"].rails["ns"] is False
    assert measured["state"].switches["ms1"] == 0


def test_measured_reflections_match_the_true_ones(measured):
    physics = measured["sim"].physics
    for name in (*REACH_CALIBRATORS, "lna"):
        m = measured["s11"][name]
        band = (m.freq_hz >= 50e6) & (m.freq_hz <= 130e6)
        truth = physics.reflection(name, m.freq_hz[band])
        # Simulated VNA noise after SOL is ~1e-4; a wrong path would be off by >1e-2.
        np.testing.assert_allclose(m.s11[band], truth, atol=2e-3, err_msg=name)


def test_temperatures_come_from_the_thermocouples(measured):
    physics = measured["sim"].physics
    hot = measured["cycles"]["hot"].temperature_k(2)
    cold = measured["cycles"]["cold"].temperature_k(1)
    assert hot == pytest.approx(physics.config.t_hot_k, abs=0.5)
    assert cold == pytest.approx(physics.enclosure_k(), abs=0.05)


def test_a_source_shorter_than_the_log_period_still_gets_its_temperature(measured):
    # One spectrum a position, the log's period far longer: no periodic reading falls
    # inside the hot load's integration, so the cycle reads once at its end.
    sim = measured["sim"]
    devices, clock = sim.site().devices, sim.clock
    teensy = Teensy(devices.teensy.port)
    spectra = Spectrometer(("127.0.0.1", devices.spectrometer.port), clock=clock,
                           period_s=PERIOD_S)
    tc08 = Tc08(load_libusbtc08(devices.tc08.library), clock, period_s=1.0)
    with teensy, spectra, tc08, TemperatureLogger(tc08, clock, period_s=1e7) as log:
        cycle = take_dicke_cycle(FrontEnd(teensy), spectra, "hot", 1, log)
        FrontEnd(teensy).safe()
    (reading,) = cycle.temperatures["source"]
    assert reading.timestamp >= max(cycle.spectra["source"].timestamps)
    assert cycle.temperature_k(2) == pytest.approx(sim.physics.config.t_hot_k, abs=0.5)
    assert not cycle.temperatures["load"]  # only the source's temperature is needed


def test_engine_recovers_the_simulators_noise_waves_within_the_posterior(measured):
    data, _, _, freq = engine_data(measured)
    solution = solve_radiometric(data)
    truth = measured["sim"].physics.effective_theta(freq)
    mean = solution.evaluate(freq)
    std = solution.parameter_std(freq)
    z = (mean - truth) / std
    # Per parameter, the truth sits within the posterior (which includes the thermometry's
    # error): the RMS of z over the band is below 2.5 and no channel is beyond 4.5 sigma.
    # The z's of one parameter are strongly correlated along frequency (a few independent
    # values per parameter), so a stricter per-channel bound would not be a 1-sigma test.
    # Typical runs give a largest |z| of 1.3-3; one CI run under load gave 4.02 at T_unc's
    # band edge. The parameters' error bars leave out that the receiver reflection's VNA
    # error is shared by every calibrator row (docs/method.md, "The VNA's errors"), which makes
    # them up to 1.7x small where that error dominates: hence 4.5, not 4.
    rms = np.sqrt(np.mean(z**2, axis=1))
    assert np.all(rms < 2.5), rms
    assert np.max(np.abs(z)) < 4.5, np.max(np.abs(z), axis=1)
    # And the posterior is informative: T_unc, T_cos, T_sin to better than 1 K.
    assert np.max(std[:3]) < 1.0


def test_calibrated_antenna_matches_the_sky_within_its_error_bars(measured):
    data, antenna, _, freq = engine_data(measured)
    solution = solve_radiometric(data)
    spectrum = solution.calibrate(freq, data.gamma_rec, antenna, data.channel_width_hz)
    sky = measured["sim"].physics.sky_temperature_k(freq, 0.0)
    z = (spectrum.mean - sky) / spectrum.std
    inside = np.mean(np.abs(z) < 1.0)
    # One realisation: the calibration part of the error is shared by all channels, so the
    # fraction inside varies from run to run far more than a binomial's (0.598 seen once in CI,
    # where spectra the simulator skips under load change the data).
    assert 0.5 < inside < 0.85, inside
    # The calibration error is common to all channels: the mean z scatters by about
    # std_calibration / std, not by 1 / sqrt(n_channels).
    common = np.median(spectrum.std_calibration) / np.median(spectrum.std)
    assert abs(np.mean(z)) < 3 * common, (np.mean(z), common)


def test_each_s11_carries_its_trace_noise_and_the_noise_scale_is_one(measured):
    """The hand-over states each sweep's trace noise, estimated from the sweep alone; it
    matches the sweep's actual scatter about the simulator's true reflection (known here),
    and with it the solver's noise scale s^2 is the radiometer equation's 1 (it was 1.13
    when the VNA's noise on the reflections was not stated)."""
    data, antenna, _, _ = engine_data(measured)
    physics = measured["sim"].physics
    stated = {name: float(np.max(src.gamma_std)) for name, src in data.sources.items()}
    stated["ant"] = float(np.max(antenna.gamma_std))
    stated["lna"] = float(np.max(data.gamma_rec_std))
    for name, sigma in stated.items():
        m = measured["s11"][name]
        actual = np.sqrt(np.mean(np.abs(m.s11 - physics.reflection(name, m.freq_hz)) ** 2))
        assert sigma == pytest.approx(actual, rel=0.15), name
    assert 0.9 < solve_radiometric(data).posterior.noise_variance < 1.1
