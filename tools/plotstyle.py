"""The plotting style of the tools' figures (matplotlib, no display): one size
for a figure of one axes, legends right of the axes (never over the curves),
one marker per kind of mesh, PNGs at one resolution cropped to what is drawn.

    from plotstyle import plt, FIGSIZE, MARKER, legend_outside, save, save_loglog
    fig, ax = plt.subplots(figsize=FIGSIZE)
    ax.plot(x, y, MARKER["goal"] + "-", label="goal")
    save(fig, "out/img/error.png", legend=ax)   # layout, legend outside, PNG, "wrote ..."
    save_loglog(fig, ax, path, "dofs", "error", "title")   # the same with labels and grid

Needs matplotlib (Debian's python3-matplotlib); use /usr/bin/python3.
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

DPI = 110
FIGSIZE = (6.4, 4.2)  # one axes; its legend goes right of it
# the marker of a run by the kind of its mesh: uniform, SPR-driven, goal-driven
MARKER = {"uniform": "o", "adaptive": "s", "spr": "s", "goal": "^"}


def legend_outside(ax, handles=None, labels=None, fontsize=8):
    """The legend right of the axes, never over the curves (saved with bbox_inches="tight");
    handles and labels: those given instead of the axes' own."""
    args = (handles, labels) if handles is not None else ()
    ax.legend(*args, fontsize=fontsize, loc="center left", bbox_to_anchor=(1.01, 0.5),
              frameon=False)


def save(fig, path, legend=None, layout=True):
    """Writes the figure to PATH and closes it; returns the path. layout: tight_layout first,
    before the legend (it would shrink the axes to fit the legend in); legend: the axes whose
    legend goes right of them."""
    if layout:
        fig.tight_layout()
    if legend is not None:
        legend_outside(legend)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    print("wrote %s" % path, file=sys.stderr, flush=True)
    return path


def save_loglog(fig, ax, path, xlabel, ylabel, title):
    """Labels, grid and legend (outside) of a log-log plot; writes PATH."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    return save(fig, path, legend=ax)
