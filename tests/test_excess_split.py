"""The model-choice benchmark's split of a method's excess over the true orders.

``excess_split`` pairs two methods run by run and says which way the choice of orders
erred where the error grew. A hand-made tally, so every figure is known beforehand.
"""

from benchmarks.model_choice import Tally, excess_split


def test_the_excess_is_paired_run_by_run_and_split_by_the_way_the_choice_erred():
    chosen = Tally(
        ratios=[1.3, 1.5, 1.0, 2.0, 1.1],
        runs=[0, 1, 2, 3, 4],
        beyond=[0, 2, 0, 1, 1],
        short=[0, 0, 3, 0, 2],  # run 4 holds extra terms and lacks some: counted "beyond"
    )
    # Run 3 failed under the true orders: it has nothing to be paired with.
    truth = Tally(ratios=[1.0, 1.0, 1.0, 1.1], runs=[0, 1, 2, 4])

    line = excess_split(chosen, truth)

    # Excess on runs 0, 1, 2, 4: 0.69, 1.25, 0, 0; mean 0.485, total 1.94.
    assert line.startswith("0.485 +- "), line
    assert "2 runs with terms beyond the truth's orders: 0.625 (64 %)" in line, line
    assert "1 only short of them: 0.000 (0 %)" in line, line
    assert "1 at them: 0.690 (36 %)" in line, line


def test_methods_that_share_no_solved_run_are_said_to():
    chosen = Tally(ratios=[1.2], runs=[0], beyond=[1], short=[0])
    assert excess_split(chosen, Tally(ratios=[1.0], runs=[1])) == "no run both solved"
