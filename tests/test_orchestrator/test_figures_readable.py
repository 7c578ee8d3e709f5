"""The run figures as a reader meets them, checked on the matplotlib objects (not the PNG):
errors in millimetres and never an offset axis, a floor instead of round-off autoscaled,
legends outside the data, events marked, empty panels left out, actuators zoomed on what they
did with commands and measurements both, solve times as a distribution with host preemption
told apart from solver work."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from orchestrator.master import run
from orchestrator.output.plots import actuators_figure, tracking_figure
from orchestrator.output.run_result import RunResult
from orchestrator.output.timing_figure import (
    HIST_BASELINE,
    PREEMPTION_FACTOR,
    disturbance_timing_figure,
    preempted,
)
from orchestrator.runner import prepare
from plant.airframe import load_airframe


@pytest.fixture(scope="module")
def fault():
    return run(prepare("rotor_failure_detected", duration=4.0), timing=True)


@pytest.fixture(scope="module")
def hover():
    return run(prepare("hover", duration=2.0), timing=False)


def drawn(fig):
    FigureCanvasAgg(fig).draw()
    return fig


def vlines_at(ax):
    return sorted({float(line.get_xdata()[0]) for line in ax.get_lines()
                   if len(line.get_xdata()) == 2 and line.get_xdata()[0] == line.get_xdata()[1]})


def data_axes(fig):
    return [ax for ax in fig.axes if ax.get_lines() or ax.patches]


def test_tracking_in_mm_without_offsets_and_with_events(fault):
    fig = drawn(tracking_figure(fault))
    axs = fig.axes
    assert "[mm]" in axs[6].get_ylabel()  # the position error panel
    for ax in axs:
        assert ax.yaxis.get_offset_text().get_text() == "", ax.get_ylabel()
    # the fault and its detection, at their times, on every time panel
    t_fault = 2.0
    t_found = float(fault.time[np.nonzero(fault.get("ctrl.rotors_detected"))[0][0]])
    for ax in axs:
        marks = vlines_at(ax)
        assert pytest.approx(t_fault) in marks and pytest.approx(t_found) in marks
    # the error panel's maximum is the millimetre maximum of the data
    err = 1e3 * np.linalg.norm(fault.get("plant.pos") - fault.get("ctrl.pos_ref_s"), axis=1)
    labels = [t.get_text() for t in fig.legends[0].texts]
    assert any(lab.startswith(f"max error {err.max():.1f} mm at ") for lab in labels), labels


def test_legends_never_inside_the_plots(fault):
    for fig in (tracking_figure(fault), actuators_figure(fault),
                disturbance_timing_figure(fault)):
        drawn(fig)
        renderer = fig.canvas.get_renderer()
        for ax in fig.axes:
            legend = ax.get_legend()
            if legend is None or ax.get_xscale() == "log":  # histograms: corner legends
                continue
            box, frame = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
            assert box.x0 >= frame.x1 - 1, (fig.texts, ax.get_ylabel())
        for legend in fig.legends:
            box = legend.get_window_extent(renderer)
            for ax in fig.axes:
                assert box.y1 <= ax.get_window_extent(renderer).y0 + 1  # below every plot


def test_a_zero_signal_shows_its_floor(hover):
    fig = drawn(tracking_figure(hover))
    err_att = fig.axes[7]
    lo, hi = err_att.get_ylim()
    assert hi - lo >= 0.1  # deg: not 1e-14 of round-off
    lo, hi = fig.axes[6].get_ylim()
    assert hi - lo >= 0.1  # mm


def test_actuators_zoomed_on_their_activity_with_both_traces(fault):
    af = load_airframe("paper_hexacopter")
    fig = drawn(actuators_figure(fault, af))
    omega = fig.axes[2]
    rpm = 60 / (2 * np.pi)
    both = np.concatenate([fault.get("ctrl.omega_cmd")[:, :6], fault.get("plant.omega")[:, :6]])
    lo, hi = omega.get_ylim()
    span = rpm * (both.max() - both.min())
    assert lo <= rpm * both.min() and hi >= rpm * both.max()
    assert hi - lo <= 1.3 * span  # zoomed: the activity fills the axis
    styles = {line.get_linestyle() for line in omega.get_lines() if len(line.get_xdata()) > 2}
    assert {"-", ":"} <= styles  # commands solid, measured dotted
    labels = [t.get_text() for t in omega.get_legend().texts]
    assert f"limit {rpm * af.omega_max:.0f} rpm (off scale)" in labels
    assert "[rpm]" in omega.get_ylabel()


def test_disturbance_panels_only_where_something_acts(fault, hover):
    fig = disturbance_timing_figure(fault)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert not any(lab.startswith(("a_d", "f_d", "tau_d")) for lab in labels)  # none acts
    assert "rotor efficiency [-]" in labels
    quiet = disturbance_timing_figure(hover)
    assert [ax.get_ylabel() for ax in quiet.axes] == ["iterations [-]"]  # timing was off


def test_solve_times_as_a_distribution_with_preemption_told_apart(fault):
    fig = drawn(disturbance_timing_figure(fault))
    hists = [ax for ax in fig.axes if ax.get_xscale() == "log"]
    assert len(hists) == 2
    for ax, key, iters in zip(hists, ("t_guid", "t_alloc"), ("guid_iter", "alloc_iter"),
                              strict=True):
        t = fault.get(f"ctrl.{key}")
        us = 1e6 * t[t > 0]
        texts = [x.get_text() for x in ax.get_legend().texts]
        for q in (50, 99):
            assert f"p{q} {np.percentile(us, q):.2f} us" in texts
        assert not any("MATLAB" in x for x in texts)
        # the preemption rule, recomputed here: above 5x its iteration count's median
        it = fault.get(f"ctrl.{iters}")[t > 0]
        expect = np.zeros(us.size, bool)
        for k in np.unique(it):
            sel = it == k
            expect[sel] = us[sel] > PREEMPTION_FACTOR * np.median(us[sel])
        np.testing.assert_array_equal(preempted(t[t > 0], it), expect)
        # every solve counted once: the outlines' heights, empty bins at the baseline aside
        heights = np.concatenate([p.get_data().values for p in ax.patches])
        assert heights[heights >= 1].sum() == us.size
        assert np.all((heights >= 1) | (heights == HIST_BASELINE))


def test_noisy_run_draws_the_truth_over_faint_measurements():
    r = run(prepare("hover", duration=1.0, settings=["plant.noise_pos=0.002",
                                                     "plant.noise_seed=3"]), timing=False)
    fig = tracking_figure(r)
    labels = [t.get_text() for t in fig.legends[0].texts]
    assert "true" in labels and "measured (sensors)" in labels
    faint = [line for line in fig.axes[0].get_lines() if line.get_label() == "measured (sensors)"]
    assert faint and faint[0].get_alpha() is not None and faint[0].get_alpha() < 0.5


def test_force_set_figure_spelled_out_large_and_uncovered():
    from controller.plots_force_sets import force_set_figure
    from orchestrator.output.plots import force_sets

    af = load_airframe("paper_hexacopter")
    afs, s0 = force_sets(af)
    fig = drawn(force_set_figure(af, afs, s0))
    renderer = fig.canvas.get_renderer()
    ax3, ax2 = fig.axes
    labels = [t.get_text() for ax in (ax3, ax2) for t in ax.get_legend().texts]
    assert any(lab.startswith("attainable force set, AFS") for lab in labels)
    assert "attainable force set (AFS) slice" in labels
    # the 3-D set at least 5 inches wide (it was 4.6 in a 14 x 5.6 in figure)
    assert ax3.get_window_extent(renderer).width >= 5.0 * fig.dpi
    # legends beside or below their plots, not on them
    box3, frame3 = ax3.get_legend().get_window_extent(renderer), ax3.get_window_extent(renderer)
    assert box3.y1 <= frame3.y0 + 1
    box2, frame2 = ax2.get_legend().get_window_extent(renderer), ax2.get_window_extent(renderer)
    assert box2.x0 >= frame2.x1 - 1


def test_reference_jumps_are_jumps_not_trajectories():
    """A chirp moving 3 mm per sample is a trajectory (its velocity explains it); a step is
    the one jump of position_step, at its time."""
    from orchestrator.output.events import events

    chirp = run(prepare("translation_frequency_sweep", duration=20.0), timing=False)
    assert not [e for e in events(chirp) if e.kind == "reference"]
    step = run(prepare("position_step", duration=2.0), timing=False)
    jumps = [e for e in events(step) if e.kind == "reference"]
    assert [e.time for e in jumps] == [pytest.approx(1.0)]
    # the same chirp given without its velocity (a user's positions only): still no jumps
    bare = RunResult([c for c in chirp.columns if not c.startswith("ref.vel_ref")],
                     chirp.data[:, [i for i, c in enumerate(chirp.columns)
                                    if not c.startswith("ref.vel_ref")]], chirp.meta,
                     chirp.integer)
    assert not [e for e in events(bare) if e.kind == "reference"]
