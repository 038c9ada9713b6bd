"""Issue 29 item 7: words one can quote. A run at rest has no growth rate (not "-inf
1/s"); a bounded run whose pattern is not clear is not "bounded: undecided (high
confidence, bound)"; a run too short to tell is not "undecided: undecided"."""

from __future__ import annotations

import math

from click.testing import CliRunner

import hapstab as h
from hapstab.cli.main import cli
from hapstab.simulation.growth import BoundednessVerdict


def _v(verdict, behaviour, confidence, basis, rate=-1.0):
    return BoundednessVerdict(verdict, rate, 0.0, confidence, basis, 1.0, 0.0, "why",
                              behaviour=behaviour)


def test_the_verdicts_read_as_sentences():
    assert _v("bounded", "undecided", "high", "bound").words() == \
        "bounded, its pattern not yet settled (high confidence, proved by a bound of the model)"
    assert _v("undecided", "undecided", "low", "trajectory").words() == \
        "undecided: the run is too short to tell (low confidence, from the trajectory)"
    assert _v("bounded", "settles", "high", "rate estimate").words() == \
        "bounded: settles (high confidence, from the decay rate)"
    assert _v("marginal", "marginal", "medium", "rate estimate").words() == \
        "marginal (medium confidence, from the decay rate)"
    for v in (_v("bounded", "undecided", "high", "bound"),
              _v("undecided", "undecided", "low", "trajectory")):
        assert "undecided (" not in v.words() and "undecided: undecided" not in v.words()


def test_a_run_at_rest_has_no_growth_rate_to_print():
    v = _v("bounded", "", "high", "observed", rate=-math.inf)
    assert v.behaviour == "at rest" and v.rate_words() == "none: nothing moves"
    out = CliRunner().invoke(cli, ["simulate", "hve", "-K", "5", "--duration", "0.5",
                                   "--force", "none"])
    assert out.exit_code == 0, out.stderr
    assert "-inf" not in out.stdout and "none: nothing moves" in out.stdout
    assert "bounded: at rest (high confidence, observed)" in out.stdout


def test_the_quantisation_condition_says_what_the_gain_margin_means():
    """Not "gain margin must be below 2.115: here 1.25" (which reads as a requirement on
    the user) but what the comparison implies for this loop."""
    import json

    out = CliRunner().invoke(cli, ["limit-cycle", "hve", "-K", "8", "-n", "10",
                                   "--resolution", "1e-4", "--json"])
    assert out.exit_code == 0, out.stderr
    text = json.loads(out.stdout)["conditions"]
    assert "must be below that" not in text
    assert "a cycle is possible only where the loop's gain margin" in text
    assert "below it, so quantisation can sustain a cycle there" in text


def test_a_short_runs_figure_title_is_a_sentence():
    """The simulation figure's title is the verdict's words: a run too short to tell is
    not titled "undecided: undecided"."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    import hapstab as h

    r = h.simulate(h.paper_hve(1e-3, 10).with_stiffness(9.0), 0.008, initial_position=0.01)
    assert r.verdict.verdict == "undecided" and r.verdict.behaviour == "undecided"
    title = np.ravel(r.plot())[0].get_title()
    assert "undecided: the run is too short to tell (low confidence" in title
    assert "undecided: undecided" not in title
    plt.close("all")


def test_kmax_zero_with_a_stable_window_higher_up_says_so():
    # issue 26 item 2's PEB: 4 poles outside as K -> 0+, stable for K in [23.07, 142.05]:
    # K_max is 0, but "unstable for every K > 0" would be false
    loop = h.TeleoperationLoop(h.Device(0.13749381169616529, 0.0),
                               h.Device(0.23273843177103054, 0.0), h.SpringDamper(1.0, 0.0),
                               h.SpringDamper(1.0, 0.0), h.spring(459.7312419258073),
                               h.spring(374.8968065578325), 0.000890594778822135, 34)
    res = h.critical_stiffness(loop)
    assert res.critical_stiffness == 0.0
    assert res.stable_intervals and 23.07 < res.stable_intervals[0][0] < 23.08
    assert "unstable for every K" not in res.reason
    assert "so K_max = 0; stable for K in [23.0708" in res.reason
