"""Site files for tests that compile or time schedules without instruments."""

from reach_receiver.config.settings import (
    DeviceSettings,
    SpectrometerSettings,
    Tc08Settings,
    TecSettings,
    TeensySettings,
    VnaSettings,
)
from reach_receiver.config.site import SiteConfig

#: A site file's ``devices`` section, as a test writes it (the spectrometer's period 30 s).
DEVICES = {
    "teensy": {"port": "/dev/ttyACM0"},
    "vna": {"resource": "TCPIP0::10.0.0.2::5025::SOCKET"},
    "tec": {"via": "teensy"},
    "tc08": {},
    "spectrometer": {"port": 4660, "period_s": 30.0},
}


def planning_site(period_s: float = 30.0, **fields) -> SiteConfig:
    """A site whose instruments are never contacted: table A.2, a spectrometer period."""
    devices = DeviceSettings(
        teensy=TeensySettings(port="/dev/null"),
        vna=VnaSettings(resource="TCPIP0::localhost::5025::SOCKET"),
        tec=TecSettings(),
        tc08=Tc08Settings(),
        spectrometer=SpectrometerSettings(period_s=period_s),
    )
    return SiteConfig(devices=devices, **fields)
