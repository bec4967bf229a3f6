"""Signal-path planning of the front-end model (pure: no device involved)."""

import pytest

from reach_receiver.devices.teensy import check_position, check_rail
from reach_receiver.errors import ConfigError, InterlockError
from reach_receiver.frontend.layout import FIXED_RAILS, REACH_SOURCES, SWITCH_RAIL, source_at
from reach_receiver.frontend.paths import FrontEnd

PLANNER = FrontEnd(matrix=None)  # type: ignore[arg-type]  # planning never touches it


@pytest.mark.parametrize("source", sorted(REACH_SOURCES))
@pytest.mark.parametrize("to", ["lna", "vna"])
def test_every_path_powers_the_rails_of_the_switches_it_moves(source, to):
    path = PLANNER.path(source, to)
    for switch, position in path.switches:
        if position not in (0, "lna"):
            assert SWITCH_RAIL[switch] in path.rails_on, (source, to, switch)
    assert not set(path.rails_on) & set(FIXED_RAILS)


@pytest.mark.parametrize("source", sorted(REACH_SOURCES))
def test_noise_source_powered_only_when_it_is_the_lna_input(source):
    lna = PLANNER.path(source, "lna")
    if source == "ns":
        assert "ns" in lna.rails_on
        assert "ns" not in lna.rails_off
    else:
        assert "ns" in lna.rails_off
        assert "ns" not in lna.rails_on
    assert "ns" in PLANNER.path(source, "vna").rails_off


def test_lna_path_needs_lna_power_and_vna_path_does_not():
    assert "6v" in PLANNER.path("hot", "lna").rails_on
    assert "6v" not in PLANNER.path("hot", "vna").rails_on


def test_cable_sources_select_their_termination_and_release_the_other():
    path = dict(PLANNER.path("c10r250", "lna").switches)
    assert (path["ms1"], path["ms4"], path["ms3"]) == (8, 4, 0)
    assert source_at(path["ms1"], path["ms3"], path["ms4"]) == "c10r250"


def test_unknown_source_and_destination_are_config_errors():
    with pytest.raises(ConfigError, match="unknown source 'sky'"):
        PLANNER.path("sky", "lna")
    with pytest.raises(ConfigError, match="'lna' or 'vna'"):
        PLANNER.path("hot", "spectrometer")  # type: ignore[arg-type]


def test_driver_refuses_fixed_rails_and_bad_positions_before_io():
    for rail in FIXED_RAILS:
        with pytest.raises(InterlockError, match="never switched"):
            check_rail(rail)
    with pytest.raises(ValueError, match="ms3 position must be 0-4"):
        check_position("ms3", 5)
    with pytest.raises(ValueError, match="mts position"):
        check_position("mts", 1)
    with pytest.raises(ValueError, match="unknown switch"):
        check_position("ms9", 1)
