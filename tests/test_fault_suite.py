"""The fault suite's quick subset: every class of bad input refused or handled, nothing lost.

Each class lives in :mod:`benchmarks.faults` (``python -m benchmarks.faults`` runs them in
full and prints the table). A trial that is not clean fails here with what was seen.
"""

import pytest

from benchmarks.faults.core import Answer, Trial, fault_classes, judge_refusal, table, tally

CLASSES = list(fault_classes())


@pytest.mark.parametrize("module", CLASSES, ids=[str(m.CLASS) for m in CLASSES])
def test_every_quick_fault_of_the_class_is_clean(module, tmp_path):
    trials = list(module.trials(tmp_path, True))
    assert trials, f"{module.CLASS}: no trials"
    bad = [t for t in trials if t.verdict != "clean"]
    assert not bad, "\n".join(f"{t.verdict} {t.name}: {t.detail}" for t in bad)


def test_a_refusal_is_judged_by_its_exit_its_message_and_its_inputs():
    refused = Answer(2, "", "reach-cal: run.h5: -o names an input\n")
    assert judge_refusal("o", refused, says="input").verdict == "clean"
    assert judge_refusal("o", refused, says="orders").verdict == "silent"
    assert judge_refusal("o", refused, intact=False).verdict == "lost"
    assert judge_refusal("o", Answer(0, "", "")).verdict == "silent"
    assert judge_refusal("o", Answer(None, "", "hung")).verdict == "crash"
    assert judge_refusal("o", Answer(-11, "", "")).verdict == "crash"
    traceback = Answer(1, "", "Traceback (most recent call last):\n  ...\nKeyError: 3\n")
    assert judge_refusal("o", traceback).verdict == "crash"


def test_the_table_counts_each_verdict_and_totals_them():
    counts = tally([Trial("a", "clean"), Trial("b", "crash"), Trial("c", "clean")])
    text = table([("schedules", counts), ("socket", tally([Trial("d", "silent")]))])
    lines = text.splitlines()
    assert lines[0].split() == ["class", "tried", "clean", "crash", "lost", "silent"]
    assert lines[2].split() == ["schedules", "3", "2", "1", "0", "0"]
    assert lines[-1].split() == ["all", "4", "2", "1", "0", "1"]
