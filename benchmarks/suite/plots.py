"""Plots of the 2D sections: work-precision and mortar time against slave facets."""

from __future__ import annotations

import pathlib

import numpy as np

from .work_precision import CASES


def plot_work_precision(data: dict, path: pathlib.Path, error_key: str | None = None,
                        time_key: str = "wall") -> None:
    """Error against the median solve time (wall, or process CPU with time_key="cpu")."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in CASES if error_key is None or CASES[c]["demo"] == "hertz"]
    width = 5.2 * len(cases) + 1.7
    fig, axes = plt.subplots(1, len(cases), figsize=(width, 4.6), squeeze=False)
    colours = plt.get_cmap("tab20").colors
    markers = "os^vD<>pPX*h"
    handles = {}
    for ax, case_name in zip(axes[0], cases, strict=True):
        key = error_key or CASES[case_name]["error"]
        for index, variant in enumerate(data["variants"]):
            runs = sorted((r for r in data["runs"] if r["case"] == case_name
                           and r["variant"] == variant["name"] and not r["failed"]),
                          key=lambda r: r["refinement"])
            if not runs:
                continue
            x = [r["timings"]["total"] if time_key == "wall" else r["solve_cpu_s"] for r in runs]
            y = [max(r["errors"][key], 1e-16) for r in runs]
            style = "--" if variant["name"].startswith("penalty") else (
                ":" if variant["name"].startswith("element") else "-")
            (line,) = ax.loglog(x, y, style, marker=markers[index % len(markers)], ms=4,
                                color=colours[(2 * index) % 20 if index < 10 else 2 * index - 19],
                                linewidth=2.2 if variant["name"] == "default" else 1.2)
            handles.setdefault(variant["name"], line)
        ax.set_title(CASES[case_name]["title"], fontsize=10)
        ax.set_xlabel(("solve time" if time_key == "wall" else "solve CPU time")
                      + f" [s] (median; refinements {data['refinements'][0]}.."
                      f"{data['refinements'][-1]})")
        ax.set_ylabel(key.replace("_", " "))
        ax.grid(True, which="both", linewidth=0.3)
    fig.tight_layout(rect=(0, 0, 1 - 1.6 / width, 1))
    fig.legend(handles.values(), handles.keys(), loc="center right", fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)



def plot_scaling(data: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scaling = data["scaling"]
    facets = np.array([r["slave_facets"] for r in scaling], dtype=float)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    series = {
        "mortar kernels per evaluation": [r["kernel_time_per_evaluation"] for r in scaling],
        "'mortar integration' phase per Newton iteration":
            [r["per_iteration"]["mortar integration"] for r in scaling],
        "bulk assembly per Newton iteration":
            [r["per_iteration"]["bulk assembly"] for r in scaling],
        "linear solve per Newton iteration":
            [r["per_iteration"]["linear solve"] for r in scaling],
    }
    for label, values in series.items():
        ax.loglog(facets, values, "o-", label=label)
    first = series["mortar kernels per evaluation"]
    ax.loglog(facets, first[-1] * facets / facets[-1], "k:", label="slope 1")
    ax.set_xlabel("slave facets (Hertz B arc, refinements "
                  f"{scaling[0]['refinement']}..{scaling[-1]['refinement']})")
    ax.set_ylabel("time [s] (median)")
    ax.set_title("Neo-Hookean Hertz B: mortar time against slave facets", fontsize=10)
    ax.grid(True, which="both", linewidth=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


