"""What the pictures show a person: every channel named, whole tick values, colour
bars from zero, and the sensor drawn the way up a drawing of it shows.

Each picture is caught just before it is written (the figure, or the pyvista plotter
with its actors), and its parts are read back."""

import numpy as np
import pytest

import hydrotact.viz._plots as plots
import hydrotact.viz._render as render


@pytest.fixture
def caught(monkeypatch):
    """The figures and plotters the pictures would have saved, in order."""
    found = []

    def keep_figure(figure, path):
        found.append(figure)

    def keep_plotter(plotter, path):
        found.append(plotter)
        plotter.render()

    monkeypatch.setattr(plots, "save_figure", keep_figure)
    monkeypatch.setattr(render, "_save", keep_plotter)
    yield found
    for item in found:
        if hasattr(item, "close"):
            item.close()


def _absolute_log(num_channels: int):
    """A log of absolute readings near the atmosphere that move by a few pascals: the
    case where matplotlib writes '1e-8 + 1.013e2' above the axis by default."""
    from hydrotact.data import BarometerLog

    times = np.arange(200) / 100.0
    columns = {"time": times}
    for k in range(num_channels):
        columns[f"c{k:02d}"] = 101325.0 + 3.0 * np.sin(times * (k + 1))
    metadata = {"format": "hydrotact.barometer_log", "version": 1, "sensor": "test", "pressure": "absolute", "channels": list(columns)[1:], "rate_hz": 100.0}
    return BarometerLog(metadata, columns)


@pytest.mark.parametrize("num_channels", [4, 25])
def test_a_log_plot_names_every_channel_and_writes_whole_ticks(caught, num_channels):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    log = _absolute_log(num_channels)
    plots.plot_log(log, "unused.png", title="test")
    [figure] = caught
    FigureCanvasAgg(figure).draw()
    axis = figure.axes[0]
    legend = axis.get_legend()
    assert legend is not None
    assert [text.get_text() for text in legend.get_texts()] == log.metadata["channels"]
    assert axis.yaxis.get_offset_text().get_text() == "", "an offset above the axis"
    labels = [label.get_text() for label in axis.get_yticklabels() if label.get_text()]
    assert labels and all(float(text.replace("−", "-")) > 100.0 for text in labels), labels  # kPa, whole values


def test_the_contact_colour_bar_starts_at_zero_and_the_camera_looks_from_minus_y(caught):
    from hydrotact.contact import press_probe
    from hydrotact.field import solve_field_report
    from hydrotact.mesh import load_tet_mesh

    mesh = load_tet_mesh("pad5x5")
    strain, _ = solve_field_report(mesh, modulus=1e6)
    report, surface, probe, X_SP = press_probe(mesh, strain, 1e6, "cylinder:d=2mm", "0.37mm,0.11mm,0.3mm")
    render.render_contact(mesh, surface, "unused.png", probe=probe, X_SP=X_SP, title="test")
    [plotter] = caught
    low, high = plotter.scalar_bars["pressure [Pa]"].GetLookupTable().GetRange()
    assert low == 0.0 and high == pytest.approx(report["max_pressure_Pa"], rel=1e-9)

    eye, centre, up = (np.asarray(v) for v in plotter.camera_position)
    assert eye[1] < centre[1] and np.allclose(up, [0.0, 0.0, 1.0])  # from -y, z up: x runs to the right
    assert eye[2] > centre[2]  # from above: the skin is where the contact is

    render.render_mesh(mesh, "unused.png", title="pad")
    eye, centre, _ = (np.asarray(v) for v in caught[-1].camera_position)
    assert eye[1] < centre[1] and eye[2] < centre[2]  # from -y and below: the bonded base shows
    # The axes frame the half drawn (y from the cut at 0 to 6.6 mm), on its outer
    # edges: they stood on the whole pad's box before, 7.5 mm in front of the cut.
    axes = caught[-1].renderer.cube_axes_actor
    x0, x1, y0, y1, z0, z1 = axes.GetBounds()
    assert (x0, x1, y0, y1, z0, z1) == pytest.approx((-7.5, 7.5, 0.0, 8.0, 0.0, 4.0))
    assert axes.GetFlyMode() == axes.VTK_FLY_OUTER_EDGES


