"""Step kinds: each kind of step declared once, and the registry of kinds a schedule may use.

A :class:`StepKind` ties together everything the language needs to know about one kind:
its YAML name and argument keys, the frozen step class it compiles into, how its
arguments are read (:meth:`StepKind.parse`), how it is described and how long it takes
(:meth:`~StepKind.describe`, :meth:`~StepKind.duration`), what it connects and what it
does to the front-end's rails and switches (:meth:`~StepKind.connections`,
:meth:`~StepKind.check_interlocks`). The run layer adds how it executes. A
:class:`KindRegistry` is the set a schedule is compiled with: compiling, the dry-run
timeline, the interlock check and the runner all look a step up in it, so a new kind is
one class registered once.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Literal, TypeVar

from reach_receiver.config.fields import Fields

from .steps import Step, Where

if TYPE_CHECKING:
    from .interlocks import BoardCheck
    from .parsing import ParseContext
    from .timing import TimingWalk

S = TypeVar("S", bound=Step)


class StepKind(Generic[S]):
    """One kind of step, as the language sees it.

    Subclasses set :attr:`name`, :attr:`step_type` and :attr:`keys`, and implement
    :meth:`parse`; the other methods have defaults that suit a kind which takes no time,
    connects nothing and needs no device.
    """

    #: The YAML name (``dicke``).
    name: ClassVar[str]
    #: The frozen step class it compiles into.
    step_type: ClassVar[type[Step]]
    #: The argument names it accepts.
    keys: ClassVar[tuple[str, ...]] = ()
    #: Whether it commands the hardware, so that it needs ``initialise`` first.
    needs_devices: ClassVar[bool] = True
    #: What a resumed run does with it when it was done before the interruption:
    #: ``"skip"`` it (a measurement), or ``"replay"`` it (it sets up state that a restart
    #: lost: connections, rails, the temperature log, the VNA's calibration).
    on_resume: ClassVar[Literal["skip", "replay"]] = "skip"

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> S:
        """Read the step's arguments (``f`` records every mistake; return a step anyway)."""
        raise NotImplementedError

    def describe(self, step: S) -> str:
        """A one-line description for the dry-run timeline."""
        return self.name

    def duration(self, step: S, walk: TimingWalk) -> float:
        """Estimated duration in seconds (``walk`` knows the sweep and the spectra)."""
        del step, walk
        return 0.0

    def timing(self, step: S, walk: TimingWalk) -> tuple[float, str]:
        """The duration and the timeline's description; override to add to the text."""
        return self.duration(step, walk), self.describe(step)

    def connections(self, step: S) -> Sequence[tuple[str, str]]:
        """The (source, ``lna`` or ``vna``) connections the step makes, in order."""
        del step
        return ()

    def check_interlocks(self, step: S, board: BoardCheck) -> None:
        """Follow the step's effect on the board's state, reporting what would be refused."""
        for source, to in self.connections(step):
            board.connect(source, to)

    def children(self, step: S) -> tuple[Step, ...]:
        """Steps nested inside this one (a ``repeat``'s body)."""
        del step
        return ()

    def rest(self, step: S, measured: Sequence[tuple[str, str]]) -> Step | None:
        """What is left of ``step`` after an interruption, given what it had measured.

        ``measured`` lists the (kind, name) of the measurements the step stored before it
        was interrupted. By default the whole step again; a kind that measures several
        things (sources, targets, cycles) returns the ones still to do, or ``None``.
        """
        del measured
        return step

    def after_repetitions(self, step: S, done: int) -> Step | None:
        """A step with children: what is left after ``done`` whole repetitions of them."""
        del step, done
        return None


class KindRegistry:
    """The step kinds a schedule may use, by YAML name and by step class.

    Parameters
    ----------
    kinds
        The kinds; names and step classes must be unique.
    """

    def __init__(self, kinds: Iterable[StepKind[Any]]) -> None:
        self._by_name: dict[str, StepKind[Any]] = {}
        self._by_type: dict[type[Step], StepKind[Any]] = {}
        for kind in kinds:
            if kind.name in self._by_name or kind.name == "use":
                raise ValueError(f"step kind {kind.name!r} is declared twice (or is 'use')")
            if kind.step_type in self._by_type:
                raise ValueError(f"step class {kind.step_type.__name__} has two kinds")
            self._by_name[kind.name] = kind
            self._by_type[kind.step_type] = kind

    def __iter__(self) -> Iterator[StepKind[Any]]:
        return iter(self._by_name.values())

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    @property
    def names(self) -> tuple[str, ...]:
        """Every kind's YAML name, in registration order."""
        return tuple(self._by_name)

    def named(self, name: str) -> StepKind[Any]:
        """The kind written ``name``."""
        return self._by_name[name]

    def of(self, step: Step) -> StepKind[Any]:
        """The kind of a compiled step."""
        try:
            return self._by_type[type(step)]
        except KeyError:
            raise KeyError(f"no step kind for {type(step).__name__}") from None

    def knows(self, step: Step) -> bool:
        """Whether ``step`` is of a kind in this registry."""
        return type(step) in self._by_type

    def with_kinds(self, *kinds: StepKind[Any]) -> KindRegistry:
        """A registry with these kinds added (this one is unchanged)."""
        return KindRegistry([*self, *kinds])

    def written(self, step: Step) -> str:
        """A step in the schedule's own words, ``dicke {sources: [hot], seconds: 600.0}``."""
        name = self.of(step).name if self.knows(step) else type(step).__name__.lower()
        fields = {k: v for k, v in vars(step).items() if k not in ("where", "steps")}
        text = ", ".join(f"{k}: {_value(v)}" for k, v in fields.items() if v not in (None, ()))
        return f"{name} {{{text}}}" if text else name


def _value(value: object) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if hasattr(value, "__dataclass_fields__"):
        given = {k: v for k, v in vars(value).items() if v is not None}
        return "{" + ", ".join(f"{k}: {_value(v)}" for k, v in given.items()) + "}"
    return str(value)
