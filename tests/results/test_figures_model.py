"""Issue #12: figures that show the finding -- the model in the title of region and
simulation plots; the wall, the penetration and the applied force on a simulation."""

import matplotlib

matplotlib.use("Agg")

import hapstab as h
from hapstab.models.loops import headline

LOOP = h.HapticLoop(h.Device(0.3, 0.5), operator=h.mass_spring_damper(0.5, 5, 500),
                    period=1e-3).with_delay_s(0.02)


def _title(ax):
    return " ".join(ax.get_title().split())


def test_the_region_title_names_the_model():
    ax = h.stability_region(LOOP, (0, 500), (0, 5), resolution=8).plot()
    assert "device 0.3 kg, 0.5 N*s/m; operator msd m=0.5 kg" in _title(ax)
    assert "t_d = 20 ms (20 samples)" in _title(ax)


def test_a_wall_contact_shows_the_wall_the_penetration_and_the_applied_force():
    run = h.simulate(LOOP.with_stiffness(200.0), 1.0, force="step:2", wall=0.0)
    ax1, ax2, _ = run.plot()
    assert " ".join(headline(LOOP).split()) in _title(ax1) and "n = 20:" in _title(ax1)
    labels1 = [t.get_text() for t in ax1.get_legend().get_texts()]
    labels2 = [t.get_text() for t in ax2.get_legend().get_texts()]
    assert "wall at 0 m" in labels1 and "penetration" in labels1
    assert "applied force on device" in labels2 and ax2.get_ylabel() == "force (N)"


def test_a_run_without_a_force_draws_no_applied_force():
    run = h.simulate(LOOP.with_stiffness(200.0), 0.5, initial_position=0.01)
    labels2 = [t.get_text() for t in run.plot()[1].get_legend().get_texts()]
    assert labels2 == ["u device"]


def test_the_simulation_summary_states_the_swing_at_the_start_and_the_end():
    run = h.simulate(LOOP.with_stiffness(1.2 * h.critical_stiffness(LOOP).critical_stiffness),
                     8.0, force="step:2")
    s = run.summary()
    assert s["swing_end_m_device"] > 20 * s["swing_start_m_device"] > 0   # visibly grows


def test_unequal_delays_show_both_in_samples_too():
    # `hapstab kmax peb --delay-forward 2 --delay-backward 5` said "t_d = 2 ms / 5 ms
    # (2 samples)": the samples named the forward delay only
    loop = h.paper_peb(delay_samples=2).with_delays_s(2e-3, 5e-3)
    assert "t_d = 2 ms / 5 ms (2 / 5 samples)" in headline(loop)
    assert "t_d = 2 ms (2 samples)" in headline(h.paper_peb(delay_samples=2))
