"""The figures of a session's report (:mod:`runner.report.session`): the path over the layout,
and the final maps of the replay. Each function returns the matplotlib Figure it drew (drawn by
Agg, outside pyplot: :func:`runner.report.figures.figure`); in a volume of cells the path is
seen from above and the maps are the horizontal slice that holds the most probes (the last
probe and the next cell drawn where they are seen from above)."""

from __future__ import annotations

from typing import Any

import numpy as np

from runner.report import figures

#: the marks of the path figure: the start, the last probe, a probe with a missing reading and
#: one with a warning (colours apart from the layout's pastel materials and from each other)
START, END, MISSING, WARNED = "#1b9e77", "#7570b3", "#d95f02", "#e7298a"
#: the largest side of a map, inches
MAP_INCHES = 6.0


def _map_size(view: figures.View, largest: float) -> tuple[float, float]:
    nx, ny = view.shape
    scale = largest / max(nx, ny)
    return nx * scale, ny * scale


def path_figure(session: Any, title: str = "") -> Any:
    """The probes of ``session`` (a :class:`runner.report.session.LoggedSession`) in order over the layout's true materials (a legend by
    material) and the task's ground-truth border: a line through the probed cells with one
    marker per probe (labelled ``probes``, coloured by step), the start and the last probe
    marked, probes with a missing reading or a warning marked over theirs."""
    from matplotlib.lines import Line2D

    view = figures.view(session.scenario, None)  # a volume: seen from above
    width, height = _map_size(view, MAP_INCHES)
    # the map, the legend beside it (about 2 in) and the bar of steps under it (1 in)
    size = (width + 2.9, height + 1.5)
    fig = figures.figure(size)
    ax = fig.add_axes((0.7 / size[0], 1.1 / size[1], width / size[0], height / size[1]))
    path = session.flat()
    x, y = figures.centre_cm(view, path)
    missing = np.array([any(v is None for v in p.readings.values()) for p in session.probes])
    warned = np.array([bool(p.warnings) for p in session.probes])
    ax.plot(x, y, "-", color="0.2", lw=0.8, alpha=0.7, zorder=3)
    steps = np.arange(len(path))
    dots = ax.scatter(x, y, c=steps, cmap="plasma", s=9, linewidths=0.3, edgecolors="0.15",
                      zorder=4, label="probes")
    handles = [Line2D([], [], color="black", lw=1.2, label=f"{session.task} border"),
               Line2D([], [], color="0.2", lw=0.8, marker="o", ms=3, mfc="0.5", mec="0.15",
                      label=f"probes in order ({len(path)})")]
    marks = [(x[:1], y[:1], {"marker": "^", "ms": 10, "mfc": START, "mec": "black",
                             "mew": 0.8, "ls": "", "label": "start"}),
             (x[-1:], y[-1:], {"marker": "s", "ms": 8, "mfc": END, "mec": "black",
                               "mew": 0.8, "ls": "", "label": "last probe"}),
             (x[missing], y[missing], {"marker": "o", "ms": 7, "mfc": "none", "mec": MISSING,
                                       "mew": 1.3, "ls": "",
                                       "label": f"a reading missing ({int(missing.sum())})"}),
             (x[warned], y[warned], {"marker": "x", "ms": 7, "color": WARNED, "mew": 1.6,
                                     "ls": "", "label": f"a warning ({int(warned.sum())})"})]
    for mx, my, style in marks:
        line, = ax.plot(mx, my, zorder=5, **style)
        handles.append(line)
    figures.draw_materials(ax, view, extra=handles)
    figures.draw_border(ax, view, session.task, colour="black", width=1.2)
    ax.set_xlabel("x (cm)", fontsize=7)
    ax.set_ylabel("y (cm)", fontsize=7)
    # under the map as drawn (its box shrinks to the grid's aspect), below the axis label
    cax = ax.inset_axes((0.0, -0.75 / height, 1.0, 0.12 / height))
    bar = fig.colorbar(dots, cax=cax, orientation="horizontal")
    bar.set_label("step k", fontsize=7)
    bar.ax.tick_params(labelsize=6)
    where = f" ({view.label})" if isinstance(view, figures.Plane) else ""
    ax.set_title(f"{title}: the path{where}", fontsize=8)
    return fig


