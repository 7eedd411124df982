#!/usr/bin/env python3
"""Plots filter_curve.sh's table: per set (realval's, the generated scenes),
the share of the kept pixels within 2 % against the share of all
ground-truth pixels kept and within 2 %, one line per curve label, the
default (a label ending in '*') marked, as a self-contained SVG (standard
library only, so it runs wherever the benchmark does).

Usage: bench/plot_filter_curve.py filter_curve.tsv out.svg
"""
import csv
import sys

from plot_common import COLOURS, number

PANEL_W, PANEL_H = 300, 240
MARGIN_X, MARGIN_Y, GAP = 70, 50, 90


def read_sets(path):
    """{set: {curve: [(completeness, precision, is_default)]}}, in file order."""
    sets = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f, delimiter="\t"):
            x, y = number(row["within_2_all"]), number(row["precision"])
            if x is None or y is None:
                continue
            label = row["label"]
            curve = label.rstrip("*")
            sets.setdefault(row["set"], {}).setdefault(curve, []).append((x, y, label.endswith("*")))
    return sets


def axis_range(values):
    low, high = min(values), max(values)
    pad = max((high - low) * 0.1, 0.01)
    return low - pad, high + pad


def panel(x0, title, curves, legend):
    xs = [p[0] for pts in curves.values() for p in pts]
    ys = [p[1] for pts in curves.values() for p in pts]
    (x_lo, x_hi), (y_lo, y_hi) = axis_range(xs), axis_range(ys)
    sx = lambda x: x0 + (x - x_lo) / (x_hi - x_lo) * PANEL_W
    sy = lambda y: MARGIN_Y + PANEL_H - (y - y_lo) / (y_hi - y_lo) * PANEL_H
    out = ['<text x="%d" y="%d" font-weight="bold">%s</text>' % (x0, MARGIN_Y - 15, title),
           '<rect x="%d" y="%d" width="%d" height="%d" fill="none" stroke="black"/>'
           % (x0, MARGIN_Y, PANEL_W, PANEL_H),
           '<text x="%d" y="%d" text-anchor="middle">kept and within 2 %% (share of all GT pixels)</text>'
           % (x0 + PANEL_W / 2, MARGIN_Y + PANEL_H + 35),
           '<text x="%d" y="%d" text-anchor="middle" transform="rotate(-90 %d %d)">'
           'precision (kept within 2 %%)</text>'
           % (x0 - 50, MARGIN_Y + PANEL_H / 2, x0 - 50, MARGIN_Y + PANEL_H / 2)]
    for i in range(5):
        x = x_lo + (x_hi - x_lo) * i / 4
        y = y_lo + (y_hi - y_lo) * i / 4
        out.append('<text x="%.1f" y="%d" text-anchor="middle" font-size="11">%.3f</text>'
                   % (sx(x), MARGIN_Y + PANEL_H + 15, x))
        out.append('<text x="%d" y="%.1f" text-anchor="end" font-size="11">%.3f</text>'
                   % (x0 - 5, sy(y) + 4, y))
    for curve, points in curves.items():
        colour = legend.setdefault(curve, COLOURS[len(legend) % len(COLOURS)])
        ordered = sorted(points)
        out.append('<polyline fill="none" stroke="%s" stroke-width="2" points="%s"/>'
                   % (colour, " ".join("%.1f,%.1f" % (sx(x), sy(y)) for x, y, _ in ordered)))
        for x, y, is_default in ordered:
            out.append('<circle cx="%.1f" cy="%.1f" r="%d" fill="%s"%s/>'
                       % (sx(x), sy(y), 6 if is_default else 3, colour,
                          ' stroke="black" stroke-width="2"' if is_default else ""))
    return out


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: plot_filter_curve.py filter_curve.tsv out.svg")
    sets = read_sets(sys.argv[1])
    if not sets:
        sys.exit("plot_filter_curve.py: no rows with numbers in " + sys.argv[1])
    width = MARGIN_X + len(sets) * (PANEL_W + GAP)
    height = MARGIN_Y + PANEL_H + 70 + 20 * 6
    body, legend = [], {}
    for i, (name, curves) in enumerate(sets.items()):
        body += panel(MARGIN_X + i * (PANEL_W + GAP), name, curves, legend)
    y = MARGIN_Y + PANEL_H + 60
    for curve, colour in legend.items():
        body.append('<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="%s" stroke-width="3"/>'
                    % (MARGIN_X, y - 4, MARGIN_X + 25, y - 4, colour))
        body.append('<text x="%d" y="%d">%s</text>' % (MARGIN_X + 32, y, curve))
        y += 20
    body.append('<text x="%d" y="%d">large ringed dot: the default</text>' % (MARGIN_X, y))
    with open(sys.argv[2], "w") as f:
        f.write('<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" '
                'font-family="sans-serif" font-size="13">\n' % (width, y + 20))
        f.write('<rect width="100%" height="100%" fill="white"/>\n')
        f.write("\n".join(body) + "\n</svg>\n")


if __name__ == "__main__":
    main()
