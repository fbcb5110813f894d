"""Drawing the workspace: maps over the grid in centimetres with colour bars, the ground-truth
border as a line between cells, materials with a legend, the path, its start and the chosen
cell. Used by the report's figures and the notebook's step view. And a lab's recordings,
reading by reading per material (:func:`recordings_figure`).

A volume of cells is drawn a plane at a time (:class:`Plane`): one slice along z, or the view
from above (fields summed over z). Every function here takes a 2-D scenario or a plane."""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from runner.world.scenario import Scenario

#: the border line (over a 'viridis' map; over a 'hot' one, HOT_BORDER), the path, the start
#: and the chosen cell: colours that stay distinct on either map
BORDER, HOT_BORDER, PATH, START, CHOSEN = "magenta", "deepskyblue", "white", "white", "red"


def figure(figsize: tuple[float, float]) -> Any:
    """A matplotlib figure drawn by Agg, outside pyplot: no backend is switched (a notebook's
    plotting stays as it was) and nothing is kept open once the figure is dropped."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


@dataclass(frozen=True)
class Plane:
    """A plane of a volume of cells to draw: the slice at height index ``z``, or, with ``z``
    None, the view from above (a field summed over z; each column shows the material of its
    highest object, so the border drawn is the outline of the task's solid seen from above)."""

    scenario: Scenario
    z: int | None = None

    @property
    def shape(self) -> tuple[int, int]:
        nx, ny = self.scenario.shape[:2]
        return nx, ny

    @property
    def cell(self) -> float:
        return self.scenario.cell

    @property
    def materials(self) -> tuple[str, ...]:
        return self.scenario.materials

    @property
    def centres(self) -> np.ndarray:
        return self.scenario.centres

    def task_material(self, task: str) -> int:
        return self.scenario.task_material(task)

    @cached_property
    def material_map(self) -> np.ndarray:
        m = self.scenario.material_map
        if self.z is not None:
            return m[:, :, self.z]
        background = self.scenario.materials.index(self.scenario.spec.background)
        solid = m != background
        top = m.shape[2] - 1 - np.argmax(solid[:, :, ::-1], axis=2)
        seen = np.take_along_axis(m, top[..., None], axis=2)[..., 0]
        return np.where(solid.any(axis=2), seen, background)

    def field(self, values: np.ndarray) -> np.ndarray:
        """A field over the volume (flat or grid-shaped) on this plane, flat [nx * ny]."""
        grid = np.asarray(values, float).reshape(self.scenario.shape)
        return (grid[:, :, self.z] if self.z is not None else grid.sum(axis=2)).ravel()

    @property
    def label(self) -> str:
        """Where the plane is: "seen from above", or the slice's height."""
        if self.z is None:
            return "seen from above"
        return f"slice z = {(self.z + 0.5) * self.cell * 100:.1f} cm"


#: what a drawing function takes: a 2-D workspace, or a plane of a volume
View = Scenario | Plane


def view(scenario: Scenario, z: int | None = None) -> View:
    """What to draw of ``scenario``: itself on a 2-D grid; in a volume, the slice at height
    index ``z``, or (``z`` None) the volume seen from above."""
    return scenario if scenario.dims == 2 else Plane(scenario, z)


def field(view: View, values: np.ndarray) -> np.ndarray:
    """A field over the workspace as drawn on ``view`` (unchanged on a 2-D workspace)."""
    return view.field(values) if isinstance(view, Plane) else np.asarray(values, float)


def extent_cm(scenario: View) -> tuple[float, float, float, float]:
    nx, ny = scenario.shape[:2]
    return (0.0, nx * scenario.cell * 100, 0.0, ny * scenario.cell * 100)


def centre_cm(scenario: View, cells: np.ndarray | list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) in cm of flat cell indices (of a volume: the cells seen from above)."""
    xy = scenario.centres[np.asarray(cells, dtype=np.int64)] * 100
    return xy[..., 0], xy[..., 1]


def border_segments(scenario: View, task: str) -> np.ndarray:
    """Segments [n, 2, 2] (cm) between a cell of the task's material and a cell of another: the
    ground-truth discontinuity the task follows."""
    m = scenario.material_map
    target = m == scenario.task_material(task)
    size = scenario.cell * 100
    out = []
    # vertical edges between (i, j) and (i + 1, j); horizontal between (i, j) and (i, j + 1)
    i, j = np.nonzero(target[:-1, :] != target[1:, :])
    for a, b in zip(i, j, strict=True):
        x = (a + 1) * size
        out.append([[x, b * size], [x, (b + 1) * size]])
    i, j = np.nonzero(target[:, :-1] != target[:, 1:])
    for a, b in zip(i, j, strict=True):
        y = (b + 1) * size
        out.append([[a * size, y], [(a + 1) * size, y]])
    return np.array(out).reshape(-1, 2, 2)


def draw_border(ax: Any, scenario: View, task: str, colour: str = BORDER,
                width: float = 1.0) -> None:
    from matplotlib.collections import LineCollection

    ax.add_collection(LineCollection(list(border_segments(scenario, task)), colors=colour,
                                     linewidths=width, label=f"{task} border"))


def draw_map(ax: Any, values: np.ndarray, scenario: View, *, cmap: str = "viridis",
             vmin: float | None = None, vmax: float | None = None, label: str | None = None,
             title: str = "", bad: str = "0.6") -> Any:
    """A field over the grid (flat or [nx, ny]) in cm, NaN drawn grey, with a labelled colour
    bar when ``label`` is given."""
    import matplotlib

    nx, ny = scenario.shape
    colours = matplotlib.colormaps[cmap].with_extremes(bad=bad)
    image = ax.imshow(np.asarray(values, float).reshape(nx, ny).T, origin="lower",
                      extent=extent_cm(scenario), cmap=colours, vmin=vmin, vmax=vmax,
                      interpolation="nearest")
    if label:
        bar = ax.figure.colorbar(image, ax=ax, fraction=0.06, pad=0.03)
        bar.set_label(label, fontsize=7)
        bar.ax.tick_params(labelsize=6)
    if title:
        ax.set_title(title, fontsize=8)
    ax.tick_params(labelsize=6)
    return image


#: the colours of the materials a layout lays out, in the scenario's order of them
PALETTE = ["#e8dcc8", "#9ecae1", "#a1d99b", "#fdae6b", "#bcbddc", "#fc9272"]
#: and of the materials it does not lay out (a material perceived that is not there)
UNLAID = ["#8c564b", "#e377c2", "#bcbd22", "#17becf", "#393b79", "#637939", "#843c39",
          "#7b4173", "#d6616b", "#e7ba52"]


def material_colours(scenario: View) -> list[str]:
    """A colour per material of the scenario, by index: :func:`draw_materials`'s for those its
    layout lays out (of a volume: anywhere in it), darker ones for the others."""
    whole = scenario.scenario if isinstance(scenario, Plane) else scenario
    present = np.unique(whole.material_map).tolist()
    laid = iter(PALETTE * (1 + len(present) // len(PALETTE)))
    other = iter(UNLAID * (1 + len(whole.materials) // len(UNLAID)))
    return [next(laid) if m in present else next(other) for m in range(len(whole.materials))]


def draw_materials(ax: Any, scenario: View, legend: bool = True,
                   extra: list[Any] | None = None) -> None:
    """The true material of every cell, one colour per material present, with a legend (and
    the ``extra`` handles after the materials)."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    # the colours of the whole workspace, so that every plane of a volume shows a material alike
    whole = scenario.scenario if isinstance(scenario, Plane) else scenario
    present = list(dict.fromkeys(np.unique(whole.material_map).tolist()))
    palette = PALETTE
    index = np.searchsorted(present, scenario.material_map)
    ax.imshow(index.T, origin="lower", extent=extent_cm(scenario), interpolation="nearest",
              cmap=ListedColormap(palette[: len(present)]), vmin=-0.5, vmax=len(present) - 0.5)
    if legend:
        handles = [Patch(facecolor=palette[i], edgecolor="0.4", label=scenario.materials[m])
                   for i, m in enumerate(present)]
        # beside the map, not over it: on a wide grid a legend inside would hide an object
        ax.legend(handles=handles + (extra or []), fontsize=6, loc="upper left",
                  bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, frameon=False)
    ax.tick_params(labelsize=6)


def path_points(scenario: View, path: list[int] | np.ndarray,
                chosen: int | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(x, y) in cm of what :func:`draw_path` draws, in its order: the path, its start, the
    chosen cell (when given) and, on a slice of a volume, the probes that lie in the slice."""
    path = np.asarray(path, dtype=np.int64)
    px, py = centre_cm(scenario, path)
    out = [(px, py), (px[:1], py[:1])]
    if chosen is not None:
        out.append(centre_cm(scenario, [chosen]))
    if isinstance(scenario, Plane) and scenario.z is not None:
        here = np.unravel_index(path, scenario.scenario.shape)[2] == scenario.z
        out.append((px[here], py[here]))
    return out


def draw_path(ax: Any, scenario: View, path: list[int] | np.ndarray,
              chosen: int | None = None) -> list[Any]:
    """The probed path (line), its start (circle) and the chosen next cell (star); on a slice
    of a volume the path is seen from above (faint) and the probes in the slice are dots.
    Returns the lines drawn, in the order of :func:`path_points`."""
    points = path_points(scenario, path, chosen)
    sliced = isinstance(scenario, Plane) and scenario.z is not None
    styles = [("-", {"color": PATH, "lw": 0.7, "alpha": 0.45 if sliced else 1.0,
                     "label": "path, seen from above" if sliced else "path"}),
              ("o", {"mfc": "none", "mec": START, "ms": 5, "mew": 1.2, "label": "start"})]
    if chosen is not None:
        styles.append(("*", {"color": CHOSEN, "ms": 9, "mec": "black", "mew": 0.4,
                             "label": "next cell"}))
    if sliced:
        styles.append(("o", {"color": PATH, "ms": 2.5, "mew": 0, "label": "probes in this slice"}))
    return [ax.plot(x, y, marker, **style)[0]
            for (x, y), (marker, style) in zip(points, styles, strict=True)]


def axes_in_cm(axes: np.ndarray) -> None:
    """Axis labels in cm on the left column and the bottom row of a grid of panels."""
    rows, cols = axes.shape
    for r in range(rows):
        for c in range(cols):
            ax = axes[r, c]
            ax.set_xlabel("x (cm)" if r == rows - 1 else "", fontsize=7)
            ax.set_ylabel("y (cm)" if c == 0 else "", fontsize=7)


def recordings_figure(frame: Any, material_column: str, readings: Sequence[str], path: Path,
                      title: str | None = None, discrete: Collection[str] = ()) -> None:
    """A lab's recordings (a DataFrame, or a CSV or Parquet file: one row per press) drawn
    reading by reading into ``path``: every pair of ``readings`` per material (one colour
    each, with a legend), each reading's histogram per material on the diagonal (a discrete
    reading, or one named in ``discrete``: the count of each state), a press's missing
    readings left out pair by pair (:func:`bayesprog.views.draw.scatter_matrix`)."""
    from bayesprog import scatter_matrix

    scatter_matrix(frame, by=material_column, columns=list(readings), discrete=discrete,
                   title=title).savefig(path, dpi=110)
