"""The site file's calibration corrections: read, written back, refused at file:line."""

import pytest
import yaml
from sites import DEVICES, planning_site

from reach_receiver.config.corrections import CableSettings, CorrectionSettings
from reach_receiver.config.site import SiteError, load_site, parse_site
from reach_receiver.store.corrections import corrections_line


def test_corrections_survive_the_site_file_round_trip():
    corrections = CorrectionSettings(
        mts_sources="mts_sources.s2p",
        mts_lna="mts_lna.s2p",
        cables={"hot": CableSettings(1, None, 0.3, 0.83, 0.1), "c10r10": CableSettings(6, "c.s2p")},
        rfi=True,
    )
    site = planning_site(corrections=corrections)
    again = parse_site(yaml.safe_load(site.to_yaml()))
    assert again.corrections == corrections


def test_a_cable_without_its_thermocouple_or_with_two_models_is_refused_with_its_line(tmp_path):
    path = tmp_path / "site.yaml"
    document = {
        "devices": DEVICES,
        "calibration": {
            "cables": {
                "hot": {"length_m": 0.3, "velocity_factor": 0.83, "loss_db_per_m": 0.1},
                "c2r27": {"s2p": "x.s2p", "length_m": 2.0, "thermocouple": 5},
            },
            "rfi": "yes",
        },
    }
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    with pytest.raises(SiteError) as err:
        load_site(path)
    text = str(err.value)
    assert f"{path}:" in text
    assert "calibration.cables.hot.thermocouple: missing required key" in text
    assert "calibration.cables.c2r27.s2p: give a measured two-port or a data-sheet" in text
    assert "calibration.rfi: must be true or false" in text


def test_the_run_summary_says_what_the_corrections_did():
    report = {"mts_sources": "mts.s2p", "cable_mean_change_k": {"c10open": -3.981},
              "rfi_flagged_channels": 5, "warnings": ["hot: no reading of its cable's port 3"]}
    assert corrections_line(report) == (
        "sources de-embedded through mts.s2p; cable temperatures (c10open -3.981 K); "
        "5 RFI channels flagged; warning: hot: no reading of its cable's port 3"
    )
    assert corrections_line({}) == ""
