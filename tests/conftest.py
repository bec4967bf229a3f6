"""Suite-wide settings.

One BLAS thread per test process: the suite runs in two worker processes on two cores
(pyproject's ``-n 2``), and numerical tests that each started a BLAS thread per core
would take the cores from the hardware-in-the-loop tests running beside them, whose
simulated clocks run at up to 3000x real time. Set before any worker imports numpy
(workers inherit this environment); a value set by the caller is kept.
"""

import os

import pytest

for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(variable, "1")


#: The longest files, longest first (seconds each took in a full two-worker run, load
#: average 5-8). ``--dist loadfile`` hands each worker a whole file; pyproject's
#: ``--no-loadscope-reorder`` keeps this order instead of xdist's (most tests first, which
#: left files of a few long tests to the end, one worker busy while the other sat idle).
#: Every other file follows in its usual order, the short ones filling the gaps. A file
#: renamed or removed here is only scheduled later, never skipped.
LONGEST_FIRST = (
    "test_deploy_offline.py",  # 159-377 s: two environments installed, the most variable
    "test_model_choice.py",  # 263 s
    "test_daemon_recovery.py",  # 193 s
    "test_deploy.py",  # 140 s
    "test_run_signals.py",  # 132 s
    "test_fault_suite.py",  # 130 s
    "test_coverage.py",  # 129 s
    "test_reach_run.py",  # 117 s
    "test_errors_in_variables.py",  # 104 s
    "test_cli_commands.py",  # 88 s
    "test_vna_systematics.py",  # 87 s
    "test_identifiability.py",  # 86 s
    "test_consistency.py",  # 85 s
    "test_daemon.py",  # 76 s
    "test_adaptive_step.py",  # about 75 s (three runs to a target or a budget)
    "test_status_page.py",  # 67 s
    "test_terminal_80.py",  # about 65 s (a followed job in tmux)
    "test_solver_choice.py",  # 63 s
    "test_healthy_day.py",  # 56 s
    "test_sim_corrections.py",  # about 45 s
    "test_term_prior.py",  # about 45 s
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
