"""The fault suite: every kind of bad input a user or local client can give, tried.

Each module of this package is one class of faults (schedules, site files, the control
socket, the engine's inputs, signals, a full disk ...). It defines ``CLASS`` (the name
in the table) and ``trials(workdir, quick)``, which tries each fault and yields a
:class:`~benchmarks.faults.core.Trial` with its verdict (:mod:`.core`):

* ``clean``: refused or handled with a clear message, nothing lost;
* ``crash``: a traceback, a hang, a process killed by a signal, a daemon gone;
* ``lost``: an input or a stored measurement damaged or gone;
* ``silent``: bad input accepted without a word.

``python -m benchmarks.faults`` runs every class in full and prints the table "tried /
clean / crash / lost / silent"; ``tests/test_fault_suite.py`` runs each class's quick
subset and requires every trial clean. A new feature that takes input adds its faults
to the class it belongs to (or a new module here): that is how it is checked.
"""