def maps_figure(session: Any, replayed: Any, title: str = "") -> Any:
    """The final maps of the replay ``replayed`` (a :class:`runner.report.session.Replay` of
    ``session``): the belief P(M = the task's material) and the material
    decided at each probed cell (a cross where it is not the layout's), the posterior over
    the next cell, and the last decision's cues (inhibition, saliency, uncertainty), each with
    its colour bar; the border, the path and the next cell over the heat maps."""
    from matplotlib import patheffects
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D

    scenario = session.scenario
    explorer = replayed.explorer
    decision = explorer.decision
    chosen = int(decision.next_cell[0])
    path = session.flat()
    z = None
    if scenario.dims == 3:  # the slice that holds the most probes (the last one's, on a tie)
        heights = np.unravel_index(path, scenario.shape)[2]
        counts = np.bincount(heights)
        z = int(heights[-1]) if counts[heights[-1]] == counts.max() else int(counts.argmax())
    view = figures.view(scenario, z)
    width, height = _map_size(view, 3.4)
    fig = figures.figure((3 * (width + 1.3) + 0.3, 2 * (height + 0.8)))
    axes = fig.subplots(2, 3)
    where = f", {view.label}" if isinstance(view, figures.Plane) else ""
    material = scenario.materials[explorer.target_material]
    heat = [(axes[0, 0], explorer.belief()[0], f"belief P(M = {material})",
             "probability (grey: not probed)", (0, 1)),
            (axes[0, 2], explorer.target_probabilities[0], "P(O | t, i, s, u, R) (eq. 13)",
             "probability per cell", None),
            (axes[1, 0], decision.inhibition[0], "inhibition I (eq. 10)",
             "I: inhibition level", (0, 1)),
            (axes[1, 1], decision.saliency[0], "saliency S (eq. 12)",
             "S (grey: not observed)", (0, 1)),
            (axes[1, 2], decision.uncertainty[0], "uncertainty U (eq. 11)",
             "U: normalised entropy", (0, 1))]
    for ax, values, name, label, limits in heat:
        shown = figures.field(view, values)
        low, high = limits or (0.0, float(np.nanmax(shown)) if np.isfinite(shown).any() else 1.0)
        figures.draw_map(ax, shown, view, vmin=low, vmax=high or 1.0, label=label,
                         title=name + where)
        figures.draw_border(ax, view, session.task, width=0.9)
        _draw_ends(ax, view, path, chosen)
    # the material decided: the MAP of every probed cell, in the layout's colours
    ax = axes[0, 1]
    visited = explorer.visits[0] > 0
    best = np.where(visited, explorer.posterior[0].argmax(axis=1), -1)
    if z is not None:  # the slice's cells (a volume's view from above would mix heights)
        best = best.reshape(scenario.shape)[:, :, z].ravel()
    names = [int(m) for m in np.unique(best[best >= 0])]
    colours = figures.material_colours(scenario)
    index = np.array([names.index(m) if m >= 0 else np.nan for m in best], float)
    cmap = ListedColormap([colours[m] for m in names] or ["white"]).with_extremes(bad="0.6")
    bounds = np.arange(len(names) + 1) - 0.5 if names else np.array([-0.5, 0.5])
    image = ax.imshow(index.reshape(view.shape).T, origin="lower", cmap=cmap,
                      norm=BoundaryNorm(bounds, cmap.N), extent=figures.extent_cm(view),
                      interpolation="nearest")
    bar = fig.colorbar(image, ax=ax, fraction=0.06, pad=0.03,
                       ticks=np.arange(len(names)) if names else [])
    bar.ax.set_yticklabels([scenario.materials[m] for m in names], fontsize=6)
    truth = view.material_map.ravel()
    wrong = np.flatnonzero((best >= 0) & (best != truth))
    wx, wy = np.unravel_index(wrong, view.shape)  # cells of the view's grid (a slice's)
    size = view.cell * 100
    ax.plot((wx + 0.5) * size, (wy + 0.5) * size, "x", color="black", ms=3, mew=0.7,
            path_effects=[patheffects.withStroke(linewidth=1.6, foreground="white")])
    figures.draw_border(ax, view, session.task, colour="black", width=0.8)
    _draw_ends(ax, view, path, chosen)
    ax.set_title(f"material decided{where}\n(grey: not probed; x: not the layout's)",
                 fontsize=8)
    ax.tick_params(labelsize=6)
    fig.legend(handles=[Line2D([], [], ls="", marker="s", ms=6, mfc=END, mec="black",
                               label="the last probe"),
                        Line2D([], [], ls="", marker="*", ms=9, mfc=figures.CHOSEN,
                               mec="black", mew=0.4, label="the next cell"),
                        Line2D([], [], color=figures.BORDER, label=f"{session.task} border "
                               "(black on the materials)")],
               loc="lower center", ncol=3, fontsize=7, frameon=False)
    figures.axes_in_cm(axes)
    fig.suptitle(f"{title}: the maps after the last probe (step "
                 f"{session.probes[-1].step}), replayed", fontsize=10)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return fig


def _draw_ends(ax: Any, view: figures.View, path: np.ndarray, chosen: int) -> None:
    """The last probe (a square, as on the path figure) and the next cell (a star)."""
    lx, ly = figures.centre_cm(view, path[-1:])
    ax.plot(lx, ly, "s", ms=5, mfc=END, mec="black", mew=0.6)
    nx, ny = figures.centre_cm(view, [chosen])
    ax.plot(nx, ny, "*", ms=9, color=figures.CHOSEN, mec="black", mew=0.4)
