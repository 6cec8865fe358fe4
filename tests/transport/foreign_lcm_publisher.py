#!/usr/bin/env python3
"""A foreign publisher for python_subscriber_test.sh (inside its private network
namespace only). Args: PYTHON_TYPES_DIR [MODE]

once (the default): after 1 s, one datagram on TISSUE_SURFACE_MESH that is not a
surface_mesh, five surface_mesh messages that decode but are not usable meshes
(a byte after the message; vertex_count 1 with 9 coordinates; triangle
indices -1 and one past the last vertex; a NaN time_s), and one sim_stats with
a NaN real-time factor.

stream: sim_stats with time_s = i ms and tet_count = i, about 5000 a second,
until killed (at most 120 s).

nan_rtf: sim_stats as a daemon sends them before it has measured its
real-time factor (NaN) but with finite time_s = i ms and tet_count = i,
about 100 a second, until killed (at most 120 s).

nan_time: the same with a NaN time_s and a finite real-time factor: nothing
in them can be placed on a time axis."""
import sys
import time

import lcm

sys.path.insert(0, sys.argv[1])
from tissue import sim_stats, surface_mesh  # noqa: E402  (the generated types are found through argv)

mode = sys.argv[2] if len(sys.argv) > 2 else "once"
lc = lcm.LCM("udpm://239.255.76.67:7667?ttl=0")


def triangle(**fields):
    """One valid triangle at z = 0, then `fields` set as given."""
    m = surface_mesh()
    m.time_s = 0.5
    m.vertex_count, m.vertex_coordinate_count = 3, 9
    m.vertex_m = [0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01, 0.0]
    m.vertex_refinement_level = b"\0\0\0"
    m.triangle_count, m.triangle_index_count = 1, 3
    m.triangle_vertex = [0, 1, 2]
    m.triangle_strain_energy_density_J_per_m3 = [0.0]
    m.bounds_max_m = [0.01, 0.01, 0.0]
    for name, value in fields.items():
        setattr(m, name, value)
    return m


if mode == "stream":
    m = sim_stats()
    m.real_time_factor = 1.0
    i, end = 0, time.monotonic() + 120.0
    while time.monotonic() < end:
        for _ in range(10):
            m.time_s, m.tet_count = i * 1e-3, i
            lc.publish("TISSUE_SIM_STATS", m.encode())
            i += 1
        time.sleep(0.002)  # a pace the subscriber keeps up with, not a wait for anything
    sys.exit(0)

if mode in ("nan_rtf", "nan_time"):
    m = sim_stats()
    i, end = 0, time.monotonic() + 120.0
    while time.monotonic() < end:
        m.tet_count = i
        m.time_s = float("nan") if mode == "nan_time" else i * 1e-3
        m.real_time_factor = float("nan") if mode == "nan_rtf" else 1.0
        lc.publish("TISSUE_SIM_STATS", m.encode())
        i += 1
        time.sleep(0.01)
    sys.exit(0)

time.sleep(1.0)
lc.publish("TISSUE_SURFACE_MESH", b"not a surface mesh")
lc.publish("TISSUE_SURFACE_MESH", triangle().encode() + b"\0")
lc.publish("TISSUE_SURFACE_MESH", triangle(vertex_count=1).encode())
lc.publish("TISSUE_SURFACE_MESH", triangle(triangle_vertex=[0, 1, -1]).encode())
lc.publish("TISSUE_SURFACE_MESH", triangle(triangle_vertex=[0, 1, 3]).encode())
lc.publish("TISSUE_SURFACE_MESH", triangle(time_s=float("nan")).encode())
m = sim_stats()
m.time_s = 0.5
m.real_time_factor = float("nan")
lc.publish("TISSUE_SIM_STATS", m.encode())
