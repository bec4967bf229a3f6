"""The standard step kinds, and the registry that compiling, timing and running share.

Each module declares whole kinds (step fields, parser, description, duration, interlock
effect, executor); :data:`STANDARD_KINDS` lists them. A new kind is a
:class:`~reach_receiver.run.kind.RunnableKind` in a module of its own, added here (or, for
one site or one test, with :meth:`~reach_receiver.schedule.kinds.KindRegistry.with_kinds`).

The step classes are re-exported, with the language's :class:`Schedule` and
:class:`Where`, as the vocabulary of a compiled schedule.
"""

from reach_receiver.schedule.kinds import KindRegistry
from reach_receiver.schedule.steps import Schedule, Step, Where

from .adaptive import CalibrateAdaptive, CalibrateAdaptiveKind
from .calibrate import Calibrate, CalibrateKind
from .observe import Observe, ObserveKind
from .repeat import Repeat, RepeatKind
from .setup import (
    Connect,
    ConnectKind,
    Initialise,
    InitialiseKind,
    Power,
    PowerKind,
    Safe,
    SafeKind,
    Tec,
    TecKind,
    Temperatures,
    TemperaturesKind,
    Wait,
    WaitKind,
    WaitStable,
)
from .spectra import Dicke, DickeKind, MeasureSpectrum, MeasureSpectrumKind
from .vna import (
    MeasureS11,
    MeasureS11Kind,
    Sweep,
    TestLoadCheck,
    TestLoadCheckKind,
    VnaCalibrate,
    VnaCalibrateKind,
)

#: Every standard kind, in the order the documentation lists them.
STANDARD_KINDS = KindRegistry(
    [
        InitialiseKind(),
        PowerKind(),
        ConnectKind(),
        VnaCalibrateKind(),
        TestLoadCheckKind(),
        MeasureS11Kind(),
        MeasureSpectrumKind(),
        DickeKind(),
        TemperaturesKind(),
        TecKind(),
        WaitKind(),
        RepeatKind(),
        CalibrateKind(),
        CalibrateAdaptiveKind(),
        ObserveKind(),
        SafeKind(),
    ]
)

__all__ = [
    "STANDARD_KINDS",
    "Calibrate",
    "CalibrateAdaptive",
    "Connect",
    "Dicke",
    "Initialise",
    "MeasureS11",
    "MeasureSpectrum",
    "Observe",
    "Power",
    "Repeat",
    "Safe",
    "Schedule",
    "Step",
    "Sweep",
    "Tec",
    "Temperatures",
    "TestLoadCheck",
    "VnaCalibrate",
    "Wait",
    "WaitStable",
    "Where",
]