def test_the_lumped_fit_plots_keep_the_curve_and_the_histogram_in_view(monkeypatch):
    """relaxation.png: a term the logs do not identify (standard error 20 x its value)
    stays out of the band and is named, and the y axis holds the fitted curve (at
    most 3 x its top); residuals.png: the histogram's density axis ends near its top
    (a log axis autoscaled to 1e12 before)."""
    from types import SimpleNamespace

    import hydrotact.viz._press as press

    figures = []
    monkeypatch.setattr(press, "save_figure", lambda figure, path: figures.append(figure))
    term = lambda value, std, identified: SimpleNamespace(value=value, std=std, identified=identified)
    fit = SimpleNamespace(ratios=[term(0.05, 1.1, False), term(0.3, 0.05, True)], taus=[term(0.06, 4.1, False), term(0.46, 0.05, True)])
    press._relaxation_panel(fit, "relaxation.png")
    axis = figures[-1].axes[0]
    low, high = axis.get_ylim()
    fitted = 1.0 + 0.05 + 0.3  # E(0)/E∞
    assert low <= 1.0 and fitted < high <= 3.0 * fitted
    assert any("not identified: E1/E∞, τ1" in text.get_text() for text in axis.texts)
    rng = np.random.default_rng(0)
    residuals = [[(np.arange(500) * 0.01, rng.standard_normal(500) * (1 + c))] for c in range(3)]
    press._residual_panels(["a", "b", "c"], residuals, "residuals.png", "residuals")
    low, high = figures[-1].axes[1].get_ylim()
    assert low == 1e-5 and 0.4 < high < 2.0


def test_the_training_curve_has_whole_epochs_and_plain_loss_ticks(monkeypatch):
    """A loss within one decade (13.6 to 16) on the log axis has only minor ticks, which
    matplotlib labelled 1.36×10^1; 12 epochs were ticked at 2.5, 7.5; a position
    target's metrics had no panel."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    import hydrotact.viz._training as training

    found = []
    monkeypatch.setattr(training, "save_figure", lambda figure, path: found.append(figure))
    history = [{"epoch": k, "train_loss": 16.0 - 0.2 * k, "validation_loss": 15.5 - 0.15 * k,
                "validation_metrics": {"contact_bce": 0.3 - 0.01 * k, "x_rmse": 2e-3 - 1e-4 * k, "depth_rmse": 4e-4}} for k in range(12)]
    training.plot_training_curve(history, "unused.png", best_epoch=9, title="test")
    [figure] = found
    FigureCanvasAgg(figure).draw()
    assert [axis.get_title() for axis in figure.axes] == ["test", "position", "contact"]
    loss = figure.axes[0]
    labels = [label.get_text() for label in loss.get_yticklabels(minor=True) + loss.get_yticklabels() if label.get_text()]
    assert labels and all("10^" not in text and "times" not in text and "×" not in text for text in labels), labels
    for axis in figure.axes:
        ticks = [tick for tick in axis.get_xticks() if axis.get_xlim()[0] <= tick <= axis.get_xlim()[1]]
        assert ticks and all(float(tick).is_integer() for tick in ticks), ticks
    figure.clf()


def test_contact_detection_draws_the_true_flag_as_a_strip_not_a_force(monkeypatch):
    """The true contact flag was a line at 0 to -0.04 of the force axis, read as a
    force of ~0.02 N; it is a strip along the axis' bottom (its height the axis', not
    newtons) where the flag is set, and the force axis starts at 0."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    import hydrotact.viz._estimator as estimator

    found = []
    monkeypatch.setattr(estimator, "save_figure", lambda figure, path: found.append(figure))
    times = np.arange(200) / 50.0
    contact = ((times > 1.0) & (times < 2.5)).astype(float)
    force = 0.8 * contact * np.sin(np.pi * (times - 1.0) / 1.5).clip(0.0)
    estimator.plot_contact_detection(times, force, contact, 0.9 * contact, force, "unused.png")
    [figure] = found
    FigureCanvasAgg(figure).draw()
    for axis in figure.axes:
        assert axis.get_ylim()[0] == 0.0
        labels = [line.get_label() for line in axis.get_lines()]
        assert not any("flag" in label for label in labels), labels
        [strip] = [c for c in axis.collections if c.get_label() == "true contact"]
        heights = np.concatenate([path.vertices[:, 1] for path in strip.get_paths()])
        assert strip.get_transform() == axis.get_xaxis_transform() and set(np.round(heights, 9)) <= {0.0, 0.06}  # x in seconds, height in the axis' fraction
    figure.clf()


