"""The attribution of the gaps between efforts (rcac_ros/tools/bench/gaps.py)."""

from rcac_ros.tools.bench.gaps import attribute, PERIOD_NS

H = PERIOD_NS


def test_each_gap_is_attributed_to_what_happened_around_it():
    states = [k * H for k in range(100)]
    efforts = [k * H + H // 4 for k in range(100)]
    # gap 1 (efforts 20 -> 24): the sentinel woke 1.5 periods late inside it
    # gap 2 (efforts 50 -> 55): the simulator's states stopped too (states 49 -> 56)
    # gap 3 (efforts 80 -> 83): nothing else happened
    for k in (21, 22, 23, 51, 52, 53, 54, 81, 82):
        efforts.remove(k * H + H // 4)
    for k in range(50, 56):
        states.remove(k * H)
    late = [(22 * H, 3 * H // 2), (70 * H, 5 * H)]      # the second: far from any gap
    rows = attribute(efforts, states, late)
    assert rows == [(4 * H, False, True), (5 * H, True, False), (3 * H, False, False)]


def test_a_gap_of_two_periods_is_not_counted_and_late_by_half_a_period_is_not_late():
    efforts = [0, 2 * H, 4 * H, 7 * H]
    rows = attribute(efforts, [k * H for k in range(8)], [(5 * H, H // 2)])
    assert rows == [(3 * H, False, False)]
