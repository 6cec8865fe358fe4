#!/usr/bin/env python3
"""The Python template subscriber's SVG plot (clients/python/tissue_subscriber.py
write_svg) at the extremes of finite statistics: every coordinate it writes
is a finite number inside the plot, also when a span between two values is
beyond the largest double (times of -1e308 and 1e308 from a foreign
publisher), and a constant series sits on the panel. No network.
Args: path of tissue_subscriber.py."""
import importlib.util
import math
import os
import re
import sys
import tempfile

spec = importlib.util.spec_from_file_location("tissue_subscriber", sys.argv[1])
subscriber = importlib.util.module_from_spec(spec)
spec.loader.exec_module(subscriber)

WIDTH, HEIGHT = 640, 400  # write_svg's canvas
failures = []


def check(name, samples, points=None):
    """`points`: how many points each polyline holds (default: one per sample
    in each of the two)."""
    points = [len(samples)] * 2 if points is None else points
    with tempfile.TemporaryDirectory() as work:
        path = os.path.join(work, "plot.svg")
        if not subscriber.write_svg(path, samples):
            failures.append(f"{name}: nothing written")
            return
        text = open(path).read()
    polylines = re.findall(r'<polyline points="([^"]*)"', text)
    if len(polylines) != len(points):
        failures.append(f"{name}: {len(polylines)} polylines, expected {len(points)}")
    for line, expected in zip(polylines, points):
        pairs = line.split()
        if len(pairs) != expected:
            failures.append(f"{name}: {len(pairs)} points, expected {expected}")
        for pair in pairs:
            x, y = (float(c) for c in pair.split(","))
            if not (math.isfinite(x) and math.isfinite(y) and 0 <= x <= WIDTH and 0 <= y <= HEIGHT):
                failures.append(f"{name}: point {pair} is not a finite point on the canvas")
                break
    if re.search(r"\b(nan|inf)\b", text, re.IGNORECASE):
        failures.append(f"{name}: the plot says nan or inf: {re.findall(r'.{30}(?:nan|inf).{10}', text, re.I)[:2]}")


check("times -1e308 .. 1e308", [(-1e308, 100, 1.0), (0.0, 200, 0.5), (1e308, 300, 2.0)])
check("values -1.7e308 .. 1.7e308", [(0.0, -1.7e308, 1.7e308), (1.0, 1.7e308, -1.7e308)])
check("ordinary run", [(0.0, 384, 1.0), (0.5, 400, 0.98), (1.0, 384, 1.01)])
check("one sample, constant values", [(2.0, 384, 1.0)])
# A NaN leaves out its own point only (a daemon's real-time factor is NaN
# until measured: its tets are still plotted), and a line of nothing but
# NaN is left out, its panel saying so.
nan = float("nan")
check("a NaN real-time factor", [(0.0, 384, nan), (0.5, 400, 0.98), (1.0, 410, 1.01)], points=[3, 2])
check("real-time factor NaN throughout", [(0.0, 384, nan), (0.5, 400, nan)], points=[2])
with tempfile.TemporaryDirectory() as work:
    path = os.path.join(work, "plot.svg")
    if subscriber.write_svg(path, [(0.0, 384, nan)]) and "real-time factor: no finite values" not in open(path).read():
        failures.append("real-time factor NaN throughout: its panel does not say so")
    if subscriber.write_svg(path, [(nan, 384, 1.0)]):
        failures.append("no finite time: a plot was written")
if failures:
    print("\n".join(failures))
    sys.exit(1)
print("python_plot_test: 6 plots, every point finite and on the canvas; NaNs left out")