@pytest.mark.parametrize("panels", [1, 4])
def test_the_error_map_keeps_its_axis_labels_inside_the_picture(monkeypatch, panels):
    """One panel's θ label fell off the left edge (a margin of 6 % of the width)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    import hydrotact.viz._estimator as estimator

    found = []
    monkeypatch.setattr(estimator, "save_figure", lambda figure, path: found.append(figure))
    edges = np.radians(np.linspace(0.0, 90.0, 7)), np.radians(np.linspace(-180.0, 180.0, 13))
    entry = {"unit": "m", "theta_edges": edges[0], "phi_edges": edges[1], "mean": np.full((6, 12), 1e-3), "count": np.ones((6, 12))}
    estimator.plot_error_maps({f"model {k}": entry for k in range(panels)}, "unused.png", title="test")
    [figure] = found
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    renderer, width = canvas.get_renderer(), figure.bbox.width
    for axis in figure.axes[:panels]:
        for label in (axis.yaxis.label, axis.xaxis.label, *axis.get_yticklabels()):
            box = label.get_window_extent(renderer)
            assert label.get_text() and 0.0 <= box.x0 and box.x1 <= width, (label.get_text(), box)
    figure.clf()


def test_the_fit_traces_mark_the_readings_the_fit_masked(monkeypatch):
    """traces.png: readings at the part's range (weight 0: left out of the fit) break
    the measured line and are drawn as crosses, counted in the title; the fitted curve
    goes on through them (it drew the clipped plateau as if measured before)."""
    from types import SimpleNamespace

    import hydrotact.sysid as sysid
    import hydrotact.viz._fit as fit_plots

    figures = []
    monkeypatch.setattr(fit_plots, "save_figure", lambda figure, path: figures.append(figure))
    monkeypatch.setattr(sysid, "calc_relaxation_band", lambda result, times: (np.ones_like(times), np.ones_like(times), np.ones_like(times)))
    times = np.arange(300) / 100.0
    truth = 101325.0 + 40e3 * np.exp(-(((times - 1.5) / 0.4) ** 2))
    observed = np.column_stack([np.minimum(truth, 125000.0), 101325.0 + 0.01 * truth])
    weights = np.ones_like(observed)
    weights[observed[:, 0] >= 125000.0, 0] = 0.0
    log = SimpleNamespace(observed=observed, times=times, weights=weights, num_channels=2)
    info = SimpleNamespace(source="clipped.parquet", channels=["b22", "b23"], force_columns=[])
    result = SimpleNamespace(problem=SimpleNamespace(logs=[log], infos=[info]), predictions=lambda: [np.column_stack([truth, observed[:, 1]])],
                             reduced_chi_square=1.0, terms=[], layout=SimpleNamespace(num_terms=0))
    fit_plots.plot_fit(result, "unused")
    axis = figures[0].axes[0]
    masked = int((weights[:, 0] == 0).sum())
    assert masked > 0 and f"{masked} readings masked" in axis.get_title()
    measured = axis.get_lines()[0].get_ydata()
    assert np.isnan(measured[weights[:, 0] == 0]).all() and np.isfinite(measured[weights[:, 0] > 0]).all()
    crosses = [line for line in axis.get_lines() if line.get_marker() == "x"]
    assert len(crosses) == 1 and len(crosses[0].get_xdata()) == masked
    assert "masked: not fitted" in [text.get_text() for text in axis.get_legend().get_texts()]


@pytest.mark.parametrize("covariance", [True, False])
def test_compare_traces_draw_the_prediction_band(monkeypatch, covariance):
    """compare_traces.png: the held-out prediction with its band (model ± 2σ of the
    fit's covariance), where compare's line reports a band it did not draw before; no
    band where the fit had no covariance (NaN)."""
    from types import SimpleNamespace

    from matplotlib.collections import PolyCollection

    import hydrotact.viz._press as press

    figures = []
    monkeypatch.setattr(press, "save_figure", lambda figure, path: figures.append(figure))
    times = np.arange(400) / 50.0
    hold = np.where((times > 2) & (times < 5), 0, -1)
    predicted = 300.0 * (hold >= 0)[:, None] * np.ones((1, 2))
    std = np.full_like(predicted, 25.0 if covariance else np.nan)
    comparison = SimpleNamespace(channels=["a", "b"], hold=hold, times=times, mask=np.ones_like(predicted, dtype=bool), predicted=predicted,
                                 observed=predicted + 10.0, predicted_std=std, noise_pa=np.array([2.0, 2.0]))
    press.plot_comparisons([comparison], "unused")
    axis = figures[0].axes[0]
    fills = [item for item in axis.collections if isinstance(item, PolyCollection)]
    labels = [text.get_text() for text in axis.get_legend().get_texts()]
    if covariance:
        assert fills and "model ± 2σ (prediction band)" in labels
        top = max(path.vertices[:, 1].max() for fill in fills for path in fill.get_paths())
        assert top == pytest.approx(300.0 + 50.0)  # 2σ above the prediction, baseline off
    else:
        assert not fills and not any("band" in label for label in labels)
