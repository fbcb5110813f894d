"""Figures of an experiment: Gamma(k) curves (Fig. 10) and visit heat maps (Fig. 9)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from runner.scenario import Scenario


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_gamma(results: dict[str, dict], out: Path, title: str = "") -> None:
    """Gamma(k), mean +- SEM over runs, one curve per configuration."""
    from runner.experiment import mean_sem

    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for conf, res in results.items():
        mean, sem = mean_sem(np.asarray(res["gamma"]))
        k = np.arange(mean.size)
        ax.plot(k, mean, label=conf.replace("_", " "))
        ax.fill_between(k, mean - sem, mean + sem, alpha=0.25)
    ax.set_xlabel("iteration k")
    ax.set_ylabel(r"$\Gamma(k)$ [m]")
    ax.set_title(title)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def plot_visits(scenario: Scenario, task: str, results: dict[str, dict], out: Path) -> None:
    """Visit counts summed over runs per configuration, beside the task's ground-truth border."""
    plt = _plt()
    nx, ny = scenario.shape
    panels = len(results) + 1
    fig, axes = plt.subplots(1, panels, figsize=(2.2 * panels, 4.2), squeeze=False)
    extent = (0, nx * scenario.cell, 0, ny * scenario.cell)
    border = scenario.border(task).astype(float)
    ax = axes[0, 0]
    ax.imshow(scenario.material_map.T, origin="lower", extent=extent, cmap="Pastel1")
    ax.contour(border.T, levels=[0.5], colors="k", linewidths=0.8, origin="lower", extent=extent)
    ax.set_title(f"{task}: border", fontsize=9)
    for ax, (conf, res) in zip(axes[0, 1:], results.items(), strict=True):
        paths = np.asarray(res["paths"])
        counts = np.bincount(paths.ravel(), minlength=nx * ny).reshape(nx, ny)
        ax.imshow(counts.T, origin="lower", extent=extent, cmap="hot")
        ax.contour(border.T, levels=[0.5], colors="c", linewidths=0.6, origin="lower", extent=extent)
        ax.set_title(conf.replace("_", " "), fontsize=9)
    for ax in axes[0]:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
