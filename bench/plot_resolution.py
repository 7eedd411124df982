#!/usr/bin/env python3
"""Plots resolution_bench.sh's table: the view's seconds per megapixel and
the peak resident memory against the image's megapixels, one line per
variant (cache budget / band size), as a self-contained SVG (standard
library only, so it runs wherever the benchmark does).

Usage: bench/plot_resolution.py resolution_bench.tsv out.svg
"""
import csv
import sys

from plot_common import COLOURS, number

WIDTH, HEIGHT = 900, 380
PANEL_W, PANEL_H = 360, 260
MARGIN_X, MARGIN_Y = 70, 50


def read_series(path):
    """{variant: [(megapixels, view s/MP, peak GB)]}, sizes in file order."""
    series = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f, delimiter="\t"):
            variant = "cache %s MiB, bands %s MP" % (row["cache_mb"], row.get("band_mp", "-"))
            mp = number(row["megapixels"])
            per_mp = number(row["view_s_per_mp"])
            peak = number(row["peak_rss_mib"])
            if mp is None:
                continue
            series.setdefault(variant, []).append(
                (mp, per_mp, None if peak is None else peak / 1024.0))
    return series


def panel(x0, title, y_label, points_by_variant, index):
    """One panel's SVG elements: axes with ticks, a line per variant."""
    values = [p[index] for pts in points_by_variant.values() for p in pts if p[index] is not None]
    xs = [p[0] for pts in points_by_variant.values() for p in pts]
    if not values or not xs:
        return ['<text x="%d" y="%d">%s: no data</text>' % (x0, MARGIN_Y, title)]
    x_max = max(xs) * 1.05
    y_max = max(values) * 1.1
    sx = lambda x: x0 + x / x_max * PANEL_W
    sy = lambda y: MARGIN_Y + PANEL_H - y / y_max * PANEL_H
    out = ['<text x="%d" y="%d" font-weight="bold">%s</text>' % (x0, MARGIN_Y - 15, title),
           '<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="black"/>'
           % (x0, MARGIN_Y + PANEL_H, x0 + PANEL_W, MARGIN_Y + PANEL_H),
           '<line x1="%d" y1="%d" x2="%d" y2="%d" stroke="black"/>' % (x0, MARGIN_Y, x0, MARGIN_Y + PANEL_H),
           '<text x="%d" y="%d" text-anchor="middle">megapixels</text>'
           % (x0 + PANEL_W / 2, MARGIN_Y + PANEL_H + 35),
           '<text x="%d" y="%d" text-anchor="middle" transform="rotate(-90 %d %d)">%s</text>'
           % (x0 - 45, MARGIN_Y + PANEL_H / 2, x0 - 45, MARGIN_Y + PANEL_H / 2, y_label)]
    for i in range(6):
        x = x_max * i / 5
        y = y_max * i / 5
        out.append('<text x="%.1f" y="%d" text-anchor="middle" font-size="11">%.0f</text>'
                   % (sx(x), MARGIN_Y + PANEL_H + 15, x))
        out.append('<text x="%d" y="%.1f" text-anchor="end" font-size="11">%.1f</text>' % (x0 - 5, sy(y) + 4, y))
        out.append('<line x1="%d" y1="%.1f" x2="%d" y2="%.1f" stroke="#ddd"/>' % (x0, sy(y), x0 + PANEL_W, sy(y)))
    for k, (variant, pts) in enumerate(points_by_variant.items()):
        colour = COLOURS[k % len(COLOURS)]
        drawn = [(sx(p[0]), sy(p[index])) for p in sorted(pts) if p[index] is not None]
        if len(drawn) > 1:
            out.append('<polyline fill="none" stroke="%s" stroke-width="2" points="%s"/>'
                       % (colour, " ".join("%.1f,%.1f" % d for d in drawn)))
        for d in drawn:
            out.append('<circle cx="%.1f" cy="%.1f" r="3" fill="%s"/>' % (d[0], d[1], colour))
    return out


def main(argv):
    if len(argv) != 3:
        sys.stderr.write(__doc__)
        return 2
    series = read_series(argv[1])
    if not series:
        sys.stderr.write("error: %s has no rows\n" % argv[1])
        return 1
    parts = ['<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" font-family="sans-serif" '
             'font-size="13">' % (WIDTH, HEIGHT + 20 * len(series)),
             '<rect width="100%" height="100%" fill="white"/>']
    parts += panel(MARGIN_X, "dispmvs_colmap, one view: seconds per megapixel", "s / MP", series, 1)
    parts += panel(MARGIN_X + PANEL_W + 100, "peak resident memory", "GB", series, 2)
    for k, variant in enumerate(series):
        y = HEIGHT + 20 * k
        parts.append('<rect x="%d" y="%d" width="14" height="4" fill="%s"/>'
                     % (MARGIN_X, y - 6, COLOURS[k % len(COLOURS)]))
        parts.append('<text x="%d" y="%d">%s</text>' % (MARGIN_X + 20, y, variant))
    parts.append("</svg>")
    with open(argv[2], "w") as f:
        f.write("\n".join(parts) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
