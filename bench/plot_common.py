"""What the benchmark plots share (plot_resolution.py, plot_filter_curve.py):
the line colours and reading a table's number. Standard library only."""
import math

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]


def number(text):
    """The finite float in `text`, else None (n/a, empty, inf, nan)."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
