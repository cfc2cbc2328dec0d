"""One look for every chart and number the kit prints: the floor, the number format, the
marks, a colour per run kind and the resolution charts are saved at.

Used by scenarios.output.report, scenarios.paper_forces, scenarios.mechanism3t_charts and the
studies, so that "1 nm", "5.44 µm" and "moving-base blue" mean the same on every page."""
import functools
import pathlib

import numpy as np

# Errors below 1 nm (1 nrad) are finer than a rigid-body model without joint play,
# compliance or sensor noise resolves, and far below any metrology: log axes stop there
# and such numbers are written "< 1 nm", not as round-off ("5.71e-07 µm").
FLOOR = 1e-3                                  # in µm (and µrad)
FLOOR_NOTE = "log axes floored at 1 nm: finer than this rigid-body model resolves (no joint play, compliance or noise)"
MARKS_UM = {"10 µm": 10.0, "0.1 mm": 100.0}   # pose requirements: focus, hexapod metrology
MARK_COLOUR = "#d62728"
MARK_STYLES = {"10 µm": ":", "0.1 mm": "--"}
# one colour per run kind wherever a run kind is drawn
RUN_COLOURS = {"none": "#7f7f7f", "fixed_base": "#ff7f0e", "moving_base": "#1f77b4"}
RUN_NAMES = {"none": "no feedforward", "fixed_base": "fixed-base model", "moving_base": "moving-base model"}
OTHER_COLOURS = ("#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
# A chart is read on a screen about 1000-1300 px wide; 100 dpi on figures of 10-13 in
# gives that, and savefig (most of a chart's time) costs less than at 110-130 dpi.
DPI = 100


def run_colour(kind, k=0):
    """The colour of a run kind (fixed_base, moving_base, none); the k-th other colour else."""
    return RUN_COLOURS.get(kind, OTHER_COLOURS[k % len(OTHER_COLOURS)])


def fmt(value):
    """A number as every report prints it: 3 significant digits ('n/a' for NaN)."""
    if isinstance(value, float):
        return "n/a" if value != value else f"{value:.3g}"
    return str(value)


def length(value_um, unit="µm"):
    """An error in µm (or µrad) as text: '5.44 µm', '< 1 nm' under the floor, 'n/a' for NaN."""
    if value_um != value_um:
        return "n/a"
    if value_um < FLOOR:
        return "< 1 nm" if unit == "µm" else "< 1 nrad"
    return f"{fmt(float(value_um))} {unit}"


def cell(value_um, unit="µm"):
    """A table cell of an error whose unit the column names: the number, or '< 1 nm'
    ('< 1 nrad') under the floor."""
    text = length(value_um, unit)
    return text[:-len(unit) - 1] if text.endswith(" " + unit) else text


def ratio(a, b):
    """a / b as 'Nx', 3 significant digits, no exponent (the same text wherever a ratio is printed)."""
    x = float(f"{a / max(b, 1e-300):.3g}")
    return f"{x:.0f}x" if x >= 100 else f"{x:g}x"


@functools.cache
def _plain_log_locator():
    """plain_log_axis's locator class, made on first use: matplotlib is imported by what
    draws (a run without charts does not pay its import, docs/speed.md)."""
    from matplotlib import ticker

    class PlainLogLocator(ticker.Locator):
        """Ticks at ``subs`` per decade while the axis spans at most 4 decades; wider, at whole
        decades only, every n-th so that about 10 remain (matplotlib's LogLocator drops every
        tick when it must thin decades with several subs)."""

        def __init__(self, subs):
            self.subs = subs

        def __call__(self):
            return self.tick_values(*self.axis.get_view_interval())

        def tick_values(self, vmin, vmax):
            vmin, vmax = sorted((vmin, vmax))
            if not vmin > 0:
                return []
            lo, hi = int(np.floor(np.log10(vmin))), int(np.ceil(np.log10(vmax)))
            subs = self.subs if hi - lo <= 4 else (1.0,)
            stride = max(1, int(np.ceil((hi - lo) / 10)))
            return [s * 10.0 ** d for d in range(lo - lo % stride, hi + 1, stride) for s in subs]

    return PlainLogLocator


def plain_log_axis(axis, subs=(1.0, 2.0, 5.0)):
    """Label a log axis at 1, 2, 5 per decade (decades alone over a wide range) in plain
    numbers (0.01, 2, 500), not 10^n; numbers under 1e-4 or over 1e6 as 1e-09."""
    from matplotlib import ticker
    axis.set_major_locator(_plain_log_locator()(subs))
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(ticker.NullFormatter())


def draw_marks(ax, top=None, vertical=False):
    """The 10 µm and 0.1 mm marks as red lines, each named at its end; on a µm axis of
    pose (platform position) error only. With ``top``, a mark above 3x top is left out.
    Returns the marks drawn."""
    drawn = []
    for text, level in MARKS_UM.items():
        if top is not None and level > 3 * top:
            continue
        if vertical:
            ax.axvline(level, color=MARK_COLOUR, lw=1, ls=MARK_STYLES[text], zorder=1)
            ax.text(level, 1.0, f" {text}", transform=ax.get_xaxis_transform(), ha="left", va="bottom",
                    fontsize=8, color=MARK_COLOUR)
        else:
            ax.axhline(level, color=MARK_COLOUR, lw=1, ls=MARK_STYLES[text], zorder=1)
            ax.text(1.0, level, f" {text}", transform=ax.get_yaxis_transform(), ha="left", va="center",
                    fontsize=8, color=MARK_COLOUR)
        drawn.append(text)
    return drawn


def label_points(ax, xs, ys, texts, fontsize=7, color="0.25"):
    """Write each text beside its point where it covers no other label and no marker of
    the axes: the first free place of eight around the point (right-above first), else
    the least covered one. Call it when the axes' scales and limits are final. Returns
    the annotations."""
    fig = ax.figure
    fig.canvas.draw()                                   # the final layout: display coordinates hold
    renderer = fig.canvas.get_renderer()
    to_px = fig.dpi / 72.0
    markers = [ax.transData.transform(c.get_offsets()) for c in ax.collections if len(c.get_offsets())]
    markers = np.concatenate(markers) if markers else np.empty((0, 2))
    radius = 5 * to_px
    placed, notes = [], []
    for x, y, text in zip(xs, ys, texts):
        px, py = ax.transData.transform((x, y))
        probe = ax.text(0, 0, text, fontsize=fontsize)
        box = probe.get_window_extent(renderer)
        probe.remove()
        w, h, gap = box.width, box.height, 4 * to_px
        candidates = [(gap, gap), (gap, -h - gap), (-w - gap, gap), (-w - gap, -h - gap),
                      (-w / 2, 2 * gap), (-w / 2, -h - 2 * gap), (2 * gap, -h / 2), (-w - 2 * gap, -h / 2)]

        def covered(dx, dy):
            x0, y0 = px + dx, py + dy
            hits = sum(x0 < bx1 and bx0 < x0 + w and y0 < by1 and by0 < y0 + h for bx0, by0, bx1, by1 in placed)
            near = ((markers[:, 0] > x0 - radius) & (markers[:, 0] < x0 + w + radius)
                    & (markers[:, 1] > y0 - radius) & (markers[:, 1] < y0 + h + radius))
            return 2 * hits + int(near.sum())

        dx, dy = min(candidates, key=lambda c: (covered(*c) > 0, covered(*c), candidates.index(c)))
        placed.append((px + dx, py + dy, px + dx + w, py + dy + h))
        notes.append(ax.annotate(text, (x, y), xytext=(dx / to_px, dy / to_px), textcoords="offset points",
                                 fontsize=fontsize, color=color, ha="left", va="bottom"))
    return notes


def save(fig, path, **kwargs):
    """Save at the kit's resolution (a figure made by pyplot, as the studies make them, is
    then closed). PNG compression level 1: the file ~1.3x larger than at the default 6,
    its encoding several times cheaper (docs/speed.md)."""
    kind = kwargs.get("format") or (pathlib.Path(path).suffix[1:] if isinstance(path, (str, pathlib.Path)) else "png")
    if kind == "png":
        kwargs.setdefault("pil_kwargs", {"compress_level": 1})
    fig.savefig(path, dpi=DPI, **kwargs)
    if fig.canvas.manager is not None:
        import matplotlib.pyplot as plt
        plt.close(fig)
