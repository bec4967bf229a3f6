"""The TC-08 driver through its real ctypes binding, loading the stand-in shared library."""

import pytest

from reach_receiver.clock import ManualClock
from reach_receiver.devices.tc08 import Tc08
from reach_receiver.errors import DeviceError
from reach_receiver.sim.tc08_standin import Tc08StandIn
from reach_receiver.transports.tc08_library import load_libusbtc08

TRUE_C = [26.0, 25.0, 96.85, 25.1, 25.2, 25.3, 25.4, 27.0, 18.5]


@pytest.fixture
def standin(tmp_path):
    values = list(TRUE_C)
    clock = ManualClock()
    stand_in = Tc08StandIn(tmp_path, lambda t: values, clock)
    yield stand_in, values, clock
    stand_in.close()


def test_driver_reads_the_standin_through_the_real_binding(standin):
    stand_in, values, clock = standin
    library = load_libusbtc08(str(stand_in.library))
    with Tc08(library, clock, period_s=10.0) as tc08:
        assert tc08.serial == "SIM/0001"
        first = tc08.read()
        assert [first.temperatures_c[c] for c in range(9)] == pytest.approx(TRUE_C, abs=0.25)
        values[2] = 100.0
        stand_in.write()
        assert tc08.read().temperatures_c[2] == pytest.approx(100.0, abs=0.25)


def test_missing_values_file_reads_as_no_unit(standin):
    stand_in, _, clock = standin
    library = load_libusbtc08(str(stand_in.library))
    stand_in.values.unlink()
    with pytest.raises(DeviceError, match="tc08"):
        Tc08(library, clock).connect()


def test_standin_readings_jitter_like_a_thermocouple(standin):
    stand_in, _, clock = standin
    library = load_libusbtc08(str(stand_in.library))
    with Tc08(library, clock, period_s=1.0) as tc08:
        readings = [tc08.read() for _ in range(50)]
    assert not any(r.flagged for r in readings)
    channel1 = [r.temperatures_c[1] for r in readings]
    spread = max(channel1) - min(channel1)
    assert 0.02 < spread < 0.5
    assert sum(channel1) / len(channel1) == pytest.approx(TRUE_C[1], abs=0.03)
